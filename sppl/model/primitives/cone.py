"""``cone(radius, height)``: base radius 1 at z = 0, apex at (0, 0, 1), with its base;
ray-cast exactly (``cone.glsl``)."""

import numpy as np
import trimesh

from .registry import (
    ROUND_SECTIONS,
    Hits,
    Primitive,
    disc,
    glsl_beside,
    plane_hit,
    register_primitive,
    roots,
)


def _mesh() -> trimesh.Trimesh:
    return trimesh.creation.cone(radius=1.0, height=1.0, sections=ROUND_SECTIONS)


def _hits(o: np.ndarray, d: np.ndarray) -> Hits:
    # x^2 + y^2 = (1 - z)^2 for z in [0, 1] (the lower nappe), then the base.
    (x, y, z), (dx, dy, dz) = o.T, d.T
    w = 1.0 - z
    found = []
    for t in roots(dx * dx + dy * dy - dz * dz, x * dx + y * dy + w * dz, x * x + y * y - w * w):
        point = o + t[:, None] * d
        t = np.where((point[:, 2] >= 0.0) & (point[:, 2] <= 1.0), t, np.nan)
        found.append((t, np.column_stack([point[:, 0], point[:, 1], 1.0 - point[:, 2]])))
    return [*found, plane_hit(o, d, 0.0, -1.0)]


def _proxy() -> trimesh.Trimesh:
    # The square pyramid around the cone: seen from the side it covers half the pixels of
    # the bounding box, and each pixel it covers costs a ray test.
    corners = [(x, y, 0.0) for x in (-1.0, 1.0) for y in (-1.0, 1.0)]
    return trimesh.Trimesh(vertices=[*corners, (0.0, 0.0, 1.0)]).convex_hull


CONE = register_primitive(Primitive(
    "cone", ("radius", "height"), mesh=_mesh, scale=lambda s: (s[0], s[0], s[1]),
    glsl=glsl_beside(__file__), hits=_hits, proxy=_proxy, outline=lambda: disc(0.0), caster=3,
))
