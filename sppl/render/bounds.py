"""Which pixels a part can cover: the screen rectangle of its projected bounding box.

Incremental scoring re-renders only where a move can change the image: the union of the
rectangles of the objects it removes and adds. The rectangle must contain every pixel whose
centre the rasteriser could shade, so it is conservative: the bounding box of the projected
corners of the part's 3D bounding box, widened by a pixel; a box reaching behind the near plane
projects to no bounded rectangle, and then the whole image is taken.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..data.camera import Camera
from ..errors import RenderError
from ..model.geometry import MESH_PREFIX, Part, unit_mesh

# Rows and columns as half-open ranges: (row0, row1, col0, col1).
Rect = tuple[int, int, int, int]
MARGIN = 1  # pixels added on every side, against rounding at the rectangle's edges


@lru_cache(maxsize=None)
def unit_corners(primitive: str) -> np.ndarray:
    """The 8 corners (4, 8) of a unit mesh's bounding box, homogeneous, as columns."""
    try:
        lo, hi = unit_mesh(primitive).bounds
    except KeyError as error:
        raise RenderError(error.args[0]) from None
    except ValueError as error:
        raise RenderError(f"cannot load the mesh {primitive[len(MESH_PREFIX):]}: {error}")
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    return corners.T


class CameraBounds:
    """Projects parts into one camera's image."""

    def __init__(self, camera: Camera) -> None:
        self.width, self.height = camera.width, camera.height
        # OpenGL camera axes look along -z: w = -z, u = fx x / w + cx, v = -fy y / w + cy.
        intrinsics = np.array([[camera.fx, 0.0, -camera.cx], [0.0, -camera.fy, -camera.cy],
                               [0.0, 0.0, -1.0]])
        # Pixel homogeneous coordinates (u w, v w, w) of a world point, w its z-depth.
        self.pixels_from_world = intrinsics @ camera.w2c[:3, :]
        self.near = camera.near
        self.position = camera.position
        self.full: Rect = (0, self.height, 0, self.width)

    def rect(self, parts) -> Rect | None:
        """The rectangle that can contain every pixel these parts shade, or None if none."""
        if not parts:
            return None
        return self.rect_of(world_corners(parts))

    def rect_of(self, corners: np.ndarray) -> Rect | None:
        """``rect`` of the parts whose ``world_corners`` these are."""
        points = self.pixels_from_world @ corners
        w = points[2]
        if np.any(w <= self.near) or not np.all(np.isfinite(points)):
            return self.full
        u, v = points[0] / w, points[1] / w
        c0 = max(int(np.floor(u.min())) - MARGIN, 0)
        c1 = min(int(np.ceil(u.max())) + MARGIN, self.width)
        r0 = max(int(np.floor(v.min())) - MARGIN, 0)
        r1 = min(int(np.ceil(v.max())) + MARGIN, self.height)
        if c0 >= c1 or r0 >= r1:
            return None
        return (r0, r1, c0, c1)


def near_box(world: np.ndarray, point: np.ndarray, margin: float) -> bool:
    """False when ``point`` is surely outside the box whose world corners (3, 8) are given,
    widened by ``margin`` along each of its axes: that lies within the world box of its
    corners widened by 3 margin (an axis moves a coordinate by at most margin, even under
    shear). A camera is usually far outside, and then no solve is needed."""
    reach = 3.0 * margin
    return not (np.any(point < world.min(axis=1) - reach)
                or np.any(point > world.max(axis=1) + reach))


def world_corners(parts) -> np.ndarray:
    """The corners of every part's posed bounding box, (4, 8 * len(parts)), homogeneous."""
    if len(parts) == 1:
        return parts[0].matrix @ unit_corners(parts[0].primitive)
    return np.hstack([p.matrix @ unit_corners(p.primitive) for p in parts])


def meets(a: Rect, b: Rect) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def union(a: Rect | None, b: Rect | None) -> Rect | None:
    if a is None:
        return b
    if b is None:
        return a
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


def closed(primitive: str) -> bool:
    """Built-in primitives are closed surfaces, so their back faces never show from outside
    and need not be drawn; a mesh file may be open, so its back faces are always drawn."""
    return not primitive.startswith(MESH_PREFIX)


INSIDE_MARGIN = 0.05  # metres: how near a part's box a camera may see inside it


def contains(part: Part, point: np.ndarray, margin: float = INSIDE_MARGIN) -> bool:
    """Whether ``point`` may be inside the part (its bounding box, widened by ``margin``
    metres): a camera there can see the part's back faces, or have the near plane cut it."""
    corners = unit_corners(part.primitive)
    if not near_box(part.matrix[:3] @ corners, point, margin):
        return False
    lo, hi = corners[:3].min(axis=1), corners[:3].max(axis=1)
    try:
        local = np.linalg.solve(part.matrix, np.append(point, 1.0))[:3]
    except np.linalg.LinAlgError:
        return False  # a flat part encloses nothing (and is not drawn)
    pad = margin / np.maximum(np.linalg.norm(part.matrix[:3, :3], axis=0), 1e-12)
    return bool(np.all(local >= lo - pad) and np.all(local <= hi + pad))
