"""A slow, obviously correct reference renderer: one ray per pixel centre, numpy only.

It shares only the unit meshes and the camera with the OpenGL renderer, and derives everything
else independently (normals from the posed triangles' edges, depth from the hit distance), so
that it can serve as the oracle the fast path is tested against. Meant for tiny images.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..camera import Camera
from ..geometry import Part, unit_mesh
from ..model import RenderSettings

# Rays per batch: bounds the (rays x triangles) temporaries to a few tens of megabytes.
BATCH = 256


def raycast(
    parts: Iterable[Part], camera: Camera, render_settings: RenderSettings | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """RGB (H, W, 3) and depth (H, W) with the same conventions as ``Renderer.render``.

    Unlike the GL renderer, nothing is cut off far away (its far plane lies beyond twice
    ``depth_max``, where no scene of interest reaches).
    """
    settings = render_settings or RenderSettings()
    light = np.asarray(settings.light, dtype=float)
    light = light / np.linalg.norm(light)
    h, w = camera.height, camera.width
    origin = camera.position
    directions = camera.ray_directions().reshape(-1, 3)
    forward = -camera.c2w[:3, 2] / np.linalg.norm(camera.c2w[:3, 2])

    nearest = np.full(h * w, np.inf)  # distance along each ray to the nearest hit
    rgb = np.tile(np.asarray(settings.background, dtype=float), (h * w, 1))
    for part in parts:
        triangles, normals = _posed_triangles(part)
        if len(triangles) == 0:
            continue
        shade = settings.ambient + (1.0 - settings.ambient) * np.maximum(normals @ light, 0.0)
        colours = np.asarray(part.colour, dtype=float)[None, :] * shade[:, None]
        for start in range(0, h * w, BATCH):
            rays = slice(start, start + BATCH)
            t, face = _nearest_hits(origin, directions[rays], triangles)
            # The GL renderer clips at its near plane, which is a plane of constant z.
            t[t * (directions[rays] @ forward) <= camera.near] = np.inf
            closer = t < nearest[rays]
            nearest[rays][closer] = t[closer]  # slices are views: these write through
            rgb[rays][closer] = colours[face[closer]]

    hit = np.isfinite(nearest)
    depth = np.full(h * w, float(camera.depth_max))
    along = nearest if camera.depth_type == "ray" else nearest * (directions @ forward)
    depth[hit] = np.minimum(along[hit], camera.depth_max)
    return rgb.reshape(h, w, 3).astype("f4"), depth.reshape(h, w).astype("f4")


def _posed_triangles(part: Part) -> tuple[np.ndarray, np.ndarray]:
    """The part's triangles in world space (F, 3, 3) and their outward unit normals (F, 3)."""
    matrix = np.asarray(part.matrix, dtype=float)
    determinant = np.linalg.det(matrix[:3, :3])
    if abs(determinant) < 1e-12:
        return np.empty((0, 3, 3)), np.empty((0, 3))  # no volume: the GL renderer skips it too
    unit = unit_mesh(part.primitive).triangles
    world = unit @ matrix[:3, :3].T + matrix[:3, 3]
    normals = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    # A mirroring matrix reverses the winding, and with it the edges' cross product.
    normals *= np.sign(determinant)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return world, normals


def _nearest_hits(
    origin: np.ndarray, directions: np.ndarray, triangles: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Möller–Trumbore for every (ray, triangle) pair: the nearest hit distance of each ray
    (inf for a miss) and the index of the triangle it hit."""
    v0 = triangles[:, 0]
    e1 = triangles[:, 1] - v0
    e2 = triangles[:, 2] - v0
    p = np.cross(directions[:, None, :], e2[None, :, :])  # (R, F, 3)
    det = np.einsum("rfk,fk->rf", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / det
        s = origin - v0  # (F, 3)
        u = np.einsum("rfk,fk->rf", p, s) * inv_det
        q = np.cross(s, e1)  # (F, 3)
        v = np.einsum("rk,fk->rf", directions, q) * inv_det
        t = np.einsum("fk,fk->f", e2, q)[None, :] * inv_det
        # Rays parallel to a triangle have det = 0 and NaN barycentrics, which compare False.
        hit = (np.abs(det) > 1e-12) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
    t = np.where(hit, t, np.inf)
    face = np.argmin(t, axis=1)
    return t[np.arange(len(t)), face], face
