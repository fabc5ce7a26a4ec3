"""Posed primitive parts, their unit meshes, and ground-plane footprints.

Every primitive is a *unit* shape resting on the ground: its lowest point is at z = 0 and its
axis is the z axis. A part poses one unit shape with a 4x4 world-from-unit matrix that includes
the scale, so a class's geometry is a few multiplications per object and the renderer uploads
each unit mesh once.

The shapes are registered in ``sppl.model.primitives``, one module each, which says their unit
shapes; ``mesh:<absolute path>`` is a mesh loaded from a file (OBJ, PLY, STL, GLB, ...), in its
own coordinates, which the model file's scale and pose then act on (``load_mesh``).

A ray-cast shape's mesh (the round shapes': 48-sided prisms and pyramids, an icosphere) gives
only its bounds and the report's 3D view: the renderers intersect each pixel's ray with the
exact shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
import shapely
import trimesh

from .primitives import MESH_PREFIX, PRIMITIVES, ROUND_SECTIONS, get_primitive

__all__ = ["MESH_PREFIX", "PRIMITIVES", "ROUND_SECTIONS"]  # re-exported for their users


@dataclass(frozen=True, eq=False)
class Part:
    """One posed, coloured primitive of an object."""

    primitive: str
    matrix: np.ndarray  # (4, 4) world-from-unit, scale included
    colour: tuple[float, float, float]


def linear_inverse(matrix: np.ndarray) -> tuple[float, ...] | None:
    """The inverse of a part matrix's 3x3 linear part, its nine entries row by row, or None
    where it is singular (a part of no volume). Both renderers take their normal matrices from
    here, so that they shade (and ray-cast spheres) with the very same floats; the cofactors
    in plain floats cost a third of a LAPACK call on one small matrix."""
    (a0, a1, a2, _), (b0, b1, b2, _), (c0, c1, c2, _) = matrix[:3].tolist()
    i00, i01, i02 = b1 * c2 - b2 * c1, a2 * c1 - a1 * c2, a1 * b2 - a2 * b1
    det = a0 * i00 + b0 * i01 + c0 * i02
    if det == 0.0 or not math.isfinite(det):
        return None
    i10, i11, i12 = b2 * c0 - b0 * c2, a0 * c2 - a2 * c0, a2 * b0 - a0 * b2
    i20, i21, i22 = b0 * c1 - b1 * c0, a1 * c0 - a0 * c1, a0 * b1 - a1 * b0
    r = 1.0 / det
    return (i00 * r, i01 * r, i02 * r, i10 * r, i11 * r, i12 * r, i20 * r, i21 * r, i22 * r)


def translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rotation_z(angle: float) -> np.ndarray:
    """Counter-clockwise rotation about +z, seen from above (right-handed)."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[:2, :2] = ((c, -s), (s, c))
    return m


def rotation(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    return trimesh.transformations.rotation_matrix(angle, axis)


def scaling(sx: float, sy: float, sz: float) -> np.ndarray:
    return np.diag([sx, sy, sz, 1.0])


@cache
def unit_mesh(primitive: str) -> trimesh.Trimesh:
    """The unit shape of a base shape or mesh file, as a trimesh (cached: built once per
    process); KeyError for a name that is neither."""
    if primitive.startswith(MESH_PREFIX):
        return load_mesh(primitive[len(MESH_PREFIX) :])
    shape = get_primitive(primitive)
    if shape.mesh is None:
        raise KeyError(f"{primitive!r} is made of other shapes and has no unit mesh")
    return shape.mesh()


def load_mesh(path: str) -> trimesh.Trimesh:
    """The triangles of a mesh file, as one trimesh; ValueError if it holds none.

    Scenes (GLB, say) are flattened into one mesh with their nodes' transforms applied.
    """
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as error:  # trimesh raises many types for a malformed file
        raise ValueError(f"{type(error).__name__}: {error}") from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError("it holds no triangles")
    return mesh


@cache
def _outline(primitive: str) -> np.ndarray:
    """Points of the unit shape whose convex hull, seen from above, is its footprint: the
    shape's own ``outline`` (exact for the box; for round shapes, the inscribed regular
    polygon at their widest height), else the vertices of its mesh's convex hull. Kept in
    homogeneous coordinates so a part's matrix poses them directly."""
    shape = None if primitive.startswith(MESH_PREFIX) else get_primitive(primitive)
    if shape is not None and shape.outline is not None:
        return shape.outline()
    mesh = unit_mesh(primitive)
    try:
        vertices = mesh.convex_hull.vertices
    except Exception:  # a flat or degenerate mesh has no hull volume
        vertices = mesh.vertices
    return np.column_stack([vertices, np.ones(len(vertices))])


def ground_points(parts: tuple[Part, ...] | list[Part]) -> np.ndarray:
    """(N, 2) points on the ground whose convex hull is the parts' footprint."""
    return np.concatenate([(_outline(p.primitive) @ p.matrix.T)[:, :2] for p in parts])


def span(parts: tuple[Part, ...] | list[Part]) -> float:
    """The diagonal of the parts' bounding box in the world: how big an object is, in metres,
    whatever its class and shape (a shape made of other shapes, which has no unit mesh,
    counts its footprint's outline, at its widest height); 0 for no parts."""
    corners = []
    for p in parts:
        try:
            low, high = unit_mesh(p.primitive).bounds
            box = np.array([[x, y, z, 1.0] for x in (low[0], high[0])
                            for y in (low[1], high[1]) for z in (low[2], high[2])])
        except KeyError:
            box = _outline(p.primitive)
        corners.append((box @ p.matrix.T)[:, :3])
    if not corners:
        return 0.0
    points = np.concatenate(corners)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def footprint_of(parts: tuple[Part, ...] | list[Part]) -> np.ndarray:
    """The convex ground-plane footprint of some parts: an (M, 2) counter-clockwise polygon."""
    hull = shapely.convex_hull(shapely.MultiPoint(ground_points(parts)))
    return np.asarray(shapely.get_coordinates(hull.exterior if hasattr(hull, "exterior") else hull))


def polygon(points: np.ndarray) -> shapely.Polygon:
    return shapely.Polygon(points)


def footprints_overlap(a: shapely.Polygon, b: shapely.Polygon) -> bool:
    """Whether two footprints share area (touching along an edge or at a point does not count)."""
    if not a.intersects(b):
        return False
    return a.intersection(b).area > 1e-12
