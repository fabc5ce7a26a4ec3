"""The lighting a pass is drawn with, packed as the shaders' ``Lighting`` block, and what
cast shadows need of the parts.

``shaders/lighting.glsl`` reads the light's direction, the ambient level, the intensity, the
per-channel gain, the sheen and, when shadows are on, every part that can cast one (its solid's
unit-from-world map and kind). Both renderers and the fast scorer write the block once per
hypothesis, so a model whose lighting is latent re-lights without recompiling anything.

A moved object changes shadows beyond its own pixels: ``shadow_corners`` bounds the region of
space its shadow can darken, for incremental scoring's dirty rectangles.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

from ..errors import RenderError
from ..model.geometry import MESH_PREFIX, Part, linear_inverse
from ..model.primitives import find_primitive
from ..model.types import RenderSettings

MAX_CASTERS = 252  # lighting.glsl's: the block then fits GL's guaranteed 16 KiB
HEADER_BYTES = 3 * 16
CASTER_BYTES = 4 * 16
BLOCK_BYTES = HEADER_BYTES + MAX_CASTERS * CASTER_BYTES


def caster_rows(parts: Sequence[Part]) -> bytes:
    """The block's rows of the parts that cast shadows: every part with a volume whose shape
    lighting.glsl tests shadow rays against (``Primitive.caster``: the built-in shapes). Mesh
    files are not tested against (a mesh may have any number of triangles), nor are shapes
    registered without a caster code: they receive shadows but cast none, in both renderers."""
    floats: list[float] = []
    for part in parts:
        kind = caster_kind(part.primitive)
        if kind is None:
            continue
        matrix = np.asarray(part.matrix, dtype=float)
        if linear_inverse(matrix) is None:
            continue  # no volume, not drawn: casts nothing
        inverse = np.linalg.inv(matrix)
        floats += inverse[:3].ravel().tolist()
        floats += (kind, 0.0, 0.0, 0.0)
    return struct.pack(f"{len(floats)}f", *floats)


def caster_kind(primitive: str) -> float | None:
    """lighting.glsl's code for a primitive's shape, or None if it casts no shadow."""
    shape = None if primitive.startswith(MESH_PREFIX) else find_primitive(primitive)
    return None if shape is None or shape.caster is None else float(shape.caster)


def block(settings: RenderSettings, casters: bytes = b"") -> bytes:
    """The ``Lighting`` block's bytes for these settings and caster rows (ignored unless
    ``settings.shadows``)."""
    if not settings.shadows:
        casters = b""
    count = len(casters) // CASTER_BYTES
    if count > MAX_CASTERS:
        raise RenderError(f"a scene with shadows may have at most {MAX_CASTERS} parts that "
                          f"cast them; this one has {count}")
    header = struct.pack(
        "12f", *settings.direction, 0.0,
        float(settings.ambient), float(settings.intensity), float(count),
        1.0 if settings.shadows else 0.0, *settings.balance, float(settings.sheen),
    )
    return header + casters


def check_light(settings: RenderSettings) -> None:
    light = np.asarray(settings.light, dtype=float)
    if not np.all(np.isfinite(light)) or np.linalg.norm(light) == 0.0:
        raise RenderError(f"the light direction {tuple(light)} is not a nonzero vector")


def shadow_corners(corners: np.ndarray, direction, floor: float) -> np.ndarray | None:
    """Homogeneous points (4, 2n) whose convex hull holds every point the parts with these
    bounding-box corners (4, n) can shade from the light ``direction``, down to the height
    ``floor``: the corners and their shadows on the plane z = floor. A part's shadow volume
    is the box swept away from the light, and cut at z = floor it is that hull (a box is
    convex). None when the light is not above the horizon: the volume is then unbounded."""
    dx, dy, dz = direction
    if dz <= 1e-9:
        return None
    s = (corners[2] - floor) / dz
    if np.any(s < 0.0):
        return None  # a corner below the floor: the cut does not hold the part
    cast = corners.copy()
    cast[0] -= s * dx
    cast[1] -= s * dy
    cast[2] = floor
    return np.hstack([corners, cast])
