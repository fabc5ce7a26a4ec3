"""The likelihood of a hypothesis: render it for every camera and compare with the observations.

Analysis by synthesis (thesis 3.3): each frame is rendered once per hypothesis, giving RGB and
depth together, and each of the frame's modalities that the model has a sensor for is reduced to
its likelihood's sufficient statistics. The statistics are cached on the trace, so the noise
moves re-score without rendering.

Two paths compute the same statistics. ``ReferenceScorer`` reads every camera's images back and
calls the likelihood's ``statistics`` in numpy: slow and obviously right. ``Scorer`` computes the
per-pixel terms on the GL side (``sppl.render.pixels``) for every likelihood that declares a
GL-side version (``gl_statistics``, ``sppl.model.gl_statistics``), and given the trace a
proposal comes from it re-renders only the pixels the changed objects covered before or cover
now. It falls back to the reference path for any other likelihood, and for renderers that are
not ``Renderer``. The images themselves are then rendered only when something asks for them
(``Renders``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..data.camera import Camera
from ..data.observations import Observations
from ..errors import ObservationError, SpplError
from ..model.gl_statistics import declared_gl_statistics
from ..model.likelihoods import Likelihood, get_likelihood
from ..model.types import RENDER_GROUP, Model, RenderSettings
from ..render.bounds import CameraBounds, union, world_corners
from ..render.lighting import block, caster_rows, shadow_corners

log = logging.getLogger(__name__)

# Which rendered output each sensor kind is compared with.
_OUTPUT = {"image": 0, "depth": 1}


@dataclass(frozen=True, eq=False)
class Term:
    """One (frame, sensor kind) pair that contributes to the likelihood."""

    frame: int
    kind: str
    camera: Camera
    observed: np.ndarray
    valid: np.ndarray | None
    likelihood: Likelihood


def depth_mask(depth: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Which depth pixels are measurements: those ``valid`` allows (all, if None) that are
    finite and above zero. A depth of 0, below zero, NaN or inf is no measurement
    (docs/observations.md), whether it came from a file or was put in an ``Observations`` by
    hand; both scoring paths leave such pixels out (the fast path through this mask)."""
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(depth) & (depth > 0)
    return mask if valid is None else mask & np.asarray(valid, dtype=bool)


class ReferenceScorer:
    """Turns a set of objects into per-term likelihood statistics, and those into a log density,
    by reading every render back and scoring it in numpy: the oracle of the fast path."""

    def __init__(self, model: Model, observations: Observations, renderer) -> None:
        self.model = model
        self.renderer = renderer
        self.likelihoods = {k: get_likelihood(s.likelihood, s.options) for k, s in model.sensors.items()}
        terms: list[Term] = []
        for i, frame in enumerate(observations.frames):
            for kind, data, valid in (
                ("image", frame.rgb, None),
                ("depth", frame.depth, frame.depth_valid),
            ):
                if data is None:
                    continue
                if kind not in model.sensors:
                    log.warning("frame %d has %s data but the model has no %s sensor: ignored",
                                i, kind, kind)
                    continue
                if kind == "depth":
                    valid = depth_mask(data, valid)
                    data = np.where(valid, data, 0.0).astype(np.float32)
                terms.append(Term(i, kind, frame.camera, data, valid, self.likelihoods[kind]))
        if not terms:
            raise ObservationError(
                "no observation matches a sensor of the model: the frames need RGB images for an"
                " 'image' sensor or depth maps for a 'depth' sensor",
                path=observations.root,
            )
        self.terms = terms
        self.cameras = {t.frame: t.camera for t in terms}
        # The sensors whose likelihood is scored at given noise values (``sppl.model.robust``): their
        # statistics hold those values, and a noise move re-scores them (``rescore``).
        self.per_pixel = sorted(k for k, lik in self.likelihoods.items()
                                if getattr(lik, "per_pixel", False))

    def evaluate(self, objects, parent=None, noise=None):
        """Render the objects for every camera; return the likelihood statistics of every term
        and the renders, as (stats, {frame: (rgb, depth)}). ``parent``, the trace the objects
        were proposed from, lets a fast scorer work incrementally; this one ignores it.
        ``noise``, the trace's noise values (by default the parent's), gives the lighting where
        the model leaves it latent (its RENDER_GROUP; without it, the model's fixed settings)
        and the values the per-pixel likelihoods are scored at."""
        noise = self._noise(parent, noise)
        rendered = self.render(self.parts(objects), self.settings_for(noise))
        stats = {(t.frame, t.kind): self.term_statistics(t, self.rendered(rendered, t), noise)
                 for t in self.terms}
        return stats, rendered

    def term_statistics(self, term: Term, rendered: np.ndarray, noise) -> np.ndarray:
        """A term's statistics in numpy (at ``noise`` for a per-pixel likelihood)."""
        if term.kind not in self.per_pixel:
            return term.likelihood.statistics(term.observed, rendered, term.valid)
        return term.likelihood.statistics(term.observed, rendered, term.valid, noise[term.kind],
                                          depth_max=term.camera.depth_max)

    def _noise(self, parent, noise):
        if noise is None:
            noise = getattr(parent, "noise", None)
        if noise is None and self.per_pixel:
            raise SpplError(f"the {', '.join(self.per_pixel)} likelihood is scored at given "
                            "noise values: pass the noise, or the trace the objects come from")
        return noise

    def evaluate_batch(self, requests):
        """``evaluate`` of several (objects, parent) or (objects, parent, noise) requests, in
        order. This path renders one hypothesis at a time; ``Scorer`` draws them together
        where it can."""
        return [self.evaluate(*request) for request in requests]

    def settings_for(self, noise) -> RenderSettings:
        """The render settings of a hypothesis with these noise values: the model's, with
        its latent lighting parameters at the values ``noise`` holds for them."""
        if not noise or RENDER_GROUP not in noise:
            return self.model.render
        return self.model.render.with_values(noise[RENDER_GROUP])

    def statistics(self, objects, noise=None) -> dict[tuple[int, str], np.ndarray]:
        return self.evaluate(objects, noise=noise)[0]

    def rescore(self, trace, noise):
        """(stats, renders) of the trace's objects at other noise values: the trace's own
        where every likelihood's statistics are sufficient for its noise (the Gaussian's),
        else the per-pixel terms scored again from its renders."""
        if all(trace.noise[k] == noise[k] for k in self.per_pixel):
            return trace.stats, trace.renders
        stats = dict(trace.stats)
        for t in self.terms:
            if t.kind in self.per_pixel:
                stats[(t.frame, t.kind)] = ReferenceScorer.term_statistics(
                    self, t, self.rendered(trace.renders, t), noise)
        return stats, trace.renders

    def parts(self, objects) -> list:
        """What a hypothesis draws: the static scenery, then each object's parts in order."""
        return [*self.model.static_parts, *(p for o in objects for p in o.parts)]

    def render(self, parts, settings: RenderSettings | None = None
               ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """{frame: (rgb, depth)} of these parts for every camera that has a term, lit as
        ``settings`` say (default: the renderer's)."""
        if settings is None or settings is self.model.render:
            return {f: self.renderer.render(parts, cam) for f, cam in self.cameras.items()}
        return {f: self.renderer.render(parts, cam, settings) for f, cam in self.cameras.items()}

    def rendered(self, renders, term: Term) -> np.ndarray:
        """The rendered array a term compares with its observation."""
        return renders[term.frame][_OUTPUT[term.kind]]

    def log_likelihood(
        self, stats: Mapping[tuple[int, str], np.ndarray], noise: Mapping[str, Mapping[str, float]]
    ) -> float:
        return sum(
            self.likelihoods[kind].log_prob(s, noise[kind]) for (_, kind), s in stats.items()
        )


def _empty_image(observed: np.ndarray, background: np.ndarray) -> float:
    """The sum of squared residuals of an image against the empty scene's, which shows the
    background everywhere."""
    r = np.subtract(observed, background, dtype=np.float64)  # exact, and summed in float64
    return float(np.sum(r * r))


class Renders(Mapping):
    """A hypothesis's renders, {frame: (rgb, depth)}, made the first time they are asked for.

    The fast path never reads images back; data-driven births, which look at what a state
    leaves unexplained, do, and for the states they are asked of only. ``pixels`` is the
    fast path's record of the hypothesis's per-pixel terms, for incremental scoring.
    """

    def __init__(self, scorer: ReferenceScorer, objects, pixels: _Pixels | None = None,
                 settings: RenderSettings | None = None) -> None:
        self.scorer, self.objects, self.pixels = scorer, objects, pixels
        self.settings = settings  # the lighting the hypothesis is drawn with (None: fixed)
        self._renders: dict | None = None

    def _all(self) -> dict:
        if self._renders is None:
            self._renders = ReferenceScorer.render(self.scorer, self.scorer.parts(self.objects),
                                                   self.settings)
        return self._renders

    def __getitem__(self, frame):
        return self._all()[frame]

    def __iter__(self):
        return iter(self.scorer.cameras)

    def __len__(self) -> int:
        return len(self.scorer.cameras)


class _Pixels:
    """The per-pixel terms of one hypothesis and their float64 sums, a flat list of floats
    (camera 0's image and depth sums, then camera 1's, ...). Per camera
    the terms are a block (rect, terms), 0 outside rect, or None where all are 0 (as
    ``PixelScorer.render`` gives them). A hypothesis scored incrementally stores only its
    parent's record and the rectangles it re-rendered; its own blocks are made when it
    becomes a parent in turn, so a rejected proposal costs no copy."""

    __slots__ = ("blocks", "key", "parent", "patches", "sums")

    def __init__(self, sums, blocks=None, parent=None, patches=(), key=None) -> None:
        self.sums, self.blocks, self.parent, self.patches = sums, blocks, parent, patches
        self.key = key  # the noise values a per-pixel likelihood's terms were computed at

    def materialise(self) -> list:
        if self.blocks is None:
            blocks = list(self.parent.materialise())
            for c, rect, patch in self.patches:  # at most one per camera
                blocks[c] = _paste(blocks[c], rect, patch)
            self.blocks, self.parent, self.patches = blocks, None, ()
        return self.blocks


def _paste(block, rect, patch):
    """A camera's block with the pixels of rect replaced by patch."""
    if block is None:
        return rect, patch
    old, terms = block
    cover = union(old, rect)
    if cover != old:
        grown = np.zeros((cover[1] - cover[0], cover[3] - cover[2], 2), dtype=terms.dtype)
        grown[old[0] - cover[0] : old[1] - cover[0], old[2] - cover[2] : old[3] - cover[2]] = terms
        old, terms = cover, grown
    else:
        terms = terms.copy()
    terms[rect[0] - old[0] : rect[1] - old[0], rect[2] - old[2] : rect[3] - old[2]] = patch
    return old, terms


def _crop(block, rect):
    """The terms of a camera's block inside rect (0 where rect reaches past the block), or
    None if the two do not meet."""
    if block is None:
        return None
    (r0, r1, c0, c1), terms = block
    if not (rect[0] < r1 and r0 < rect[1] and rect[2] < c1 and c0 < rect[3]):
        return None
    if r0 <= rect[0] and rect[1] <= r1 and c0 <= rect[2] and rect[3] <= c1:
        return terms[rect[0] - r0 : rect[1] - r0, rect[2] - c0 : rect[3] - c0]
    crop = np.zeros((rect[1] - rect[0], rect[3] - rect[2], 2), dtype=terms.dtype)
    a0, a1, b0, b1 = max(rect[0], r0), min(rect[1], r1), max(rect[2], c0), min(rect[3], c1)
    crop[a0 - rect[0] : a1 - rect[0], b0 - rect[2] : b1 - rect[2]] = \
        terms[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0]
    return crop


# Past this fraction of the atlas's pixels, a full render is cheaper than regions.
_INCREMENTAL_AREA = 0.6


class Scorer(ReferenceScorer):
    """The fast path: per-pixel terms and their sums computed on the GL side, incrementally
    where a proposal changes a few objects. Same statistics as ``ReferenceScorer`` (to float32
    rounding in the per-pixel terms; the sums are float64).

    A per-pixel likelihood's terms are computed at the noise values of the hypothesis they
    score (its parent's, for a move of objects); a hypothesis's record keeps them (``key``),
    and a proposal is scored incrementally only from a parent whose terms are at its own noise
    values. A noise move re-runs the terms pass over the whole hypothesis (``rescore``)."""

    def __init__(self, model: Model, observations: Observations, renderer, fast: bool = True):
        super().__init__(model, observations, renderer)
        self.pixels = None
        from ..render import Renderer

        if not fast or not isinstance(renderer, Renderer):
            return
        declared = {t.kind: declared_gl_statistics(t.likelihood) for t in self.terms}
        slow = sorted(kind for kind, found in declared.items() if found is None)
        if slow:
            log.info("the %s likelihood has no GL-side statistics: scoring reads renders back",
                     ", ".join(slow))
            return
        from ..render.drawlist import DrawCache
        from ..render.pixels import PixelScorer

        self.frames = sorted(self.cameras)
        index = {f: i for i, f in enumerate(self.frames)}
        observed = {f: [None, None] for f in self.frames}
        self._constant = {}  # (frame, kind) -> (n, sum of squares against the empty scene)
        self._background = background = np.asarray(renderer.settings.background, dtype="f4")
        for t in self.terms:
            if t.kind == "image":
                observed[t.frame][0] = t.observed
                self._constant[(t.frame, t.kind)] = (t.observed.size,
                                                     _empty_image(t.observed, background))
            else:
                valid = np.ones(t.observed.shape, bool) if t.valid is None else t.valid
                observed[t.frame][1] = np.where(valid, t.observed, np.nan)
                r = np.subtract(t.observed[valid], np.float32(t.camera.depth_max),
                                dtype=np.float64)
                self._constant[(t.frame, t.kind)] = (int(valid.sum()), float(np.sum(r * r)))
        self._slot = {(t.frame, t.kind): (index[t.frame], 0 if t.kind == "image" else 1)
                      for t in self.terms}
        # Per Gaussian term: its key, its place in the flattened (cameras, 2) sums, its count of
        # values and its sum of squares against the empty scene. Per per-pixel term: its key,
        # its place, and the term (whose empty scene's log density depends on the noise).
        self._terms = [(k, 2 * c + kind, float(self._constant[k][0]), self._constant[k][1])
                       for k, (c, kind) in self._slot.items() if k[1] not in self.per_pixel]
        # The same, per white balance: the empty scene shows the background times it.
        self._balanced = {(1.0, 1.0, 1.0): self._terms}
        self._pixel_terms = [((t.frame, t.kind), 2 * self._slot[(t.frame, t.kind)][0]
                              + self._slot[(t.frame, t.kind)][1], t, self.per_pixel.index(t.kind))
                             for t in self.terms if t.kind in self.per_pixel]
        self._fast_at: dict[tuple, bool] = {}  # _fast's answers, by noise key
        self._empty: dict[tuple, float] = {}  # (term key, noise key, balance) -> the empty scene's
        defines = {}
        shaders = {found.shader for found in declared.values() if found.shader}
        for kind, name in (("image", "IMAGE_TERM"), ("depth", "DEPTH_TERM")):
            likelihood = self.likelihoods.get(kind)
            if kind in self.per_pixel:
                defines[name] = likelihood.shader_term
                if kind == "depth" and likelihood.returns:
                    defines["DEPTH_RETURNS"] = 1
                # A modality whose density is defined in, with no observation of it in these
                # data (an RGB-only camera set), still compiles its density's code.
                found = declared_gl_statistics(likelihood)
                if found is not None and found.shader:
                    shaders.add(found.shader)
        self._noise_key = None  # the noise values the programs' uniforms hold
        shaders = sorted(shaders)
        self.pixels = PixelScorer(renderer.settings, [self.cameras[f] for f in self.frames],
                                  [observed[f] for f in self.frames], defines, shaders)
        self.draws = DrawCache([CameraBounds(self.cameras[f]) for f in self.frames])
        static = model.static_parts
        self._static = [self.draws.of_parts(static)] if static else []
        self._static_casters = caster_rows(static)
        # Shadows reach down to the lowest surface a hypothesis has: the static parts' or an
        # object's (``_shadow_rects``).
        self._static_floor = float(world_corners(static)[2].min()) if static else 0.0
        self._area = sum(c.width * c.height for c in self.cameras.values())
        self._token = object()

    def evaluate(self, objects, parent=None, noise=None):
        if self.pixels is None:
            return super().evaluate(objects, parent, noise)
        noise = self._noise(parent, noise)
        key = self._key(noise)
        if not self._fast(noise, key):
            return ReferenceScorer.evaluate(self, objects, noise=noise)
        return (self._from_parent(objects, parent, noise, key)
                or self.evaluate_many([objects], [noise])[0])

    def evaluate_batch(self, requests):
        """``evaluate`` of several (objects, parent) or (objects, parent, noise) requests, in
        order, with the same results: each that its parent can score incrementally is scored
        so (its regions are rendered on their own), and all the others are drawn together
        before one read-back."""
        if self.pixels is None:
            return super().evaluate_batch(requests)
        noises = [self._noise(r[1], r[2] if len(r) > 2 else None) for r in requests]
        out = []
        for (objects, parent, *_), noise in zip(requests, noises):
            key = self._key(noise)
            out.append(self._from_parent(objects, parent, noise, key)
                       if self._fast(noise, key) else None)
        full = [i for i, result in enumerate(out) if result is None]
        if full:
            results = self.evaluate_many([requests[i][0] for i in full], [noises[i] for i in full])
            for i, result in zip(full, results):
                out[i] = result
        return out

    def rescore(self, trace, noise):
        """``ReferenceScorer.rescore`` on the GL side: the terms pass run again over the
        whole hypothesis at the new noise values, lit as the trace is (a noise move leaves
        the lighting; the Gaussian terms' statistics stand)."""
        if (self.pixels is None or all(trace.noise[k] == noise[k] for k in self.per_pixel)
                or not self._fast(noise, self._key(noise))):
            return super().rescore(trace, noise)
        stats, renders = self.evaluate_many([trace.objects], [noise])[0]
        return {k: (v if k[1] in self.per_pixel else trace.stats[k]) for k, v in stats.items()}, \
            renders

    def _from_parent(self, objects, parent, noise, key):
        """``evaluate``'s answer scored incrementally from the parent trace, or None where
        there is no parent of this scorer's, its terms are at other noise values, the lighting
        differs from the parent's (a lighting move changes every pixel) or a full render is
        cheaper."""
        before = getattr(parent, "renders", None)
        if isinstance(before, Renders) and before.scorer is self and before.pixels is not None:
            if before.pixels.key != key:
                return None
            settings = self.settings_for(noise)
            if before.settings is not settings and before.settings.shaded() != settings.shaded():
                return None
            if key is not None:
                self._uniforms(noise, key)
            pixels = self._incremental(parent.objects, objects, before.pixels, settings)
            if pixels is not None:
                return (self._stats(pixels.sums, noise, key, settings),
                        Renders(self, objects, pixels, settings))
        return None

    def evaluate_many(self, hypotheses, noises=None):
        """``evaluate`` for several object sets, whole (no parent), each lit and scored at its
        noise values (default: the model's fixed lighting; per-pixel likelihoods need them)."""
        if noises is None:
            noises = [self._noise(None, None)] * len(hypotheses)
        if self.pixels is None:
            return [super().evaluate(o, noise=n) for o, n in zip(hypotheses, noises)]
        out = []
        # Hypotheses at the same noise values are drawn together: the uniforms hold one set.
        i = 0
        while i < len(hypotheses):
            key = self._key(noises[i])
            j = i + 1
            while j < len(hypotheses) and self._key(noises[j]) == key:
                j += 1
            if key is not None:
                self._uniforms(noises[i], key)
            group = hypotheses[i:j]
            settings = [self.settings_for(n) for n in noises[i:j]]
            lighting = [self._lighting(objects, s) for objects, s in zip(group, settings)]
            blocks, sums = self.pixels.render([self._drawn(objects) for objects in group],
                                              lighting)
            for b, (objects, s) in enumerate(zip(group, settings)):
                flat = sums[b].ravel().tolist()
                out.append((self._stats(flat, noises[i], key, s),
                            Renders(self, objects, _Pixels(flat, blocks[b], key=key), s)))
            i = j
        return out

    # -- helpers -------------------------------------------------------------------------------

    def _drawn(self, objects) -> list:
        return [*self._static, *(self.draws.of_object(o) for o in objects)]

    def _key(self, noise) -> tuple | None:
        """The noise values the per-pixel terms depend on (None: there are none)."""
        if not self.per_pixel:
            return None
        return tuple(self.likelihoods[k].key(noise[k]) for k in self.per_pixel)

    def _fast(self, noise, key) -> bool:
        """Whether the GL side can score the per-pixel likelihoods at these noise values:
        inside their support, with every uniform a finite float32 (a probability of exactly
        0 or 1, or a scale beyond float32, goes to the float64 reference)."""
        if key is None:
            return True
        found = self._fast_at.get(key)
        if found is None:
            found = True
            for kind in self.per_pixel:
                likelihood = self.likelihoods[kind]
                values = likelihood.values(noise[kind])
                # depth_max only shifts a log that is finite for any camera's
                found = found and likelihood.in_support(values) and bool(np.all(np.isfinite(
                    np.float32(self._kind_uniforms(kind, values, 8.0)))))
            if len(self._fast_at) > 256:
                self._fast_at.clear()
            self._fast_at[key] = found
        return found

    def _kind_uniforms(self, kind, values, depth_max):
        likelihood = self.likelihoods[kind]
        k, high = (3, 1.0) if kind == "image" else (1, depth_max)
        with np.errstate(all="ignore"):
            out = likelihood.uniforms(values, k, high)
            if kind == "depth" and likelihood.returns:
                m, q = values["missing"], values["missing_far"]
                out = (*out, *(math.log(p) if p > 0.0 else -math.inf
                               for p in (m, 1.0 - m, q, 1.0 - q)))
        return out

    def _uniforms(self, noise, key) -> None:
        """Set every camera's per-pixel likelihood uniforms to these noise values."""
        if key == self._noise_key:
            return
        for c, f in enumerate(self.frames):
            camera = self.cameras[f]
            uniforms = {}
            for kind in self.per_pixel:
                values = self.likelihoods[kind].values(noise[kind])
                found = self._kind_uniforms(kind, values, float(camera.depth_max))
                uniforms[f"{kind}_noise"] = tuple(found[:4])
                if len(found) > 4:
                    uniforms["depth_returns"] = tuple(found[4:])
            self.pixels.set_noise(c, uniforms)
        self._noise_key = key

    def _empty_scene(self, key, term: Term, values, noise_key, balance) -> float:
        """The log density of a term's observation given the empty scene, at these noise
        values and white balance (numpy, float64; the GL-side terms are relative to it)."""
        found = self._empty.get((key, noise_key, balance))
        if found is None:
            if term.kind == "image":
                shown = (self._background * np.asarray(balance, dtype="f4")).astype("f4")
                rendered = np.broadcast_to(shown, term.observed.shape)
            else:
                rendered = np.full(term.observed.shape, np.float32(term.camera.depth_max))
            found = term.likelihood.log_density(term.observed, rendered, term.valid, values,
                                                term.camera.depth_max)
            if len(self._empty) > 256:  # noise values visited long ago
                self._empty.clear()
            self._empty[(key, noise_key, balance)] = found
        return found

    def _lighting(self, objects, settings: RenderSettings) -> bytes:
        """The ``Lighting`` block of a hypothesis: its settings and, with shadows, every
        part's caster rows (each object's worked out once, kept in its cache)."""
        if not settings.shadows:
            return block(settings)
        rows = [self._static_casters]
        for o in objects:
            found = o.cache.get(caster_rows)
            if found is None:
                found = o.cache[caster_rows] = caster_rows(o.parts)
            rows.append(found)
        return block(settings, b"".join(rows))

    def _stats(self, sums: list[float], noise=None, key=None,
               settings: RenderSettings | None = None) -> dict[tuple[int, str], np.ndarray]:
        terms, balance = self._terms, (1.0, 1.0, 1.0)
        if settings is not None and settings.balance != balance:
            balance = tuple(settings.balance)
            terms = self._balanced_terms(balance)
        out = {term: np.array((n, max(empty + sums[i], 0.0))) for term, i, n, empty in terms}
        for term, i, t, k in self._pixel_terms:
            out[term] = np.array([*key[k], self._empty_scene(term, t, noise[t.kind], key[k],
                                                             balance) + sums[i]])
        return out

    def _balanced_terms(self, balance) -> list:
        """``_terms`` with the empty scene's sums for a background shown times ``balance``
        (a few kept: a chain's lighting moves visit a new balance at each acceptance)."""
        found = self._balanced.get(balance)
        if found is None:
            if len(self._balanced) > 64:
                self._balanced = {(1.0, 1.0, 1.0): self._terms}
            shown = (self._background * np.asarray(balance, dtype="f4")).astype("f4")
            by_key = {(t.frame, t.kind): t for t in self.terms}
            found = self._balanced[balance] = [
                (k, i, n, _empty_image(by_key[k].observed, shown) if k[1] == "image" else empty)
                for k, i, n, empty in self._terms]
        return found

    def _shadow_rects(self, changed, objects, old_objects, settings: RenderSettings):
        """Per camera, the rectangle of pixels the changed objects' shadows can darken, before
        and after the move (None: none); False when no rectangle bounds them (the light at or
        below the horizon, or a corner behind a camera), and the whole image must be drawn."""
        corners_of = self._corners
        floor = min(self._static_floor,
                    *(corners_of(o)[1] for o in (*old_objects, *objects)))
        rects = [None] * len(self.frames)
        for o in changed:
            volume = shadow_corners(corners_of(o)[0], settings.direction, floor)
            if volume is None:
                return False
            for c, bounds in enumerate(self.draws.bounds):
                rect = bounds.rect_of(volume)
                if rect == bounds.full:
                    return False
                rects[c] = union(rects[c], rect)
        return rects

    @staticmethod
    def _corners(obj):
        """An object's parts' bounding-box corners (4, 8n) and their lowest height, cached."""
        found = obj.cache.get(world_corners)
        if found is None:
            corners = world_corners(obj.parts) if obj.parts else np.zeros((4, 0))
            low = float(corners[2].min()) if obj.parts else np.inf
            found = obj.cache[world_corners] = (corners, low)
        return found

    def _incremental(self, old_objects, objects, before: _Pixels,
                     settings: RenderSettings | None = None) -> _Pixels | None:
        """The new hypothesis's record from its parent's, re-rendering only the rectangles
        the changed objects cover before or after, and with shadows the rectangles their
        shadows can reach; None when a full render is cheaper."""
        settings = settings or self.model.render
        if len(old_objects) == len(objects):
            # The usual move changes objects in place: those that differ, at either end.
            changed = [o for pair in zip(old_objects, objects) if pair[0] is not pair[1]
                       for o in pair]
        else:
            old_ids, new_ids = {id(o) for o in old_objects}, {id(o) for o in objects}
            changed = [o for o in old_objects if id(o) not in new_ids]
            changed += [o for o in objects if id(o) not in old_ids]
        if not changed:
            return before
        of_object = self.draws.of_object
        rects = of_object(changed[0]).rects
        for o in changed[1:]:
            rects = [union(r, s) for r, s in zip(rects, of_object(o).rects)]
        if settings.shadows:
            shadows = self._shadow_rects(changed, objects, old_objects, settings)
            if shadows is False:
                return None
            rects = [union(r, s) for r, s in zip(rects, shadows)]
        area = 0
        for r in rects:
            if r is not None:
                area += (r[1] - r[0]) * (r[3] - r[2])
        if area > _INCREMENTAL_AREA * self._area:
            return None
        if area == 0:
            return before  # no camera sees the change
        blocks = before.materialise()
        patches = self.pixels.render_regions(self._drawn(objects), rects,
                                             self._lighting(objects, settings))
        # The sums as plain floats: a move's few additions cost less than numpy's indexing.
        sums = list(before.sums)
        kept = []
        change = self.pixels.change
        for c, patch in enumerate(patches):
            if patch is not None:
                rect = rects[c]
                image, depth = change(patch, _crop(blocks[c], rect))
                sums[2 * c] += image
                sums[2 * c + 1] += depth
                kept.append((c, rect, patch))
        return _Pixels(sums, parent=before, patches=tuple(kept), key=before.key)


class PriorScorer:
    """A scorer with no observations: the chain then targets the prior, which is how the
    sampler is verified (prior recovery) and how ``sppl verify`` checks a user's model."""

    terms: list[Term] = []
    cameras: dict = {}

    def evaluate(self, objects, parent=None, noise=None):
        return {}, {}

    def evaluate_batch(self, requests):
        return [({}, {}) for _ in requests]

    def statistics(self, objects) -> dict[tuple[int, str], np.ndarray]:
        return {}

    def log_likelihood(self, stats, noise) -> float:
        return 0.0
