"""What the report's 3D view is given (sppl/output/report_view.py), checked against sppl's own geometry
on hand-made runs: each part's matrix and colour, the best-so-far frames, the ghosts' opacity,
mesh parts and their box proxies, and JSON that cannot close its <script> element.

No browser: tests/test_report.py opens a real report in headless Chromium.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_report_computations import CLASSES, ROOT, cube, sphere

from sppl.lang import load_model
from sppl.model.simulate import objects_from_dict
from sppl.output import report_view
from sppl.output.posterior import Chain, RunFiles
from sppl.output.report_view import _embed_json, timeline, view_data, view_html


@pytest.fixture(scope="module")
def model():
    return load_model(ROOT / "models" / "shapes.scn")


def sample(step, score, *objects):
    return {"step": step, "score": score, "objects": list(objects),
            "noise": {"image": {"sigma": 0.05}}}


def run_of(*chains, map_sample=None):
    summary = {"class_counts": {k: {} for k in CLASSES}, "burn": 0, "map": map_sample}
    return RunFiles(Path("run"), {}, summary,
                    [Chain(Path(f"chain_{i}"), {}, summary, s) for i, s in enumerate(chains)])


def unmatrix(flat):
    """A part's 4x4 matrix back from the view's column-major list."""
    return np.asarray(flat).reshape(4, 4).T


def test_the_timeline_is_each_sweep_that_improved_the_best_so_far():
    scores = [1.0, 0.0, 3.0, 2.0, 5.0, 5.0, 6.0, 4.0]  # a tie is no improvement
    samples = [sample(k + 1, s) for k, s in enumerate(scores)]
    assert timeline(samples) == [0, 2, 4, 6]
    # Fewer frames than improvements: evenly among them, the first and the last kept.
    assert timeline(samples, frames=2) == [0, 6]
    assert timeline(samples, frames=3) == [0, 4, 6]  # improvements 0, 2 (rounded) and 3
    assert timeline([]) == []


def test_each_part_is_drawn_with_the_matrix_and_colour_sppl_renders(model):
    tilted = cube(0.7, -0.4, s=0.5, a=0.3, c="green")
    data = view_data(model, run_of([sample(1, 0.0, tilted)]), [tilted], None, [], [],
                     (-2.0, 2.0, -2.0, 2.0))
    (obj,) = data["scenes"][data["map"]]
    (expected,) = objects_from_dict(model, {"objects": [tilted]})[0].parts
    (part,) = obj["parts"]
    assert obj["class"] == "cube" and part["p"] == "box"
    np.testing.assert_allclose(unmatrix(part["m"]), expected.matrix, atol=1e-4)
    assert part["c"] == pytest.approx(model.colours["green"])
    # The matrix is the renderer's: its translation is the cube's ground position and its
    # columns are the size along each rotated axis.
    m = unmatrix(part["m"])
    assert m[:3, 3] == pytest.approx([0.7, -0.4, 0.0], abs=1e-4)
    assert m[:3, 0] == pytest.approx([0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.0], abs=1e-4)


def test_scenes_are_stored_once_and_frames_refer_to_them(model):
    a, b = cube(0.0, 0.0), sphere(1.5, 1.0)
    chain0 = [sample(1, 1.0), sample(2, 5.0, a), sample(3, 4.0, a, b), sample(4, 9.0, a, b)]
    chain1 = [sample(1, 2.0, a), sample(2, 1.0)]
    ghosts = [chain0[2], chain0[3], chain1[0]]
    run = run_of(chain0, chain1, map_sample={"chain": 0, "step": 4, "score": 9.0,
                                             "objects": [a, b]})
    data = view_data(model, run, [a, b], [b], ghosts, [], (-2.0, 2.0, -2.0, 2.0))
    scenes = data["scenes"]
    assert len(scenes) == 4  # empty, [a], [a, b], [b]
    assert [len(scenes[i]) for i in data["ghosts"]] == [2, 2, 1]
    assert data["ghosts"][0] == data["ghosts"][1] == data["map"]
    assert len(scenes[data["truth"]]) == 1
    frames = data["chains"][0]["frames"]
    assert [(f["step"], f["score"], f["n"]) for f in frames] == [(1, 1.0, 0), (2, 5.0, 1),
                                                                (4, 9.0, 2)]
    assert frames[-1]["scene"] == data["map"] and data["map_chain"] == 0
    assert [f["step"] for f in data["chains"][1]["frames"]] == [1]
    # N ghosts stacked reach GHOST_STACK_OPACITY: 1 - (1 - a)^N.
    a_ = data["ghost_opacity"]
    assert 1 - (1 - a_) ** 3 == pytest.approx(report_view.GHOST_STACK_OPACITY, abs=1e-3)


def test_a_map_the_thinned_samples_missed_ends_its_chain(model):
    """With thinning the chain's best may be a sweep it did not write: the view ends on it."""
    best = cube(0.3, 0.2)
    run = run_of([sample(10, 1.0), sample(20, 2.0, cube(0.0, 0.0))],
                 map_sample={"step": 13, "score": 7.0, "objects": [best]})
    data = view_data(model, run, [best], None, [], [], (-2.0, 2.0, -2.0, 2.0))
    frames = data["chains"][0]["frames"]
    assert [f["step"] for f in frames] == [10, 20, 13]
    assert frames[-1]["scene"] == data["map"] and data["truth"] is None


def test_cameras_carry_their_pose_and_intrinsics(model):
    from sppl.data.camera import Camera, look_at

    cam = Camera("front", 64, 48, 50.0, 52.0, 30.0, 25.0, look_at((3.0, -2.0, 2.0), (0, 0, 0.3)))
    data = view_data(model, run_of([sample(1, 0.0)]), [], None, [], [cam], (-2.0, 2.0, -2.0, 2.0))
    (c,) = data["cameras"]
    np.testing.assert_allclose(unmatrix(c["c2w"]), cam.c2w, atol=1e-4)
    assert (c["name"], c["w"], c["h"], c["fx"], c["fy"], c["cx"], c["cy"]) == (
        "front", 64, 48, 50.0, 52.0, 30.0, 25.0)


def test_a_mesh_part_carries_its_triangles_or_its_bounding_box(monkeypatch, tmp_path):
    from sppl.model.geometry import unit_mesh

    tabletop = load_model(ROOT / "models" / "tabletop.scn")
    mug = {"class": "mug", "params": {"x": 0.1, "y": -0.1, "a": 0.5, "k": 1.2, "c": "red"}}
    (obj,) = objects_from_dict(tabletop, {"objects": [mug]})
    (part,) = obj.parts
    run = run_of([sample(1, 0.0, mug)])
    data = view_data(tabletop, run, [mug], None, [], [], (-2.0, 2.0, -2.0, 2.0))
    (drawn,) = data["scenes"][data["map"]][0]["parts"]
    mesh = unit_mesh(part.primitive)
    assert drawn["p"] == part.primitive and data["proxies"] == []
    table = data["meshes"][part.primitive]
    assert len(table["f"]) == 3 * len(mesh.faces)
    np.testing.assert_allclose(np.reshape(table["v"], (-1, 3)), mesh.vertices, atol=1e-4)
    assert len(data["static"]) == len(tabletop.static_parts)  # the table and the floor

    # Too many triangles: the mesh's bounding box, posed the same way, instead.
    monkeypatch.setattr(report_view, "MESH_FACES_MAX", 10)
    data = view_data(tabletop, run, [mug], None, [], [], (-2.0, 2.0, -2.0, 2.0))
    (drawn,) = data["scenes"][data["map"]][0]["parts"]
    assert drawn["p"] == "box" and data["meshes"] == {} and data["proxies"] == [part.primitive]
    corners = np.array([[x, y, z, 1.0] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0, 1)])
    lo, hi = mesh.bounds
    unit_corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                             for z in (lo[2], hi[2])])
    np.testing.assert_allclose(corners @ unmatrix(drawn["m"]).T, unit_corners @ part.matrix.T,
                               atol=1e-4)
    assert "bounding boxes here: mug.obj" in view_html(data, tmp_path)


def test_the_embedded_json_cannot_close_its_script_element():
    text = _embed_json({"name": "</script><script>alert(1)</script>"})
    assert "</" not in text
    assert json.loads(text) == {"name": "</script><script>alert(1)</script>"}
    with pytest.raises(ValueError):
        _embed_json({"x": math.nan})  # JSON has no NaN: the page's parse would fail


def test_the_view_copies_three_js_beside_the_page_and_fetches_nothing(model, tmp_path):
    data = view_data(model, run_of([sample(1, 0.0, cube(0, 0))]), [cube(0, 0)], None, [], [],
                     (-2.0, 2.0, -2.0, 2.0))
    page = view_html(data, tmp_path)
    assert (tmp_path / "three.min.js").read_bytes() == (
        report_view.ASSETS / "three.min.js").read_bytes()
    assert '<script src="three.min.js"></script>' in page
    assert "http" not in page and "import " not in page and "fetch(" not in page
    assert "@license" in (tmp_path / "three.min.js").read_text()[:200]  # the licence header
