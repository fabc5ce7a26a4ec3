"""What an object contributes to each camera's pass, worked out once per object.

A chain proposes thousands of hypotheses that share all but one object, and the objects are
immutable, so an object's instance rows (its parts' matrices and colours, ready for the GPU) and
the screen rectangle it covers in each camera are computed the first time it is drawn and kept
while the object lives. A pass then draws only the objects whose rectangle meets the region it
renders: the whole image, or the few pixels a move can change.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..geometry import Part
from .bounds import INSIDE_MARGIN, MARGIN, CameraBounds, Rect, contains, world_corners
from .pixels import instance_rows


@dataclass(frozen=True, eq=False)
class Drawn:
    rows: dict[str, np.ndarray]  # per primitive, the instance rows of its parts, in order
    rects: tuple[Rect | None, ...]  # per camera, the pixels it can cover (None: out of view)
    # Per camera: whether the camera may be inside one of the parts, where back faces show.
    inside: tuple[bool, ...]


class DrawCache:
    def __init__(self, bounds: Sequence[CameraBounds]) -> None:
        self.bounds = list(bounds)
        # Every camera's projection stacked, so that an object's corners go into all cameras
        # in one product, and every camera's rectangle is found in one pass over them.
        self._project = np.concatenate([b.pixels_from_world for b in self.bounds])
        self._near = np.array([b.near for b in self.bounds])
        self._positions = np.array([b.position for b in self.bounds])  # (cameras, 3)
        self._objects: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def of_object(self, obj) -> Drawn:
        drawn = self._objects.get(obj)
        if drawn is None:
            drawn = self._objects[obj] = self.of_parts(obj.parts)
        return drawn

    def of_parts(self, parts: Sequence[Part]) -> Drawn:
        n = len(self.bounds)
        if not parts:
            return Drawn({}, (None,) * n, (False,) * n)
        corners = world_corners(parts)
        return Drawn(instance_rows(parts), self.rects(corners), self._inside(parts, corners))

    def rects(self, corners: np.ndarray) -> tuple[Rect | None, ...]:
        """Per camera, ``CameraBounds.rect_of(corners)``, for all cameras at once."""
        n = len(self.bounds)
        points = (self._project @ corners).reshape(n, 3, -1)
        w = points[:, 2]
        behind = np.any(w <= self._near[:, None], axis=1) | ~np.all(np.isfinite(points),
                                                                     axis=(1, 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = points[:, 0] / w, points[:, 1] / w
        spans = np.stack([u.min(axis=1), u.max(axis=1), v.min(axis=1), v.max(axis=1)], axis=1)
        out = []
        for b, far_away, (u0, u1, v0, v1) in zip(self.bounds, behind.tolist(), spans.tolist()):
            if far_away:
                out.append(b.full)
                continue
            c0, c1 = max(math.floor(u0) - MARGIN, 0), min(math.ceil(u1) + MARGIN, b.width)
            r0, r1 = max(math.floor(v0) - MARGIN, 0), min(math.ceil(v1) + MARGIN, b.height)
            out.append(None if c0 >= c1 or r0 >= r1 else (r0, r1, c0, c1))
        return tuple(out)

    def _inside(self, parts: Sequence[Part], corners: np.ndarray) -> tuple[bool, ...]:
        """Per camera, whether it may be inside one of the parts (``contains``), asking
        ``contains`` only of the parts whose box the camera is near (``near_box``)."""
        world = corners[:3].reshape(3, len(parts), 8)
        reach = 3.0 * INSIDE_MARGIN
        lo, hi = world.min(axis=2) - reach, world.max(axis=2) + reach  # (3, parts)
        near = np.all((self._positions[:, :, None] >= lo) & (self._positions[:, :, None] <= hi),
                      axis=1)  # (cameras, parts)
        if not near.any():
            return (False,) * len(self.bounds)
        return tuple(any(contains(p, b.position) for p, close in zip(parts, row) if close)
                     for b, row in zip(self.bounds, near.tolist()))
