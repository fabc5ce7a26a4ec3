"""``box(width, depth, height)``: x and y in [-1/2, 1/2], z in [0, 1], drawn as 12 triangles."""

import numpy as np
import trimesh

from .registry import Primitive, register_primitive


def _mesh() -> trimesh.Trimesh:
    mesh = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    mesh.apply_translation((0.0, 0.0, 0.5))
    return mesh


def _outline() -> np.ndarray:
    square = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
    return np.array([(x, y, z, 1.0) for z in (0.0, 1.0) for x, y in square])


BOX = register_primitive(Primitive(
    "box", ("width", "depth", "height"), mesh=_mesh, scale=lambda s: (s[0], s[1], s[2]),
    outline=_outline, caster=0,
))
