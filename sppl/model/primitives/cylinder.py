"""``cylinder(radius, height)``: radius 1 about the z axis, z in [0, 1], with both caps;
ray-cast exactly (``cylinder.glsl``)."""

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
    mesh = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=ROUND_SECTIONS)
    mesh.apply_translation((0.0, 0.0, 0.5))
    return mesh


def _hits(o: np.ndarray, d: np.ndarray) -> Hits:
    # x^2 + y^2 = 1 for z in [0, 1], then the planes z = 0 and z = 1 inside radius 1.
    (x, y, _), (dx, dy, _) = o.T, d.T
    found = []
    for t in roots(dx * dx + dy * dy, x * dx + y * dy, x * x + y * y - 1.0):
        point = o + t[:, None] * d
        t = np.where((point[:, 2] >= 0.0) & (point[:, 2] <= 1.0), t, np.nan)
        found.append((t, np.column_stack([point[:, 0], point[:, 1], np.zeros(len(d))])))
    return [*found, plane_hit(o, d, 0.0, -1.0), plane_hit(o, d, 1.0, 1.0)]


CYLINDER = register_primitive(Primitive(
    "cylinder", ("radius", "height"), mesh=_mesh, scale=lambda s: (s[0], s[0], s[1]),
    glsl=glsl_beside(__file__), hits=_hits,
    outline=lambda: np.concatenate([disc(0.0), disc(1.0)]), caster=2,
))
