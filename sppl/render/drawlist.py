"""What an object contributes to each camera's pass, worked out once per object.

A chain proposes thousands of hypotheses that share all but one object, and the objects are
immutable, so an object's instance rows (its parts' matrices and colours, ready for the GPU) and
the screen rectangle it covers in each camera are computed the first time it is drawn and kept
in the object's cache, for as long as it lives. A pass then draws only the objects whose
rectangle meets the region it renders: the whole image, or the few pixels a move can change.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from math import ceil, floor
from operator import truediv
from typing import NamedTuple

import numpy as np

from ..model.geometry import Part
from .bounds import (
    INSIDE_MARGIN,
    MARGIN,
    CameraBounds,
    Rect,
    contains,
    unit_corners,
    world_corners,
)
from .kernels import compiled
from .pixels import instance_rows


class Drawn(NamedTuple):
    """What an object contributes to each camera's pass. A named tuple: one is made for every
    object a chain proposes, and a frozen dataclass costs several times as much to make."""

    rows: dict[str, bytes]  # per primitive, the instance rows of its parts, in order, packed
    rects: tuple[Rect | None, ...]  # per camera, the pixels it can cover (None: out of view)
    # Per camera: whether the camera may be inside one of the parts, where back faces show.
    inside: tuple[bool, ...]


class DrawCache:
    def __init__(self, bounds: Sequence[CameraBounds]) -> None:
        self.bounds = list(bounds)
        # Every camera's projection stacked, so that an object's corners go into all cameras
        # in one product.
        self._project = np.concatenate([b.pixels_from_world for b in self.bounds])
        self._positions = [tuple(float(x) for x in b.position) for b in self.bounds]
        self._limits = tuple((float(b.near), b.width, b.height) for b in self.bounds)
        self.compiled = compiled

    def of_object(self, obj) -> Drawn:
        drawn = obj.cache.get(self)
        if drawn is None:
            drawn = obj.cache[self] = self.of_parts(obj.parts)
        return drawn

    def of_parts(self, parts: Sequence[Part]) -> Drawn:
        if parts and self.compiled is not None:
            found = self.compiled.draw_data(parts, unit_corners, self._project, self._limits,
                                            MARGIN)
            if found is not None:
                rows, rects, nearest = found
                # The corners again, in numpy, only for the rare camera near the object.
                if min(nearest) > 3.0 * INSIDE_MARGIN:
                    return Drawn(rows, rects, (False,) * len(rects))
                return Drawn(rows, rects, self._inside(parts, world_corners(parts), nearest))
        return self.of_parts_python(parts)

    def of_parts_python(self, parts: Sequence[Part]) -> Drawn:
        """``of_parts`` in Python: the compiled kernel's twin and fallback."""
        n = len(self.bounds)
        if not parts:
            return Drawn({}, (None,) * n, (False,) * n)
        corners = world_corners(parts)
        rects, nearest = self._project_corners(corners)
        return Drawn(instance_rows(parts), rects, self._inside(parts, corners, nearest))

    def _project_corners(self, corners: np.ndarray) -> tuple[tuple[Rect | None, ...], list[float]]:
        """Per camera, ``CameraBounds.rect_of(corners)`` and the corners' smallest z-depth,
        for all cameras from one product. An object has a few dozen corners: past the
        product, plain floats are quicker than numpy's calls on arrays this small."""
        rows = (self._project @ corners).tolist()
        out, nearest = [], []
        for c, b in enumerate(self.bounds):
            us, vs, ws = rows[3 * c], rows[3 * c + 1], rows[3 * c + 2]
            near = min(ws)
            nearest.append(near)
            if near <= b.near or not math.isfinite(sum(us) + sum(vs) + sum(ws)):
                out.append(b.full)  # reaching behind the camera (or degenerate)
                continue
            u, v = list(map(truediv, us, ws)), list(map(truediv, vs, ws))
            c0, c1 = max(floor(min(u)) - MARGIN, 0), min(ceil(max(u)) + MARGIN, b.width)
            r0, r1 = max(floor(min(v)) - MARGIN, 0), min(ceil(max(v)) + MARGIN, b.height)
            out.append(None if c0 >= c1 or r0 >= r1 else (r0, r1, c0, c1))
        return tuple(out), nearest

    def _inside(self, parts: Sequence[Part], corners: np.ndarray,
                nearest: Sequence[float]) -> tuple[bool, ...]:
        """Per camera, whether it may be inside one of the parts (``contains``). ``contains``
        widens a part's box by INSIDE_MARGIN along each of its axes, which moves no point more
        than 3 margins, so a camera whose nearest corner is deeper than that is outside every
        part (a box's smallest depth is at a corner): the usual case, decided here without
        looking at the parts. The others ask ``contains`` of the parts whose box they are
        near (``near_box``)."""
        reach = 3.0 * INSIDE_MARGIN
        out = [False] * len(self.bounds)
        boxes = None
        for c, (b, position) in enumerate(zip(self.bounds, self._positions)):
            if nearest[c] > reach:
                continue
            if boxes is None:
                xyz = corners[:3].tolist()
                boxes = [[(min(axis[8 * i : 8 * i + 8]) - reach,
                           max(axis[8 * i : 8 * i + 8]) + reach) for axis in xyz]
                         for i in range(len(parts))]
            near = [p for p, box in zip(parts, boxes)
                    if all(lo <= x <= hi for x, (lo, hi) in zip(position, box))]
            out[c] = bool(near) and any(contains(p, b.position) for p in near)
        return tuple(out)
