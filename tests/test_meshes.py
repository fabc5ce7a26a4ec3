"""Meshes loaded from files: the unit mesh, its footprint, and rendering on first use."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from sppl.camera import Camera, look_at
from sppl.errors import RenderError
from sppl.geometry import MESH_PREFIX, Part, footprint_of, load_mesh, unit_mesh
from sppl.render import Renderer, gl_context, raycast

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


@pytest.fixture
def gl():
    try:
        gl_context()
    except RenderError as error:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must be able to render: {error}")
        pytest.skip(f"no headless OpenGL context on this machine: {error}")


def test_a_mesh_is_uploaded_on_first_use_and_matches_the_ray_caster(gl):
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


def test_an_unknown_primitive_is_still_an_error(gl):
    renderer = Renderer()
    try:
        with pytest.raises(RenderError, match="unknown primitive 'torus'"):
            renderer.render([Part("torus", np.eye(4), (1, 1, 1))], Camera(
                "c", 4, 4, 4.0, 4.0, 2.0, 2.0, look_at((0, -3, 1), (0, 0, 0))))
    finally:
        renderer.release()
