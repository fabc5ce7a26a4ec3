"""The test bed of benchmarks/testbed/: every folder loads as an observation folder, its true
scene is a scene of its model, and Cycles' depth agrees with sppl's rendering of the true scene
(which catches a camera-convention mistake in the render script: a flipped axis, a wrong
focal length, a depth along the ray read as along the axis).

The renders themselves are made by benchmarks/testbed/render_cycles.py with Blender's bpy; that
script is tested only where bpy is installed (``pip install '.[cycles]'``)."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from sppl.data.observations import load_observations
from sppl.lang import load_model
from sppl.model.simulate import load_scene, sample_noise

ROOT = Path(__file__).resolve().parent.parent
TESTBED = ROOT / "benchmarks" / "testbed"
INDEX = json.loads((TESTBED / "scenes.json").read_text())
NAMES = [e["name"] for e in INDEX]
SIGMA = 0.02  # the sensors' true noise in the test bed


def entry(name):
    return next(e for e in INDEX if e["name"] == name)


def test_testbed_has_the_scenes_it_promises():
    models = [e["model"] for e in INDEX]
    assert models.count("models/blocks.scn") >= 8 and models.count("models/shapes.scn") >= 4
    counts = [len(e["scene"]["objects"]) for e in INDEX]
    assert 0 in counts and max(counts) <= 5
    assert any(o["params"].get("material") == "metal" for e in INDEX for o in e["scene"]["objects"])


def test_scene_list_is_the_fixed_seed_scripts():
    """scenes.json is what make.py draws: the committed renders are of reproducible scenes."""
    sys.path.insert(0, str(TESTBED))
    try:
        import make
    finally:
        sys.path.remove(str(TESTBED))
    assert json.loads(json.dumps(make.all_scenes())) == INDEX


@pytest.mark.parametrize("renderer", ["cycles", "sppl"])
@pytest.mark.parametrize("name", NAMES)
def test_folder_loads_with_its_true_scene(name, renderer):
    e = entry(name)
    folder = TESTBED / name / renderer
    obs = load_observations(folder)
    assert [f.modalities for f in obs.frames] == [("rgb",), ("depth",)]
    for f in obs.frames:
        assert (f.camera.width, f.camera.height) == (96, 96) and f.camera.depth_type == "z"
    model = load_model(ROOT / e["model"])
    objects, noise = load_scene(model, folder / "scene.json")
    assert [o.as_dict() for o in objects] == e["scene"]["objects"]
    # Both folders carry the sensors' true Gaussian noise; sppl's also the values its model's
    # other noise parameters and latent lighting were rendered with (make.simulation_noise).
    assert noise["image"]["sigma"] == noise["depth"]["sigma"] == SIGMA
    if renderer == "cycles":
        assert noise == {"image": {"sigma": SIGMA}, "depth": {"sigma": SIGMA}}
    else:
        assert {k for k, _ in model.noise_groups} == set(noise)
        assert all(v == 0.0 for k in ("image", "depth") for n, v in noise[k].items()
                   if n == "outlier")


def depth_agreement(frame, model, objects, renderer):
    """The median |observed - rendered| depth over pixels of a surface away from edges (whose
    3x3 neighbourhood in the rendered depth spans under 20 cm; the sky, clipped at depth_max
    in both, is left out), and the share of those pixels off by more than 10 cm."""
    _, rendered = renderer.render([*model.static_parts, *(p for o in objects for p in o.parts)],
                                  frame.camera)
    pad = np.pad(rendered, 1, mode="edge")
    windows = np.stack([pad[i:i + 96, j:j + 96] for i in range(3) for j in range(3)])
    flat = (windows.max(axis=0) - windows.min(axis=0)) < 0.2
    surface = rendered < frame.camera.depth_max - 0.01
    diff = np.abs(frame.depth - rendered)[flat & surface & frame.depth_valid]
    return float(np.median(diff)), float(np.mean(diff > 0.1))


@pytest.fixture(scope="module")
def renderers(require_gl):
    from sppl.render import Renderer

    made = {}
    yield lambda model: made.setdefault(id(model.render), Renderer(model.render))
    for r in made.values():
        r.release()


@pytest.fixture(scope="module")
def models():
    return {m: load_model(ROOT / m) for m in {e["model"] for e in INDEX}}


@pytest.mark.parametrize("name", NAMES)
def test_cycles_depth_agrees_with_sppls_rendering_of_the_truth(name, renderers, models):
    """Sensor noise alone (0.02 m) gives a median |difference| of 0.0135 m; a depth along the
    ray read as along the axis, an image upside down or a focal length 10% off gives tenths
    of a metre over much of the floor."""
    model = models[entry(name)["model"]]
    folder = TESTBED / name / "cycles"
    objects, _ = load_scene(model, folder / "scene.json")
    frame = next(f for f in load_observations(folder).frames if f.depth is not None)
    median, far = depth_agreement(frame, model, objects, renderers(model))
    assert median < 0.025 and far < 0.02, (median, far)


@pytest.mark.parametrize("mistake", ["ray depth", "upside down", "focal length"])
def test_depth_agreement_catches_convention_mistakes(mistake, renderers, models):
    """The check above fails on the mistakes it is there for (made here on purpose)."""
    name = "blocks_prior3"
    model = models[entry(name)["model"]]
    folder = TESTBED / name / "cycles"
    objects, _ = load_scene(model, folder / "scene.json")
    frame = next(f for f in load_observations(folder).frames if f.depth is not None)
    cam = frame.camera
    if mistake == "ray depth":
        cam = dataclasses.replace(cam, depth_type="ray")
    elif mistake == "upside down":  # OpenCV's +y down read as OpenGL's +y up
        frame = dataclasses.replace(frame, depth=frame.depth[::-1].copy(),
                                    depth_valid=frame.depth_valid[::-1].copy())
    else:
        cam = dataclasses.replace(cam, fx=cam.fx * 1.1, fy=cam.fy * 1.1)
    frame = dataclasses.replace(frame, camera=cam)
    median, far = depth_agreement(frame, model, objects, renderers(model))
    assert not (median < 0.025 and far < 0.02), (median, far)


def test_render_script_makes_a_folder_that_agrees(tmp_path, renderers, models):
    """Only where Blender's bpy is installed: render one scene anew, few samples."""
    pytest.importorskip("bpy")
    pytest.importorskip("OpenEXR")
    sys.path.insert(0, str(TESTBED))
    try:
        from render_cycles import render_folder
    finally:
        sys.path.remove(str(TESTBED))
    e = entry("blocks_occlusion")
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(e["scene"]))
    out = render_folder(ROOT / e["model"], ROOT / e["cameras"], scene, tmp_path / "out",
                        samples=8)
    model = models[e["model"]]
    objects, noise = load_scene(model, out / "scene.json")
    assert noise["depth"]["sigma"] == SIGMA
    frame = next(f for f in load_observations(out).frames if f.depth is not None)
    median, far = depth_agreement(frame, model, objects, renderers(model))
    assert median < 0.025 and far < 0.02, (median, far)


@pytest.mark.parametrize("name", NAMES)
def test_the_speck_colour_test_adds_no_seed_at_the_truth_of_cycles_renders(
        name, renderers, models, monkeypatch):
    """Cycles' edges are anti-aliased, its shadows soft and its light bounced off the floor:
    at the true scene, a piece of strongly-off pixels beside a drawn edge shows a shade or
    blend of the colours drawn there, and the birth's colour test (sppl.infer.birth._Beside)
    keeps none of them as a speck: the seeds are those the rule without it finds."""
    from sppl.infer import birth
    from sppl.infer.chain import Sampler
    from sppl.scoring.scorer import Scorer

    model = models[entry(name)["model"]]
    folder = TESTBED / name / "cycles"
    sampler = Sampler(model, Scorer(model, load_observations(folder), renderers(model)),
                      np.random.default_rng(0))
    objects, noise = load_scene(model, folder / "scene.json")
    # The scene file gives the sensors' sigmas only; the rest (outlier rates) from the prior.
    drawn = sample_noise(model, np.random.default_rng(0))
    noise = {kind: {**drawn[kind], **noise.get(kind, {})} for kind in drawn}
    with_colours = sampler.birth.seeds(sampler.make_trace(objects, noise))

    class Never(birth._Beside):
        def unexplained(self, piece, strong):
            return False

    monkeypatch.setattr(birth, "_Beside", Never)
    without = sampler.birth.seeds(sampler.make_trace(objects, noise))
    assert with_colours.tolist() == without.tolist()
