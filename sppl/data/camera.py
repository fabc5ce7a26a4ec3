"""Pinhole cameras: intrinsics, extrinsics, and the matrices the renderer needs.

Conventions (the same as nerfstudio's ``transforms.json``):
- ``c2w`` is the 4x4 camera-to-world matrix in OpenGL axes: +x right, +y up, the camera looks
  along its -z axis. OpenCV/COLMAP matrices are converted when observations are loaded.
- ``fx, fy, cx, cy`` are in pixels, in continuous image coordinates whose origin is the
  top-left *corner* of the image, so pixel (row i, column j) covers [j, j+1] x [i, i+1] and its
  centre is at (j + 0.5, i + 0.5). A centred principal point is ``cx = width / 2``.
- A depth pixel holds either the distance along the optical axis (``depth_type = "z"``, what
  RGB-D sensors and nerfstudio store) or the distance from the optical centre along the pixel's
  ray (``"ray"``, the thesis's definition), clipped at ``depth_max`` metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

DEPTH_TYPES = ("z", "ray")

# OpenCV axes (+y down, +z forward) to OpenGL axes (+y up, -z forward), on the camera side.
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True, eq=False)
class Camera:
    name: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    c2w: np.ndarray = field(repr=False)
    depth_max: float = 10.0
    depth_type: str = "z"
    near: float = 0.01

    @property
    def w2c(self) -> np.ndarray:
        return np.linalg.inv(self.c2w)

    @property
    def position(self) -> np.ndarray:
        return self.c2w[:3, 3].copy()

    def projection(self) -> np.ndarray:
        """OpenGL projection matrix (row-major; clip = P @ camera point) for these intrinsics."""
        w, h, n = self.width, self.height, self.near
        f = max(self.depth_max, n) * 2.0 + 1.0  # beyond depth_max, so clipping happens in depth
        return np.array(
            [
                [2 * self.fx / w, 0.0, 1.0 - 2 * self.cx / w, 0.0],
                [0.0, 2 * self.fy / h, 2 * self.cy / h - 1.0, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) to continuous pixel coordinates (N, 2) as (u right, v down),
        and their z-depth in front of the camera (N,); points behind have depth <= 0."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        cam = (self.w2c @ np.column_stack([pts, np.ones(len(pts))]).T).T[:, :3]
        depth = -cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * cam[:, 0] / depth + self.cx
            v = -self.fy * cam[:, 1] / depth + self.cy
        return np.stack([u, v], axis=1), depth

    def ray_directions(self) -> np.ndarray:
        """Unit world-space directions (H, W, 3) through each pixel centre."""
        j, i = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        d = np.stack([(j - self.cx) / self.fx, -(i - self.cy) / self.fy, -np.ones_like(j)], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return d @ self.c2w[:3, :3].T

    def ray_to_z(self) -> np.ndarray:
        """Per-pixel factor (H, W) turning distance along the ray into distance along the axis."""
        j, i = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        x, y = (j - self.cx) / self.fx, (i - self.cy) / self.fy
        return 1.0 / np.sqrt(1.0 + x * x + y * y)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world matrix (OpenGL axes) of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at: the up vector is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, true_up, back, eye
    return m


def focal_from_fov(size: int, fov_degrees: float) -> float:
    return 0.5 * size / math.tan(0.5 * math.radians(fov_degrees))
