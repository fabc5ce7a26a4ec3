"""A dome: half an ellipsoid standing on its flat side, ``dome(radius, height)``.

Registering it makes ``geometry dome(r, h) ...`` valid in model files, and both renderers
draw it exactly: the GL renderer with the snippet in ``dome.glsl``, the reference ray caster
with ``hits`` below. docs/walkthroughs/adding-a-primitive.md explains each piece.
"""

from pathlib import Path

import numpy as np
import trimesh

import sppl


def unit_dome() -> trimesh.Trimesh:
    """The unit shape as a closed mesh: a quarter circle from the rim (1, 0) to the top
    (0, 1), revolved about the z axis. The renderers use only its bounds (and the report's
    3D view its triangles)."""
    angles = np.linspace(0.0, np.pi / 2, 13)
    profile = np.vstack([[0.0, 0.0], np.column_stack([np.cos(angles), np.sin(angles)])])
    return trimesh.creation.revolve(profile, sections=48)


def hits(o: np.ndarray, d: np.ndarray) -> sppl.Hits:
    """Every candidate hit of the rays o + t d (o and d: (N, 3), in the unit dome's
    coordinates), each as (t, the outward normal there), t NaN where that candidate misses."""
    # The sphere |o + t d|^2 = 1: a t^2 + 2 b t + c = 0, kept where z >= 0. On the unit sphere
    # the outward normal is the point itself.
    a, b, c = (np.einsum("nk,nk->n", d, d), np.einsum("nk,nk->n", o, d),
               np.einsum("nk,nk->n", o, o) - 1.0)
    found = []
    with np.errstate(invalid="ignore", divide="ignore"):
        for t in ((-b - np.sqrt(b * b - a * c)) / a, (-b + np.sqrt(b * b - a * c)) / a):
            point = o + t[:, None] * d
            found.append((np.where(point[:, 2] >= 0.0, t, np.nan), point))
        # The base: the plane z = 0 inside radius 1, facing down.
        t = -o[:, 2] / d[:, 2]
    point = o + np.nan_to_num(t, posinf=0.0, neginf=0.0)[:, None] * d
    inside = point[:, 0] ** 2 + point[:, 1] ** 2 <= 1.0
    found.append((np.where(inside, t, np.nan), np.tile((0.0, 0.0, -1.0), (len(d), 1))))
    return found


def outline() -> np.ndarray:
    """Points whose convex hull seen from above is the footprint: the base's rim, as
    homogeneous points (N, 4)."""
    angles = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    return np.column_stack([np.cos(angles), np.sin(angles), np.zeros(48), np.ones(48)])


DOME = sppl.register_primitive(sppl.Primitive(
    "dome",
    ("radius", "height"),
    mesh=unit_dome,
    scale=lambda s: (s[0], s[0], s[1]),  # the x, y and z scale of the unit dome
    glsl=Path(__file__).with_suffix(".glsl").read_text(),
    hits=hits,
    outline=outline,
))
