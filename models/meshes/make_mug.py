"""Writes mug.obj, the mug that models/tabletop.scn loads: made here with trimesh, not downloaded.

A mug in metres, standing on z = 0 and centred on the z axis: a cylindrical shell 8 cm across
and 9.5 cm tall with a closed bottom, and a ring handle on the +x side.

    python models/meshes/make_mug.py
"""

from pathlib import Path

import numpy as np
import trimesh

SECTIONS = 24


def mug() -> trimesh.Trimesh:
    wall = trimesh.creation.annulus(r_min=0.035, r_max=0.04, height=0.095, sections=SECTIONS)
    wall.apply_translation((0.0, 0.0, 0.0475))
    bottom = trimesh.creation.cylinder(radius=0.0352, height=0.008, sections=SECTIONS)
    bottom.apply_translation((0.0, 0.0, 0.004))
    handle = trimesh.creation.torus(
        major_radius=0.025, minor_radius=0.0055, major_sections=16, minor_sections=8
    )
    # The torus lies in the xy plane; stand it up in the xz plane, beside the wall.
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    handle.apply_translation((0.045, 0.0, 0.05))
    return trimesh.util.concatenate([wall, bottom, handle])


if __name__ == "__main__":
    out = Path(__file__).with_name("mug.obj")
    mesh = mug()
    out.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=False, digits=5))
    print(f"wrote {out}: {len(mesh.vertices)} vertices, {len(mesh.faces)} triangles")
