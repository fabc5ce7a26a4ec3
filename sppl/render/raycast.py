"""A slow, obviously correct reference renderer: one ray per pixel centre, numpy only.

It shares only the unit meshes and the camera with the OpenGL renderer, and derives everything
else independently (normals from the posed triangles' edges, depth from the hit distance), so
that it can serve as the oracle the fast path is tested against. Spheres, which the renderer
ray-casts exactly, are intersected exactly here too, in double precision (``_sphere_hits``).
Meant for tiny images.
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
    colour_of = lambda part, normals: np.asarray(part.colour, dtype=float)[None, :] * (  # noqa: E731
        settings.ambient + (1.0 - settings.ambient) * np.maximum(normals @ light, 0.0))[:, None]
    for part in parts:
        if part.primitive == "sphere":
            # The GL renderer clips at its near plane, a plane of constant z: a ray's hits
            # count from the z-depth ``near`` on.
            t, normals = _sphere_hits(part, origin, directions, camera.near / (directions @ forward))
            if normals is None:
                continue
            closer = t < nearest
            nearest[closer] = t[closer]
            rgb[closer] = colour_of(part, normals[closer])
            continue
        triangles, normals = _posed_triangles(part)
        if len(triangles) == 0:
            continue
        colours = colour_of(part, normals)
        for start in range(0, h * w, BATCH):
            rays = slice(start, start + BATCH)
            t, face = _nearest_hits(origin, directions[rays], triangles)
            t[t * (directions[rays] @ forward) <= camera.near] = np.inf
            closer = t < nearest[rays]
            nearest[rays][closer] = t[closer]  # slices are views: these write through
            rgb[rays][closer] = colours[face[closer]]

    hit = np.isfinite(nearest)
    depth = np.full(h * w, float(camera.depth_max))
    along = nearest if camera.depth_type == "ray" else nearest * (directions @ forward)
    depth[hit] = np.minimum(along[hit], camera.depth_max)
    return rgb.reshape(h, w, 3).astype("f4"), depth.reshape(h, w).astype("f4")


def _sphere_hits(part: Part, origin, directions, start):
    """The distance along each unit ray to the part's sphere (inf for a miss), counting only
    hits at least ``start`` (per ray) along it, and the outward unit normals (N, 3) there;
    (None, None) for a part with no volume. The unit sphere has radius 1 and centre (0, 0, 1)."""
    matrix = np.asarray(part.matrix, dtype=float)
    linear = matrix[:3, :3]
    if abs(np.linalg.det(linear)) < 1e-12:
        return None, None
    unit_from_world = np.linalg.inv(linear)
    o = unit_from_world @ (origin - matrix[:3, 3]) - (0.0, 0.0, 1.0)
    d = directions @ unit_from_world.T
    # |o + t d|^2 = 1, a quadratic in t.
    a = np.einsum("nk,nk->n", d, d)
    b = d @ o
    c = o @ o - 1.0
    discriminant = b * b - a * c
    t = np.full(len(d), np.inf)
    hit = discriminant >= 0.0
    root = np.sqrt(discriminant[hit])
    near, far = (-b[hit] - root) / a[hit], (-b[hit] + root) / a[hit]
    first = np.where(near > start[hit], near, np.where(far > start[hit], far, np.inf))
    t[hit] = first
    unit_normals = np.tile((0.0, 0.0, 1.0), (len(d), 1))
    found = np.isfinite(t)
    unit_normals[found] = o + t[found, None] * d[found]
    normals = unit_normals @ unit_from_world  # the inverse-transpose applied to each normal
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return t, normals


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
