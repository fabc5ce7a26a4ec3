"""``sphere(radius)``: radius 1 centred at (0, 0, 1), so that it rests on the ground;
ray-cast exactly (``sphere.glsl``)."""

import numpy as np
import trimesh

from .registry import Hits, Primitive, disc, glsl_beside, register_primitive, roots


def _mesh() -> trimesh.Trimesh:
    # Only its bounds and the report's 3D view use it: the renderers ray-cast the sphere.
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mesh.apply_translation((0.0, 0.0, 1.0))
    return mesh


def _hits(o: np.ndarray, d: np.ndarray) -> Hits:
    # |o + t d - (0, 0, 1)|^2 = 1
    centred = np.broadcast_to(o - (0.0, 0.0, 1.0), d.shape)
    return [(t, centred + t[:, None] * d)
            for t in roots(np.einsum("nk,nk->n", d, d), np.einsum("nk,nk->n", d, centred),
                           np.einsum("nk,nk->n", centred, centred) - 1.0)]


SPHERE = register_primitive(Primitive(
    "sphere", ("radius",), mesh=_mesh, scale=lambda s: (s[0], s[0], s[0]),
    glsl=glsl_beside(__file__), hits=_hits, outline=lambda: disc(1.0), caster=1,
))
