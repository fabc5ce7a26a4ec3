"""The likelihood of a hypothesis: render it for every camera and compare with the observations.

Analysis by synthesis (thesis 3.3): each frame is rendered once per hypothesis, giving RGB and
depth together, and each of the frame's modalities that the model has a sensor for is reduced to
its likelihood's sufficient statistics. The statistics are cached on the trace, so the noise
moves re-score without rendering.

Two paths compute the same statistics. ``ReferenceScorer`` reads every camera's images back and
calls the likelihood's ``statistics`` in numpy: slow and obviously right. ``Scorer`` computes the
per-pixel terms on the GL side (``sppl.render.pixels``) for every likelihood that has a GL-side
version (``likelihoods.gpu_statistics``), and given the trace a proposal comes from it re-renders
only the pixels the changed objects covered before or cover now. It falls back to the
reference path for any other likelihood, and for renderers that are not ``Renderer``. The
images themselves are then rendered only when something asks for them (``Renders``).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .errors import ObservationError
from .likelihoods import Likelihood, get_likelihood, gpu_statistics
from .model import Model
from .observations import Observations
from .render.bounds import CameraBounds, union

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

    def evaluate(self, objects, parent=None):
        """Render the objects for every camera; return the likelihood statistics of every term
        and the renders, as (stats, {frame: (rgb, depth)}). ``parent``, the trace the objects
        were proposed from, lets a fast scorer work incrementally; this one ignores it."""
        parts = self.parts(objects)
        rendered = self.render(parts)
        stats = {
            (t.frame, t.kind): t.likelihood.statistics(
                t.observed, rendered[t.frame][_OUTPUT[t.kind]], t.valid
            )
            for t in self.terms
        }
        return stats, rendered

    def evaluate_batch(self, requests):
        """``evaluate`` of several (objects, parent) pairs, in order. This path renders one
        hypothesis at a time; ``Scorer`` draws them together where it can."""
        return [self.evaluate(objects, parent=parent) for objects, parent in requests]

    def statistics(self, objects) -> dict[tuple[int, str], np.ndarray]:
        return self.evaluate(objects)[0]

    def parts(self, objects) -> list:
        """What a hypothesis draws: the static scenery, then each object's parts in order."""
        return [*self.model.static_parts, *(p for o in objects for p in o.parts)]

    def render(self, parts) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """{frame: (rgb, depth)} of these parts for every camera that has a term."""
        return {f: self.renderer.render(parts, cam) for f, cam in self.cameras.items()}

    def rendered(self, renders, term: Term) -> np.ndarray:
        """The rendered array a term compares with its observation."""
        return renders[term.frame][_OUTPUT[term.kind]]

    def log_likelihood(
        self, stats: Mapping[tuple[int, str], np.ndarray], noise: Mapping[str, Mapping[str, float]]
    ) -> float:
        return sum(
            self.likelihoods[kind].log_prob(s, noise[kind]) for (_, kind), s in stats.items()
        )


class Renders(Mapping):
    """A hypothesis's renders, {frame: (rgb, depth)}, made the first time they are asked for.

    The fast path never reads images back; data-driven births, which look at what a state
    leaves unexplained, do, and for the states they are asked of only. ``pixels`` is the
    fast path's record of the hypothesis's per-pixel terms, for incremental scoring.
    """

    def __init__(self, scorer: ReferenceScorer, objects, pixels: _Pixels | None = None) -> None:
        self.scorer, self.objects, self.pixels = scorer, objects, pixels
        self._renders: dict | None = None

    def _all(self) -> dict:
        if self._renders is None:
            self._renders = ReferenceScorer.render(self.scorer, self.scorer.parts(self.objects))
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

    __slots__ = ("blocks", "parent", "patches", "sums")

    def __init__(self, sums, blocks=None, parent=None, patches=()) -> None:
        self.sums, self.blocks, self.parent, self.patches = sums, blocks, parent, patches

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
    rounding in the per-pixel terms; the sums are float64)."""

    def __init__(self, model: Model, observations: Observations, renderer, fast: bool = True):
        super().__init__(model, observations, renderer)
        self.pixels = None
        from .render import Renderer

        if not fast or not isinstance(renderer, Renderer):
            return
        slow = sorted({t.kind for t in self.terms if gpu_statistics(t.likelihood) is None})
        if slow:
            log.info("the %s likelihood has no GL-side statistics: scoring reads renders back",
                     ", ".join(slow))
            return
        from .render.drawlist import DrawCache
        from .render.pixels import PixelScorer

        self.frames = sorted(self.cameras)
        index = {f: i for i, f in enumerate(self.frames)}
        observed = {f: [None, None] for f in self.frames}
        self._constant = {}  # (frame, kind) -> (n, sum of squares against the empty scene)
        background = np.asarray(renderer.settings.background, dtype="f4")
        for t in self.terms:
            if t.kind == "image":
                observed[t.frame][0] = t.observed
                r = np.subtract(t.observed, background, dtype=np.float64)  # exact
                self._constant[(t.frame, t.kind)] = (t.observed.size, float(np.sum(r * r)))
            else:
                valid = np.ones(t.observed.shape, bool) if t.valid is None else t.valid
                observed[t.frame][1] = np.where(valid, t.observed, np.nan)
                r = np.subtract(t.observed[valid], np.float32(t.camera.depth_max),
                                dtype=np.float64)
                self._constant[(t.frame, t.kind)] = (int(valid.sum()), float(np.sum(r * r)))
        self._slot = {(t.frame, t.kind): (index[t.frame], 0 if t.kind == "image" else 1)
                      for t in self.terms}
        # Per term: its key, its place in the flattened (cameras, 2) sums, its count of values
        # and its sum of squares against the empty scene.
        self._terms = [(k, 2 * c + kind, float(self._constant[k][0]), self._constant[k][1])
                       for k, (c, kind) in self._slot.items()]
        self.pixels = PixelScorer(renderer.settings, [self.cameras[f] for f in self.frames],
                                  [observed[f] for f in self.frames])
        self.draws = DrawCache([CameraBounds(self.cameras[f]) for f in self.frames])
        static = model.static_parts
        self._static = [self.draws.of_parts(static)] if static else []
        self._area = sum(c.width * c.height for c in self.cameras.values())
        self._token = object()

    def evaluate(self, objects, parent=None):
        if self.pixels is None:
            return super().evaluate(objects)
        return self._from_parent(objects, parent) or self.evaluate_many([objects])[0]

    def evaluate_batch(self, requests):
        """``evaluate`` of several (objects, parent) pairs, in order, with the same results:
        each that its parent can score incrementally is scored so (its regions are rendered
        on their own), and all the others are drawn together before one read-back."""
        if self.pixels is None:
            return super().evaluate_batch(requests)
        out = [self._from_parent(objects, parent) for objects, parent in requests]
        full = [i for i, result in enumerate(out) if result is None]
        if full:
            for i, result in zip(full, self.evaluate_many([requests[i][0] for i in full])):
                out[i] = result
        return out

    def _from_parent(self, objects, parent):
        """``evaluate``'s answer scored incrementally from the parent trace, or None where
        there is no parent of this scorer's or a full render is cheaper."""
        before = getattr(parent, "renders", None)
        if isinstance(before, Renders) and before.scorer is self and before.pixels is not None:
            pixels = self._incremental(parent.objects, objects, before.pixels)
            if pixels is not None:
                return self._stats(pixels.sums), Renders(self, objects, pixels)
        return None

    def evaluate_many(self, hypotheses):
        """``evaluate`` for several object sets, whole (no parent)."""
        if self.pixels is None:
            return [super().evaluate(objects) for objects in hypotheses]
        blocks, sums = self.pixels.render([self._drawn(objects) for objects in hypotheses])
        out = []
        for b, objects in enumerate(hypotheses):
            flat = sums[b].ravel().tolist()
            out.append((self._stats(flat), Renders(self, objects, _Pixels(flat, blocks[b]))))
        return out

    # -- helpers -------------------------------------------------------------------------------

    def _drawn(self, objects) -> list:
        return [*self._static, *(self.draws.of_object(o) for o in objects)]

    def _stats(self, sums: list[float]) -> dict[tuple[int, str], np.ndarray]:
        return {key: np.array((n, max(empty + sums[i], 0.0)))
                for key, i, n, empty in self._terms}

    def _incremental(self, old_objects, objects, before: _Pixels) -> _Pixels | None:
        """The new hypothesis's record from its parent's, re-rendering only the rectangles
        the changed objects cover before or after; None when a full render is cheaper."""
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
        area = 0
        for r in rects:
            if r is not None:
                area += (r[1] - r[0]) * (r[3] - r[2])
        if area > _INCREMENTAL_AREA * self._area:
            return None
        if area == 0:
            return before  # no camera sees the change
        blocks = before.materialise()
        patches = self.pixels.render_regions(self._drawn(objects), rects)
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
        return _Pixels(sums, parent=before, patches=tuple(kept))


class PriorScorer:
    """A scorer with no observations: the chain then targets the prior, which is how the
    sampler is verified (prior recovery) and how ``sppl verify`` checks a user's model."""

    terms: list[Term] = []
    cameras: dict = {}

    def evaluate(self, objects, parent=None):
        return {}, {}

    def evaluate_batch(self, requests):
        return [({}, {}) for _ in requests]

    def statistics(self, objects) -> dict[tuple[int, str], np.ndarray]:
        return {}

    def log_likelihood(self, stats, noise) -> float:
        return 0.0
