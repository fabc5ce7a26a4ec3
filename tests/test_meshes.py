"""Meshes loaded from files: the unit mesh, its footprint, and rendering on first use."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely

from sppl.data.camera import Camera, look_at
from sppl.errors import RenderError
from sppl.model.geometry import MESH_PREFIX, Part, footprint_of, load_mesh, unit_mesh
from sppl.render import Renderer, raycast

MUG = Path(__file__).resolve().parent.parent / "models" / "meshes" / "mug.obj"
NAME = MESH_PREFIX + str(MUG)


def test_the_shipped_mug():
    mesh = unit_mesh(NAME)
    assert len(mesh.faces) > 100
    np.testing.assert_allclose(mesh.bounds, [[-0.04, -0.04, 0.0], [0.0755, 0.04, 0.095]], atol=1e-4)
    footprint = footprint_of([Part(NAME, np.eye(4), (1, 1, 1))])
    assert footprint[:, 0].min() == pytest.approx(-0.04, abs=1e-3)


def test_a_file_that_is_not_a_mesh(tmp_path):
    junk = tmp_path / "junk.obj"
    junk.write_text("not a mesh\n")
    with pytest.raises(ValueError):
        load_mesh(str(junk))


def test_a_mesh_is_uploaded_on_first_use_and_matches_the_ray_caster(require_gl):
    camera = Camera(
        "c", 40, 30, 60.0, 60.0, 20.0, 15.0, look_at((0.25, -0.25, 0.25), (0.0, 0.0, 0.05))
    )
    matrix = np.diag([1.5, 1.5, 1.5, 1.0])
    floor = Part("box", np.diag([0.6, 0.6, 0.01, 1]), (0.5, 0.5, 0.5))
    parts = [Part(NAME, matrix, (0.8, 0.2, 0.2)), floor]
    renderer = Renderer()
    try:
        assert NAME not in renderer._vaos
        rgb, depth = renderer.render(parts, camera)
        assert NAME in renderer._vaos
    finally:
        renderer.release()
    ref_rgb, ref_depth = raycast(parts, camera)
    # Edges may land on either side of a pixel centre: compare all but a few pixels.
    close = np.abs(depth - ref_depth) < 1e-3
    assert close.mean() > 0.97
    assert (np.abs(rgb - ref_rgb).max(axis=-1) < 0.02).mean() > 0.97
    assert (depth < camera.depth_max).sum() > 200  # the mug is in view


def test_an_unknown_primitive_is_still_an_error(require_gl):
    renderer = Renderer()
    try:
        with pytest.raises(RenderError, match="unknown primitive 'torus'"):
            renderer.render([Part("torus", np.eye(4), (1, 1, 1))], Camera(
                "c", 4, 4, 4.0, 4.0, 2.0, 2.0, look_at((0, -3, 1), (0, 0, 0))))
    finally:
        renderer.release()


# ---- the other mesh formats: the same mesh as OBJ, PLY, STL and GLB ------------------------

FORMATS = ("obj", "ply", "stl", "glb")


@pytest.fixture(scope="module")
def meshes_in_every_format(tmp_path_factory):
    """The shipped mug and a box off centre, each written by trimesh in every format, and a
    model per file whose class is that mesh, posed, in a folder of their own."""
    import trimesh

    folder = tmp_path_factory.mktemp("formats")
    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    box.apply_translation((0.1, -0.05, 0.05))  # off centre, resting on z = 0
    shapes = {"mug": trimesh.load(MUG, force="mesh"), "box": box}
    models = {}
    for name, mesh in shapes.items():
        for ext in FORMATS:
            mesh.export(folder / f"{name}.{ext}")
            model = folder / f"{name}_{ext}.scn"
            model.write_text(
                "class thing {\n"
                "    count ~ poisson(1)\n"
                "    x : real ~ normal(0, 0.1)\n"
                "    y : real ~ normal(0, 0.1)\n"
                "    a : periodic(2 * pi) ~ uniform(-pi, pi)\n"
                "    k : positive ~ lognormal(0, 0.1)\n"
                "    pose at (x, y) rotate a scale k\n"
                f'    geometry mesh("{name}.{ext}") colour rgb(0.8, 0.3, 0.2)\n'
                "}\n"
            )
            models[name, ext] = model
    return shapes, models


VALUES = {"x": 0.05, "y": -0.02, "a": 0.7, "k": 1.3}


@pytest.mark.parametrize("ext", FORMATS[1:])
@pytest.mark.parametrize("name", ("mug", "box"))
def test_a_mesh_in_another_format_compiles_to_the_obj_shape(meshes_in_every_format, name, ext):
    from sppl.lang import load_model

    shapes, models = meshes_in_every_format
    cls = load_model(models[name, ext]).object_class("thing")
    obj = load_model(models[name, "obj"]).object_class("thing")
    (part,) = cls.parts(VALUES)
    (obj_part,) = obj.parts(VALUES)
    assert part.primitive.endswith(f"{name}.{ext}")
    np.testing.assert_allclose(part.matrix, obj_part.matrix)
    # The same triangles, so the same bounds and the same derived footprint.
    mesh, obj_mesh = unit_mesh(part.primitive), unit_mesh(obj_part.primitive)
    assert len(mesh.faces) == len(obj_mesh.faces)
    np.testing.assert_allclose(mesh.bounds, shapes[name].bounds, atol=1e-6)
    np.testing.assert_allclose(mesh.bounds, obj_mesh.bounds, atol=1e-6)
    assert mesh.area == pytest.approx(obj_mesh.area, rel=1e-6)
    # Formats that store 32-bit floats move vertices by about 1e-8 of their size.
    footprint = shapely.Polygon(cls.footprint(VALUES))
    obj_footprint = shapely.Polygon(obj.footprint(VALUES))
    assert footprint.symmetric_difference(obj_footprint).area < 1e-6 * obj_footprint.area
    if name == "box":  # its outline seen from above, scaled by k
        assert footprint.area == pytest.approx(0.3 * 0.2 * VALUES["k"] ** 2, rel=1e-6)


@pytest.mark.parametrize("name", ("mug", "box"))
def test_every_format_renders_like_the_obj(meshes_in_every_format, name, require_gl):
    from sppl.lang import load_model

    _, models = meshes_in_every_format
    camera = Camera(
        "c", 48, 36, 50.0, 50.0, 24.0, 18.0, look_at((0.35, -0.35, 0.35), (0.05, -0.02, 0.05))
    )
    renderer = Renderer()
    try:
        images = {
            ext: renderer.render(load_model(models[name, ext]).object_class("thing").parts(VALUES),
                                 camera)
            for ext in FORMATS
        }
    finally:
        renderer.release()
    rgb, depth = images["obj"]
    assert (depth < camera.depth_max).sum() > 100  # the object is in view
    for ext in FORMATS[1:]:
        other_rgb, other_depth = images[ext]
        # Normals may be shaded per face in one format and per vertex in another: the depth
        # is the same everywhere but on a few edge pixels, the colours close.
        assert (np.abs(other_depth - depth) < 1e-4).mean() > 0.99, ext
        assert (np.abs(other_rgb - rgb).max(axis=-1) < 0.1).mean() > 0.97, ext
