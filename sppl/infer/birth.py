"""Where a birth puts its new object: from the class's prior, or near what is unexplained.

A birth drawn from the prior almost never lands on an object the cameras see: the prior on
position is wide and the objects are small. So a birth may instead place the object near a
point where the observations disagree with the current hypothesis: a depth pixel nearer than
what is rendered there (back-projected with its measured depth), or an RGB pixel whose colour
is off (its ray followed down to the height objects stand on: ``support_height``).

The proposal stays exact. Its density over the two position parameters is the mixture

    q(x, y | state) = (1 - w) p(x, y) + w (1/M) sum_i Normal((x, y); point_i, h^2 I)

where p(x, y) is the class's position prior (restricted to the model's region if it has one,
sppl/model/region.py), the points are a deterministic function of the state (the renders of its
objects), and every other parameter is drawn from its prior. A death's reverse is a birth from the state
after the death, so the death's ratio evaluates the same density with the points of that
state; docs/inference.md has the derivation. ``w`` is the model's ``data_birth`` setting
(0 gives the thesis's prior-only births).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy import ndimage

from ..model.types import Model, ObjectClass
from ..render.bounds import world_corners
from ..scoring.protocol import ObservationScorer

# A depth pixel is unexplained when it is nearer than the render by more than twice the depth
# map's noise (``depth_noise``), and at least this, in metres: less than the height of a mug
# standing on a table, which the table top behind it shows 6 to 11 cm further away.
DEPTH_GAP = 0.05
# An RGB pixel is unexplained when its mean absolute colour difference exceeds this: a red
# mug on a wooden table differs from it by 0.12 to 0.2.
COLOUR_GAP = 0.1
# An object a pixel or two across (a sphere 4 cm wide, 4 m from a 96x96 camera) leaves no
# blob, but a coloured object on a grey floor differs from it by 0.25 to 0.4, where the
# sensor noise of a right scene (0.05 a channel) leaves no pixel above 0.2: a speck of
# unexplained RGB pixels too small to seed, apart from every larger blob, is kept whole, and
# seeds, when one of its pixels is this far off, or STRONG_SIGMAS times the image's noise
# where that is more (a mean of three absolute Gaussian deviates passes 4 sigma about once
# in ten million pixels).
STRONG_COLOUR_GAP = 0.2
STRONG_SIGMAS = 4.0
# The same holds in a depth map: a cone 4 cm wide far across a floor seen at a slant is a
# column of depth pixels one or two wide, metres nearer than the floor behind, which the
# erosion removes whole. A piece of unexplained depth pixels seeds when at least
# DEPTH_SPECK_PIXELS of its pixels are strongly off (nearer than the render by STRONG_SIGMAS
# times the map's noise, and at least twice DEPTH_GAP) and measure depths within
# DEPTH_SPECK_SPAN of their median, and most of it lies away from what the state draws. A
# sensor's stray returns are strongly off too, but at depths drawn at random (a map with 1%
# of them holds two side by side about twice, three that agree almost never); a rim of a
# drawn object placed a pixel off, or a scenery edge whose depth a camera mixed across it,
# lies along that edge.
DEPTH_SPECK_PIXELS = 3
DEPTH_SPECK_SPAN = 0.5
# At most this many points describe a state (an even stride over the unexplained pixels), so
# that the density costs microseconds.
MAX_POINTS = 400
# A blob of unexplained pixels seeds a fitted birth when it has this many pixels or holds a
# pixel STRONG_COLOUR_GAP off, and a state has at most this many seeds (its largest blobs),
# so that a fitted death's choice among them stays a short list.
SEED_PIXELS = 4
MAX_SEEDS = 8
_LOG_2PI = math.log(2.0 * math.pi)


class BirthProposal:
    def __init__(self, model: Model, scorer: ObservationScorer | None = None) -> None:
        self.model = model
        self.weight = model.inference.data_birth if scorer is not None else 0.0
        self.spread = model.inference.data_birth_spread
        self.terms = list(getattr(scorer, "terms", []))
        self.scorer = scorer
        self.floor = support_height(model)
        # Per depth term: the gap that counts as unexplained. Twice the noise keeps noisy
        # maps (5 cm) from seeding at every pixel the noise pushes forward; a function of
        # the observations alone, so the proposal stays a function of the state.
        noise = {t.frame: depth_noise(t.observed, t.valid, t.camera.depth_max)
                 for t in self.terms if t.kind == "depth"}
        self.depth_gaps = {f: max(DEPTH_GAP, 2.0 * s) for f, s in noise.items()}
        self.strong_depth_gaps = {f: max(2.0 * DEPTH_GAP, STRONG_SIGMAS * s)
                                  for f, s in noise.items()}
        self._static_depth = None
        self.strong_gaps = {t.frame: max(STRONG_COLOUR_GAP,
                                         STRONG_SIGMAS * image_noise(t.observed))
                            for t in self.terms if t.kind == "image"}
        # Per camera: world ray directions, the ray-to-axis factor, and the centre.
        self.rays = {
            t.frame: (t.camera.ray_directions(), t.camera.ray_to_z(), t.camera.position)
            for t in self.terms
        }

    def _drawn(self, renders, frame) -> np.ndarray:
        """The pixels of camera ``frame`` where the state draws an object: its render's depth
        nearer than the static scenery's (rendered once)."""
        if self._static_depth is None:
            self._static_depth = {f: depth for f, (_, depth)
                                  in self.scorer.render(self.model.static_parts).items()}
        return renders[frame][1] < self._static_depth[frame] - 1e-3

    # -- the points a state leaves unexplained ----------------------------------------------

    def points(self, trace) -> np.ndarray:
        if self.weight == 0.0:
            return np.empty((0, 2))
        return _cached(trace, "birth_points", self._points)

    def _points(self, renders) -> np.ndarray:
        found = [pts for _, pts, _ in self._unexplained(renders)]
        pts = np.concatenate(found) if found else np.empty((0, 2))
        if len(pts) > MAX_POINTS:
            pts = pts[:: math.ceil(len(pts) / MAX_POINTS)]
        return pts

    def _unexplained(self, renders):
        """Per camera term, the pixels the render leaves unexplained, the ground points
        (x, y) of those pixels, in the order ``mask[mask]`` reads them, and which of them
        are strongly off (an RGB pixel STRONG_COLOUR_GAP off): a depth pixel back-projected
        with its measured depth, an RGB pixel's ray followed down to the height objects
        stand on (an RGB pixel whose ray never gets there is dropped)."""
        for t in self.terms:
            dirs, ray_to_z, centre = self.rays[t.frame]
            rendered = self.scorer.rendered(renders, t)
            if t.kind == "depth":
                flagged = t.observed < rendered - self.depth_gaps[t.frame]
                flagged &= _measured(t.observed, t.valid, t.camera.depth_max)
                blobs = _blobs(flagged)
                strong = _depth_specks(
                    flagged, blobs, t.observed < rendered - self.strong_depth_gaps[t.frame],
                    t.observed, _depth_edges(rendered, self.depth_gaps[t.frame])
                    | self._drawn(renders, t.frame))
                near = blobs | strong
                dist = t.observed[near]
                if t.camera.depth_type == "z":
                    dist = dist / ray_to_z[near]
                pts = centre + dirs[near] * dist[:, None]
                strong = strong[near]
            elif t.kind == "image":
                off = np.abs(t.observed - rendered).mean(axis=-1)
                blobs = _blobs(off > COLOUR_GAP)
                drawn = self._drawn(renders, t.frame)
                strong = _specks(off > COLOUR_GAP, blobs, off > self.strong_gaps[t.frame],
                                 _edges(rendered) | drawn,
                                 _Beside(drawn, t.observed, rendered, self.strong_gaps[t.frame]))
                near = blobs | strong
                # An object seen from above is found where its pixel's ray meets the
                # surface it stands on, not the ground under a table.
                near &= (dirs[..., 2] < -1e-6) & (centre[2] > self.floor)
                d = dirs[near]
                s = (self.floor - centre[2]) / d[:, 2]
                pts = centre + d * s[:, None]
                strong = strong[near]
            else:
                continue
            yield near, pts[:, :2], strong

    def seeds(self, trace) -> np.ndarray:
        """Ground points (S, 2) where whole objects seem to be missing from ``trace``: per
        camera, each blob of at least SEED_PIXELS unexplained pixels, or with a strongly-off
        one, gives the median of its pixels' ground points; the largest MAX_SEEDS blobs over
        all cameras, largest first.
        A deterministic function of the state's renders, as a fitted birth's density needs
        (sppl.infer.fitted_birth)."""
        return self._seed_table(trace)[0]

    def speck_seeds(self, trace) -> np.ndarray:
        """Which of ``seeds(trace)`` come from specks (RGB or depth): pieces too small for a
        blob, apart from what the state draws (or beside it, in a colour no rim of it
        shows), where an object a few pixels across stands and not a misplaced object's
        rim (a fitted birth there may shrink its starts: ``sppl.infer.fit.SHRINK``)."""
        return self._seed_table(trace)[1]

    def _seed_table(self, trace) -> tuple[np.ndarray, np.ndarray]:
        return _cached(trace, "birth_seeds", self._seeds,
                       (np.empty((0, 2)), np.zeros(0, dtype=bool)))

    def _seeds(self, renders) -> tuple[np.ndarray, np.ndarray]:
        found = []  # (pixels, order found, point, a speck)
        for mask, pts, strong in self._unexplained(renders):
            labels, count = ndimage.label(mask, structure=_CROSS)
            of_pixel = labels[mask]
            for blob in range(1, count + 1):
                here = of_pixel == blob
                mine = pts[here]
                if len(mine) >= SEED_PIXELS or strong[here].any():
                    found.append((len(mine), len(found), np.median(mine, axis=0),
                                  bool(strong[here].all())))
        found.sort(key=lambda f: (-f[0], f[1]))
        return (np.array([f[2] for f in found[:MAX_SEEDS]]).reshape(-1, 2),
                np.array([f[3] for f in found[:MAX_SEEDS]], dtype=bool))

    # -- sampling and density ------------------------------------------------------------------

    def sample(self, cls: ObjectClass, trace, rng: np.random.Generator) -> dict[str, Any]:
        values = cls.sample_prior(rng)
        pts = self.points(trace) if cls.position else np.empty((0, 2))
        if len(pts) and rng.random() < self.weight:
            centre = pts[int(rng.integers(len(pts)))]
            xy = centre + self.spread * rng.standard_normal(2)
            values[cls.position[0]], values[cls.position[1]] = float(xy[0]), float(xy[1])
        return values

    def log_density(self, cls: ObjectClass, values: Mapping[str, Any], trace) -> float:
        """log q(values | state) of a birth of class ``cls`` from the state ``trace``."""
        pts = self.points(trace) if cls.position else np.empty((0, 2))
        if not len(pts):
            return cls.log_prior(values)
        x, y = values[cls.position[0]], values[cls.position[1]]
        # The other parameters are drawn from their priors; none of them depends on the
        # position (the compiler only declares a position that nothing depends on). The
        # position's prior is the class's, restricted to the model's region if it has one.
        rest = cls.log_prior(values, only=[n for n in cls.parameter_names if n not in cls.position])
        log_prior_xy = cls.log_prior(values, only=cls.position)
        d2 = ((pts - (x, y)) ** 2).sum(axis=1)
        h2 = self.spread**2
        log_kernel = -0.5 * d2 / h2 - _LOG_2PI - math.log(h2)
        log_data = np.logaddexp.reduce(log_kernel) - math.log(len(pts))
        mix = np.logaddexp(math.log1p(-self.weight) + log_prior_xy, math.log(self.weight) + log_data)
        return rest + float(mix)


_CROSS = ndimage.generate_binary_structure(2, 1)


def support_height(model: Model) -> float:
    """The height the model's objects stand on: the median, over its classes that are placed
    on the ground plane and do not float, of the lowest point of one prior draw (a fixed seed:
    the proposal must be the same function of the state in every process). 0 for the ground;
    the table's height where a pose lifts every object onto a table."""
    rng = np.random.default_rng(0)
    lows = []
    for c in model.classes:
        if c.position is None or c.floating:
            continue
        # Drawn past any region restriction, which moves the object only along the ground.
        values: dict[str, Any] = {}
        for p in c.parameters:
            values[p.name] = p.sample(rng, values)
        # Its parts' posed bounding boxes: exact for upright parts, never above a tilted one.
        lows.append(float(world_corners(c.parts(values))[2].min()))
    return float(np.median(lows)) if lows else 0.0


def depth_noise(observed: np.ndarray, valid: np.ndarray | None, far: float) -> float:
    """A robust estimate of a depth map's noise scale, in metres: the median absolute second
    difference along rows, over runs of three measured pixels, scaled to a Gaussian's
    standard deviation (a second difference of independent noise has variance 6 sigma^2; a
    surface's slope cancels in it, and its edges are too few to move the median)."""
    return _second_difference_scale(observed, _measured(observed, valid, far))


def image_noise(observed: np.ndarray) -> float:
    """``depth_noise``'s estimate for an RGB image (H, W, 3): the median of its channels'."""
    ok = np.ones(observed.shape[:2], dtype=bool)
    return float(np.median([_second_difference_scale(observed[..., c], ok)
                            for c in range(observed.shape[-1])]))


def _second_difference_scale(observed: np.ndarray, ok: np.ndarray) -> float:
    second = observed[:, :-2] - 2.0 * observed[:, 1:-1] + observed[:, 2:]
    runs = ok[:, :-2] & ok[:, 1:-1] & ok[:, 2:]
    if not runs.any():
        return 0.0
    return float(np.median(np.abs(second[runs])) / 0.6745 / math.sqrt(6.0))


def _measured(observed: np.ndarray, valid: np.ndarray | None, far: float) -> np.ndarray:
    """The depth pixels that measured a surface: valid, and nearer than the camera's range."""
    ok = observed < far * (1.0 - 1e-3)
    return ok & valid if valid is not None else ok


def _cached(trace, key: str, compute, empty=None):
    """``compute(trace.renders)``, kept in the trace's cache; ``empty`` (no points) without
    renders."""
    if trace.renders is None:
        return np.empty((0, 2)) if empty is None else empty
    cached = trace.cache.get(key)
    if cached is None:
        cached = trace.cache[key] = compute(trace.renders)
    return cached


def _specks(flagged: np.ndarray, blobs: np.ndarray, strong: np.ndarray,
            drawn: np.ndarray, beside: _Beside | None = None) -> np.ndarray:
    """The pieces of ``flagged`` (4-connected) that hold some ``strong`` pixel and fewer
    than SEED_PIXELS pixels of ``blobs`` (the erosion left too little of them to seed),
    whole, and touch no pixel of ``drawn`` (the render's edges and the objects it draws):
    objects too small for a blob, standing where the state has nothing. A larger piece
    keeps only its blob, as before, so that the eroded edge of an object the state lacks
    seeds nothing of its own; a piece along an edge the state draws is that edge drawn a
    pixel off (a camera's anti-aliasing, a shadow's soft rim), and one on an object it
    draws a glint (a metal sphere's highlight), not an object. With ``beside``, a piece
    that touches the edges but lies on no object drawn is kept after all when its colour
    is one no shade or blend of the colours drawn around it gives (``_Beside``): a red cube
    two pixels across beside a green one, which no rim of the green cube can show."""
    labels, count = ndimage.label(flagged, structure=_CROSS)
    if not count:
        return np.zeros_like(flagged)
    keep = np.zeros(count + 1, dtype=bool)
    keep[np.unique(labels[strong & flagged])] = True
    keep &= np.bincount(labels[blobs], minlength=count + 1) < SEED_PIXELS
    touching = np.zeros(count + 1, dtype=bool)
    touching[np.unique(labels[drawn])] = True
    kept = keep & ~touching
    if beside is not None:
        for piece in np.flatnonzero(keep & touching):
            if piece and beside.unexplained(labels == piece, strong):
                kept[piece] = True
    kept[0] = False
    return kept[labels]


# The render's pixels within this many of a piece are the colours a rim of what it draws
# can show: a rim drawn a pixel or two off, and the edges' two pixels of anti-aliasing.
BESIDE_PIXELS = 3


class _Beside:
    """Whether a piece of strongly-off RGB pixels beside a drawn edge can be that edge
    drawn a little off. A rim a pixel off shows the colour drawn beside it; a camera's
    anti-aliased edge a blend of two such colours; a shadow's rim, shading and bounced light
    a darker or lighter shade of them. Every such colour lies in the cone a u + b v (a, b >=
    0) of two colours u, v the render draws within BESIDE_PIXELS of the piece; a piece whose
    strongly-off pixels lie, on average, further than ``gap`` (a mean absolute difference)
    from every such cone is something the state does not draw."""

    def __init__(self, objects: np.ndarray, observed: np.ndarray, rendered: np.ndarray,
                 gap: float) -> None:
        self.objects, self.observed, self.rendered, self.gap = objects, observed, rendered, gap

    def unexplained(self, piece: np.ndarray, strong: np.ndarray) -> bool:
        if (piece & self.objects).any():
            return False  # a glint on a drawn object, or a rim drawn on the wrong side
        around = ndimage.binary_dilation(piece, structure=np.ones((3, 3), dtype=bool),
                                         iterations=BESIDE_PIXELS)
        # Colours a twentieth apart are one: the cones of near colours are near.
        colours = np.unique(np.round(self.rendered[around] * 20.0), axis=0) / 20.0
        off = self.observed[piece & strong]
        return bool(_cone_distance(off, colours).mean() > self.gap)


def _cone_distance(points: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """Per point (P, 3), the mean absolute difference between it and its nearest point, in
    least squares, of the cones a u + b v (a, b >= 0) of every pair of ``colours`` (C, 3),
    a pair being a colour with itself too."""
    u = colours[:, None, None, :]
    v = colours[None, :, None, :]
    c = points[None, None, :, :]
    uu, vv, uv = (u * u).sum(-1), (v * v).sum(-1), (u * v).sum(-1)
    cu, cv = (c * u).sum(-1), (c * v).sum(-1)
    tiny = 1e-12
    # Both weights free, where the Gram matrix is not singular and both come out >= 0 ...
    det = uu * vv - uv * uv
    a = np.where(det > tiny, (cu * vv - cv * uv) / np.maximum(det, tiny), -1.0)
    b = np.where(det > tiny, (cv * uu - cu * uv) / np.maximum(det, tiny), -1.0)
    both = (a >= 0) & (b >= 0)
    # ... or one of them zero, or both (the black that every cone holds).
    a1 = np.maximum(cu, 0.0) / np.maximum(uu, tiny)
    b1 = np.maximum(cv, 0.0) / np.maximum(vv, tiny)
    fits = [np.where(both[..., None], a[..., None] * u + b[..., None] * v, np.inf),
            a1[..., None] * u, b1[..., None] * v, np.zeros_like(c)]
    shape = (len(colours), len(colours), len(points))
    best = np.min([np.broadcast_to(np.abs(c - f).mean(-1), shape) for f in fits], axis=0)
    return best.min(axis=(0, 1))


def _depth_specks(flagged: np.ndarray, blobs: np.ndarray, strong: np.ndarray,
                  observed: np.ndarray, drawn: np.ndarray) -> np.ndarray:
    """``_specks`` for a depth map: the pieces of ``flagged`` (4-connected) with at least
    DEPTH_SPECK_PIXELS ``strong`` pixels whose ``observed`` depths lie within
    DEPTH_SPECK_SPAN of their median, and no piece of ``blobs`` that seeds (SEED_PIXELS), whole,
    with fewer than half their pixels within two of ``drawn`` (the objects the state draws
    and the render's depth edges). Unlike an RGB speck, one may touch a drawn object: a pole
    standing beside a cube, metres nearer than the floor behind both, meets the cube's
    outline at a few of its pixels, where a misplaced rim runs the outline's length."""
    labels, count = ndimage.label(flagged, structure=_CROSS)
    if not count:
        return np.zeros_like(flagged)
    marked = np.where(strong & flagged, labels, 0)
    ids = np.unique(marked[marked > 0])
    if not len(ids):
        return np.zeros_like(flagged)
    median = np.zeros(count + 1)
    median[ids] = ndimage.median(observed, marked, ids)
    agree = (marked > 0) & (np.abs(observed - median[marked]) <= DEPTH_SPECK_SPAN)
    size = np.bincount(labels.ravel(), minlength=count + 1)
    by_edges = np.bincount(
        labels[ndimage.binary_dilation(drawn, structure=_CROSS, iterations=2)],
        minlength=count + 1)
    keep = np.bincount(marked[agree], minlength=count + 1) >= DEPTH_SPECK_PIXELS
    # The erosion may leave a piece 2 pixels wide a few pixels apart from each other, none
    # of which seeds: the piece is a speck unless one of them is a blob that seeds itself.
    pieces, _ = ndimage.label(blobs, structure=_CROSS)
    sizes = np.bincount(pieces.ravel())
    sizes[0] = 0
    largest = np.zeros(count + 1)
    largest[1:] = ndimage.maximum(sizes[pieces], labels, np.arange(1, count + 1))
    keep &= largest < SEED_PIXELS
    keep &= 2 * by_edges < size
    keep[0] = False
    return keep[labels]


def _steps(across: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Both pixels of every step flagged between neighbours across (H, W - 1) and down
    (H - 1, W)."""
    step = np.zeros((across.shape[0], down.shape[1]), dtype=bool)
    step[:, 1:] |= across
    step[:, :-1] |= across
    step[1:] |= down
    step[:-1] |= down
    return step


def _depth_edges(rendered: np.ndarray, gap: float) -> np.ndarray:
    """The pixels of a rendered depth map (H, W) where the depth jumps by more than ``gap``
    to a neighbour: the outlines of the objects and scenery it draws."""
    return _steps(np.abs(np.diff(rendered, axis=1)) > gap,
                  np.abs(np.diff(rendered, axis=0)) > gap)


def _edges(rendered: np.ndarray) -> np.ndarray:
    """The pixels within two of an edge in a render (H, W, 3): where its colour changes by
    more than COLOUR_GAP from one pixel to the next."""
    step = _steps(np.abs(np.diff(rendered, axis=1)).mean(axis=-1) > COLOUR_GAP,
                  np.abs(np.diff(rendered, axis=0)).mean(axis=-1) > COLOUR_GAP)
    return ndimage.binary_dilation(step, structure=_CROSS, iterations=2)


def _blobs(mask: np.ndarray) -> np.ndarray:
    """Keep pixels whose four neighbours are flagged too: an object leaves a blob of them,
    sensor noise only scattered single pixels."""
    return ndimage.binary_erosion(mask, structure=_CROSS)
