"""Where the occlusion example's hidden cone may stand: the cube's shadow, and the distances
along the camera's ray that the one image allows.

Used by examples/occlusion/experiment.py (the table and figures of docs/occlusion.md) and by
benchmarks/time_to_solution.py (what counts as the hidden cone found).

The image shows only the cone's tip above the cube, and a tip fixes a direction, not a distance:
a cone whose apex lies on the same camera ray and whose sides have the same slope (radius over
height) coincides, above the ground, with the true cone scaled about the camera, so wherever the
rest of it is hidden it draws the very same pixels. ``along_ray`` makes that cone at a given
distance, ``profile`` scores a scene with it in place of the hidden one at each of a range of
distances, and ``allowed`` reads off the distances the observations cannot tell apart.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

SHADOW_DEGREES = 6.0  # how far from the ray through the hidden object still counts as behind
ALLOWED_NATS = 10.0  # a distance is allowed while the profile stays this close to its best
PROFILE_STEP = 0.02  # metres between the distances the profile scores


class Shadow:
    """The ground behind ``front`` as seen from ``eye`` (x, y), near the ray to ``hidden``:
    farther from the eye than the front object's centre by 0.3 m, nearer than ``far``, and
    within ``degrees`` of the ray."""

    def __init__(self, eye, front, hidden, far: float, degrees: float = SHADOW_DEGREES) -> None:
        self.eye = np.asarray(eye, dtype=float)[:2]
        self.far = far
        self.degrees = degrees
        self.ray = self._xy(hidden) - self.eye
        self.ray /= np.linalg.norm(self.ray)
        self.beyond = float(np.linalg.norm(self._xy(front) - self.eye)) + 0.3

    @staticmethod
    def _xy(o) -> np.ndarray:
        return np.array([o["params"]["x"], o["params"]["y"]], dtype=float)

    def distance(self, o) -> float:
        """Ground distance of ``o`` from the eye."""
        return float(np.linalg.norm(self._xy(o) - self.eye))

    def contains(self, o) -> bool:
        v = self._xy(o) - self.eye
        d = float(np.linalg.norm(v))
        angle = np.degrees(np.arccos(np.clip(v @ self.ray / max(d, 1e-9), -1, 1)))
        return self.beyond < d < self.far and angle <= self.degrees

    def objects_in(self, objects) -> list:
        return [o for o in objects if self.contains(o)]


def profile_distances(shadow: Shadow) -> np.ndarray:
    """The profile's distances: every PROFILE_STEP from the front object's centre to the far
    end of the shadow."""
    return np.arange(shadow.beyond - 0.3, shadow.far + 1e-9, PROFILE_STEP)


def along_ray(eye, cone: Mapping[str, Any], distance: float) -> dict[str, Any] | None:
    """The cone standing ``distance`` metres (on the ground) from the camera at ``eye`` (x, y, z)
    that shows the same tip as ``cone``: its apex on the camera's ray through ``cone``'s apex,
    its radius over height the same. None where that apex would be at or below the ground."""
    eye = np.asarray(eye, dtype=float)
    p = cone["params"]
    apex = np.array([p["x"], p["y"], p["h"]], dtype=float)
    t = distance / float(np.linalg.norm(apex[:2] - eye[:2]))
    x, y, h = eye + t * (apex - eye)
    if h <= 0:
        return None
    params = dict(p, x=float(x), y=float(y), h=float(h), r=float(p["r"] / p["h"] * h))
    return {"class": cone["class"], "params": params}


def profile(model, observations, scene: Mapping[str, Any], place: int | None, eye,
            cone: Mapping[str, Any],
            distances: Sequence[float]) -> list[tuple[float, float, float]]:
    """(distance, log prior, log likelihood) of ``scene`` (``{"objects", "noise"}``) with its
    object ``place`` replaced by ``along_ray(eye, cone, distance)`` (added where ``place`` is
    None), for each distance at which that cone stands above the ground; the log prior is
    -inf where its footprint overlaps another's (the model's no-overlap constraint, which a
    trace made from given objects does not check)."""
    from sppl import Renderer, Sampler, Scorer, objects_from_dict

    objects = list(scene["objects"])
    renderer = Renderer(model.render)
    try:
        sampler = Sampler(model, Scorer(model, observations, renderer), np.random.default_rng(0))
        rows = []
        for d in distances:
            moved = along_ray(eye, cone, float(d))
            if moved is None:
                continue
            kept = objects[:place] + objects[place + 1:] if place is not None else objects
            objects_now = objects_from_dict(model, {"objects": [*kept, moved]})
            trace = sampler.make_trace(objects_now, scene["noise"])
            log_prior = float(trace.log_prior)
            if model.no_overlap and _overlap(objects_now):
                log_prior = -math.inf
            rows.append((float(d), log_prior, float(trace.log_likelihood)))
        return rows
    finally:
        renderer.release()


def _overlap(objects) -> bool:
    """Whether two of the objects' footprints share area (as the no-overlap constraint says)."""
    feet = [o.footprint for o in objects if o.footprint is not None]
    return any(a.intersects(b) and a.intersection(b).area > 1e-12
               for i, a in enumerate(feet) for b in feet[i + 1:])


def allowed(rows: Sequence[tuple[float, float, float]],
            nats: float = ALLOWED_NATS) -> tuple[float, float]:
    """The distances around the profile's best over which its log joint stays within ``nats``
    of that best: (nearest, farthest), the ends being the last grid points inside."""
    joint = np.array([lp + ll for _, lp, ll in rows])
    best = int(np.argmax(joint))
    lo = hi = best
    while lo > 0 and joint[lo - 1] >= joint[best] - nats:
        lo -= 1
    while hi < len(rows) - 1 and joint[hi + 1] >= joint[best] - nats:
        hi += 1
    return rows[lo][0], rows[hi][0]
