"""Scenes drawn from a model's prior conditioned on their number of objects and on every object
being in view of every camera: the scenes a benchmark can fairly ask a sampler to find (an
object no camera sees is only the prior's to place).

Given the count, each object's class is drawn by the classes' rates and its parameters from
its prior until its centre is inside every image, and the whole scene is redrawn until it is
a valid scene of the model (no two footprints overlap, the count constraints hold)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from sppl.model.trace import counts_allowed, make_object, scene_is_valid

MARGIN = 6  # pixels: an object's centre at least this far inside every image


def in_view(objects, cameras, margin: float = MARGIN) -> bool:
    """Every object's centre (its parts' mean, half way up) inside every camera's image."""
    for o in objects:
        centre = np.mean([p.matrix[:3] @ (0.0, 0.0, 0.5, 1.0) for p in o.parts], axis=0)
        for spec in cameras:
            cam = spec.camera
            (u, v), depth = (a[0] for a in cam.project(centre))
            if not (depth > 0 and margin <= u <= cam.width - margin
                    and margin <= v <= cam.height - margin):
                return False
    return True


def draw_in_view(model, cameras, count: int, rng: np.random.Generator, max_tries: int = 10_000):
    """One scene of ``count`` objects, each in view of every camera (a list of SceneObject)."""
    rates = np.array([c.rate for c in model.classes], dtype=float)
    for _ in range(max_tries):
        objects = []
        for _ in range(count):
            cls = model.classes[rng.choice(len(rates), p=rates / rates.sum())]
            while not in_view([o := make_object(model, cls, cls.sample_prior(rng))], cameras):
                pass
            objects.append(o)
        if counts_allowed(model, objects) and scene_is_valid(objects):
            return objects
    raise RuntimeError(f"no valid scene of {count} objects in view in {max_tries} draws")
