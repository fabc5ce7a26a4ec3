"""A slow, obviously correct reference renderer: one ray per pixel centre, numpy only.

It shares only the unit meshes and the camera with the OpenGL renderer, and derives everything
else independently (normals from the posed triangles' edges, depth from the hit distance), so
that it can serve as the oracle the fast path is tested against. Shapes that the renderer
ray-casts exactly (spheres, cylinders, cones) are intersected exactly here too, in double
precision, by their numpy twin (``Primitive.hits``), a formulation of their own.
Meant for tiny images.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..data.camera import Camera
from ..model.geometry import MESH_PREFIX, Part, unit_mesh
from ..model.primitives import find_primitive
from ..model.types import RenderSettings
from .lighting import caster_kind

# Rays per batch: bounds the (rays x triangles) temporaries to a few tens of megabytes.
BATCH = 256


def _exact(primitive: str):
    """The shape's numpy ray intersection, for a shape the GL renderer ray-casts; else None."""
    shape = None if primitive.startswith(MESH_PREFIX) else find_primitive(primitive)
    return shape.hits if shape is not None and shape.ray_cast else None


def raycast(
    parts: Iterable[Part], camera: Camera, render_settings: RenderSettings | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """RGB (H, W, 3) and depth (H, W) with the same conventions as ``Renderer.render``.

    Unlike the GL renderer, nothing is cut off far away (its far plane lies beyond twice
    ``depth_max``, where no scene of interest reaches).
    """
    settings = render_settings or RenderSettings()
    light = np.asarray(settings.direction)
    h, w = camera.height, camera.width
    origin = camera.position
    directions = camera.ray_directions().reshape(-1, 3)
    forward = -camera.c2w[:3, 2] / np.linalg.norm(camera.c2w[:3, 2])

    parts = list(parts)
    nearest = np.full(h * w, np.inf)  # distance along each ray to the nearest hit
    colour = np.zeros((h * w, 3))  # the unlit colour of the part each ray hits
    normal = np.zeros((h * w, 3))  # its outward unit normal there
    for part in parts:
        if _exact(part.primitive):
            # The GL renderer clips at its near plane, a plane of constant z: a ray's hits
            # count from the z-depth ``near`` on.
            t, normals = _round_hits(part, origin, directions, camera.near / (directions @ forward))
            if normals is None:
                continue
            closer = t < nearest
            nearest[closer] = t[closer]
            colour[closer] = part.colour
            normal[closer] = normals[closer]
            continue
        triangles, normals = _posed_triangles(part)
        if len(triangles) == 0:
            continue
        for start in range(0, h * w, BATCH):
            rays = slice(start, start + BATCH)
            t, face = _nearest_hits(origin, directions[rays], triangles)
            t[t * (directions[rays] @ forward) <= camera.near] = np.inf
            closer = t < nearest[rays]
            nearest[rays][closer] = t[closer]  # slices are views: these write through
            colour[rays][closer] = part.colour
            normal[rays][closer] = normals[face[closer]]

    hit = np.isfinite(nearest)
    balance = np.asarray(settings.balance, dtype=float)
    rgb = np.tile(np.asarray(settings.background, dtype=float) * balance, (h * w, 1))
    lambert = np.maximum(normal[hit] @ light, 0.0)
    if settings.shadows:
        points = origin + nearest[hit][:, None] * directions[hit]
        facing = lambert > 0.0
        lambert[facing] *= ~_shadowed(parts, points[facing], light)
    rgb[hit] = balance * (colour[hit] * (
        settings.ambient + settings.intensity * (1.0 - settings.ambient) * lambert)[:, None]
        + settings.sheen)
    depth = np.full(h * w, float(camera.depth_max))
    along = nearest if camera.depth_type == "ray" else nearest * (directions @ forward)
    depth[hit] = np.minimum(along[hit], camera.depth_max)
    return rgb.reshape(h, w, 3).astype("f4"), depth.reshape(h, w).astype("f4")


# A point is in a part's shadow when its ray towards the light meets the part more than this
# far away (metres): lighting.glsl's SHADOW_BIAS.
SHADOW_BIAS = 1e-3


def _shadowed(parts, points: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Whether each point's ray towards the light crosses a part's surface beyond
    SHADOW_BIAS. Parts are closed, so such a crossing is where the ray enters or leaves a
    solid; a point on its own part, lit from outside, leaves it at once. Only shapes with a
    caster code cast shadows (as in the GL renderers, which test only those solids)."""
    blocked = np.zeros(len(points), dtype=bool)
    directions = np.tile(light, (len(points), 1))
    bias = np.full(len(points), SHADOW_BIAS)
    for part in parts:
        if caster_kind(part.primitive) is None:
            continue
        if _exact(part.primitive):
            t, _ = _round_hits(part, points, directions, bias)
            if t is not None:
                blocked |= np.isfinite(t)
        else:
            triangles, _ = _posed_triangles(part)
            for start in range(0, len(points), BATCH):
                rays = slice(start, start + BATCH)
                t = _hits_from(points[rays], light, triangles)
                blocked[rays] |= np.any(t > SHADOW_BIAS, axis=1)
    return blocked


def _hits_from(origins: np.ndarray, direction: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Möller–Trumbore from each origin (R, 3) along one direction: the distance to each
    triangle (R, F), -inf where the ray misses it."""
    v0 = triangles[:, 0]
    e1 = triangles[:, 1] - v0
    e2 = triangles[:, 2] - v0
    p = np.cross(direction, e2)  # (F, 3)
    det = np.einsum("fk,fk->f", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / det
        s = origins[:, None, :] - v0[None, :, :]  # (R, F, 3)
        u = np.einsum("rfk,fk->rf", s, p) * inv_det
        q = np.cross(s, e1)  # (R, F, 3)
        v = (q @ direction) * inv_det
        t = np.einsum("fk,rfk->rf", e2, q) * inv_det
        hit = (np.abs(det) > 1e-12) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0)
    return np.where(hit, t, -np.inf)


def _round_hits(part: Part, origin, directions, start):
    """The distance along each unit ray to the part's exactly intersected shape (inf for a
    miss), counting only hits at least ``start`` (per ray) along it, and the outward unit
    normals (N, 3) there; (None, None) for a part with no volume. ``origin`` is one point, or
    one per ray (N, 3)."""
    matrix = np.asarray(part.matrix, dtype=float)
    linear = matrix[:3, :3]
    if abs(np.linalg.det(linear)) < 1e-12:
        return None, None
    unit_from_world = np.linalg.inv(linear)
    o = (origin - matrix[:3, 3]) @ unit_from_world.T  # the ray's origin in unit coordinates
    d = directions @ unit_from_world.T
    o = np.ascontiguousarray(np.broadcast_to(o, d.shape))
    candidates = _exact(part.primitive)(o, d)  # (t, the unit shape's normal there), t NaN: none
    times = np.stack([t for t, _ in candidates], axis=1)
    times = np.where(np.isfinite(times) & (times > start[:, None]), times, np.inf)
    nearest = np.argmin(times, axis=1)
    rows = np.arange(len(d))
    t = times[rows, nearest]
    unit_normals = np.stack([n for _, n in candidates], axis=1)[rows, nearest]
    unit_normals[~np.isfinite(t)] = (0.0, 0.0, 1.0)
    # A cone's apex has no normal; the GL renderer lights it as the axis's tip.
    unit_normals[np.all(unit_normals == 0.0, axis=1)] = (0.0, 0.0, 1.0)
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
