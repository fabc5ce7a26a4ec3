"""Traces: one hypothesis about the scene, with every random choice and its log-probability.

The latent scene is a *set* of objects. Its prior density, with respect to the unit-rate
marked Poisson process over (class, parameters), is

    exp(-sum_c lambda_c) * prod_objects lambda_c * p_c(phi)       (times the no-overlap indicator)

so a trace's score is

    score = log p(choices, observations)
          = -sum_c lambda_c + sum_objects [log lambda_c + log p_c(phi)]
            + sum_sensors log p(noise) + log p(observations | scene, noise).

The sign is + log-probability throughout. ``objects`` is a tuple only for storage: its order
carries no meaning, and no acceptance ratio counts orderings (see docs/inference.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import shapely

from .geometry import Part, footprints_overlap, ground_points
from .types import Model, ObjectClass


@dataclass(frozen=True, eq=False)
class SceneObject:
    """One object: its class and parameter values, and what follows from them."""

    cls: ObjectClass
    values: Mapping[str, Any]
    log_prior: float  # log lambda_c + log p_c(phi)
    parts: tuple[Part, ...] = field(repr=False)
    # Whether the no-overlap constraint applies to this object (it has a footprint).
    constrained: bool = field(repr=False, default=False)
    # What renderers work out from the object once, by who worked it out (a scorer's draw
    # list, say): it lives and dies with the object. Not copied by dataclasses.replace.
    cache: dict = field(repr=False, default_factory=dict, init=False)

    # The footprint is made only when a check needs it: a chain proposes thousands of objects,
    # most of them far from every other, and the bounding box tells those apart first.
    @cached_property
    def footprint(self) -> shapely.Polygon | None:
        if not self.constrained:
            return None
        return shapely.Polygon(self.cls.footprint(self.values, self.parts))

    @cached_property
    def extent(self) -> tuple[float, float, float, float] | None:
        """(x0, y0, x1, y1): the footprint's bounding box on the ground."""
        if not self.constrained:
            return None
        if self.cls.footprint_fn is not None:
            points = self.cls.footprint(self.values)
        else:
            points = ground_points(self.parts)
        (x0, y0), (x1, y1) = points.min(axis=0), points.max(axis=0)
        return float(x0), float(y0), float(x1), float(y1)

    def as_dict(self, seen: bool | None = None) -> dict[str, Any]:
        out = {"class": self.cls.name, "params": {k: _plain(v) for k, v in self.values.items()}}
        if seen is not None:
            out["seen"] = seen  # whether some camera sees it (sppl.render.seen)
        return out


def _plain(v: Any) -> Any:
    return float(v) if isinstance(v, (float, np.floating)) else v


def make_object(model: Model, cls: ObjectClass, values: Mapping[str, Any]) -> SceneObject:
    values = dict(values)
    log_prior = math.log(cls.rate) + cls.log_prior(values) if cls.rate > 0 else -math.inf
    if not math.isfinite(log_prior):
        return SceneObject(cls, values, -math.inf, ())
    parts = cls.parts(values)
    # A floating object has no footprint on the ground, so the constraint leaves it out.
    constrained = model.no_overlap and not cls.floating
    return SceneObject(cls, values, log_prior, parts, constrained)


def overlaps_any(obj: SceneObject, others) -> bool:
    if not obj.constrained:
        return False
    a = obj.extent
    for o in others:
        if o is obj or not o.constrained:
            continue
        b = o.extent
        # Footprints lie inside their boxes: boxes that share no area keep them apart.
        if a[0] >= b[2] or b[0] >= a[2] or a[1] >= b[3] or b[1] >= a[3]:
            continue
        if footprints_overlap(obj.footprint, o.footprint):
            return True
    return False


def counts_allowed(model: Model, objects) -> bool:
    """Whether the numbers of objects keep the model's count constraints: fixed counts, a
    class's upper bound, and the bound on the total."""
    objects = list(objects)
    if model.max_objects is not None and len(objects) > model.max_objects:
        return False
    bounded = [c for c in model.classes if c.count is not None or c.max_count is not None]
    if not bounded:
        return True
    n = dict.fromkeys(model.classes, 0)
    for o in objects:
        n[o.cls] = n.get(o.cls, 0) + 1
    return all(
        (c.count is None or n[c] == c.count) and (c.max_count is None or n[c] <= c.max_count)
        for c in bounded
    )


def scene_is_valid(objects) -> bool:
    """No two footprints overlap (vacuously true when the model has no such constraint)."""
    objs = list(objects)
    return not any(overlaps_any(o, objs[i + 1 :]) for i, o in enumerate(objs))


@dataclass(frozen=True, eq=False)
class Trace:
    """A full hypothesis: objects, noise parameters, and the likelihood's cached statistics.

    ``stats`` maps (frame index, sensor kind) to that likelihood's sufficient statistics for
    the current objects, so that a noise move re-scores without rendering.
    """

    model: Model = field(repr=False)
    objects: tuple[SceneObject, ...]
    noise: Mapping[str, Mapping[str, float]]
    stats: Mapping[tuple[int, str], np.ndarray]
    log_prior: float
    log_likelihood: float
    # The renders the statistics came from, {frame: (rgb, depth)}, for proposals that look at
    # what the hypothesis leaves unexplained; and a cache of what is derived from them.
    renders: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = field(default=None, repr=False)
    cache: dict = field(default_factory=dict, repr=False)

    @property
    def score(self) -> float:
        return self.log_prior + self.log_likelihood

    @property
    def n_objects(self) -> int:
        return len(self.objects)

    def counts(self, class_names) -> dict[str, int]:
        c = dict.fromkeys(class_names, 0)
        for o in self.objects:
            c[o.cls.name] += 1
        return c

    def as_dict(self, seen: list[bool] | None = None) -> dict[str, Any]:
        """The scene as plain data; ``seen``, if given, marks each object seen or not."""
        marks = [None] * len(self.objects) if seen is None else seen
        return {
            "objects": [o.as_dict(s) for o, s in zip(self.objects, marks)],
            "noise": {k: {n: float(v) for n, v in p.items()} for k, p in self.noise.items()},
        }


def objects_log_prior(model: Model, objects) -> float:
    # Fixed and bounded counts restrict the Poisson prior to the allowed counts; the
    # normalising constant that this leaves out does not depend on the state.
    if not counts_allowed(model, objects):
        return -math.inf
    return -sum(c.rate for c in model.classes) + sum(o.log_prior for o in objects)


def noise_log_prior(model: Model, noise: Mapping[str, Mapping[str, float]]) -> float:
    total = 0.0
    for kind, parameters in model.noise_groups:
        for p in parameters:
            total += p.log_prob(noise[kind][p.name])
    return total
