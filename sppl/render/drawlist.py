"""What an object contributes to each camera's pass, worked out once per object.

A chain proposes thousands of hypotheses that share all but one object, and the objects are
immutable, so an object's instance rows (its parts' matrices and colours, ready for the GPU) and
the screen rectangle it covers in each camera are computed the first time it is drawn and kept
while the object lives. A pass then draws only the objects whose rectangle meets the region it
renders: the whole image, or the few pixels a move can change.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..geometry import Part
from .bounds import CameraBounds, Rect, contains
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
        self._objects: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def of_object(self, obj) -> Drawn:
        drawn = self._objects.get(obj)
        if drawn is None:
            drawn = self._objects[obj] = self.of_parts(obj.parts)
        return drawn

    def of_parts(self, parts: Sequence[Part]) -> Drawn:
        rects = tuple(b.rect(parts) for b in self.bounds)
        inside = tuple(any(contains(p, b.position) for p in parts) for b in self.bounds)
        return Drawn(instance_rows(parts), rects, inside)
