"""Which objects the cameras see: the id pass against its ray-cast twin, a scene with an
object hidden behind another, and the seen counts in samples, summaries and posterior.nc."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sppl.data.observations import load_observations
from sppl.lang import load_model
from sppl.model.simulate import load_scene, objects_from_dict
from sppl.model.trace import make_object
from sppl.output.posterior import load_run, posterior_arrays
from sppl.output.samples import format_summary, read_samples, summarise
from sppl.render.seen import SeenPass, seen_reference
from sppl.runs.experiment import simulate
from sppl.runs.run import ChainRun

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "shapes.scn"

# A cube 1.2 m tall in front of a small sphere, as one camera at (4, 0, 1) sees them: the line
# from the camera to the sphere's top passes through the cube's front face 0.66 m up.
HIDDEN = {
    "objects": [
        {"class": "cube", "params": {"x": 0.0, "y": 0.0, "a": 0.0, "s": 1.2, "c": "red"}},
        {"class": "sphere", "params": {"x": -1.0, "y": 0.0, "r": 0.25, "c": "blue"}},
        {"class": "cone", "params": {"x": 0.6, "y": -1.6, "r": 0.3, "h": 0.6, "c": "green"}},
    ],
    "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}},
}
CAMERAS = {
    "w": 40, "h": 32, "fl_x": 40.0, "fl_y": 40.0, "cx": 20.0, "cy": 16.0, "depth_max": 10.0,
    "frames": [{"name": "front", "modalities": ["rgb", "depth"],
                "look_at": {"eye": [4.0, 0.0, 1.0], "target": [0.0, 0.0, 0.5], "up": [0, 0, 1]}}],
}


@pytest.fixture(scope="module")
def hidden_obs(tmp_path_factory, require_gl):
    d = tmp_path_factory.mktemp("hidden")
    (d / "scene.json").write_text(json.dumps(HIDDEN))
    (d / "cameras.json").write_text(json.dumps(CAMERAS))
    return simulate(MODEL, d / "cameras.json", d / "scene.json", d / "obs", seed=0)


def test_a_hidden_object_is_unseen_by_both_passes(hidden_obs):
    model = load_model(MODEL)
    obs = load_observations(hidden_obs)
    objects, _ = load_scene(model, hidden_obs / "scene.json")
    fast = SeenPass(model, obs.cameras)
    assert fast(objects) == [True, False, True]
    assert seen_reference(model, objects, obs.cameras) == [True, False, True]
    # Without the cube, the sphere shows.
    assert fast(objects[1:]) == [True, True] == seen_reference(model, objects[1:], obs.cameras)
    # An object out of every camera's view, and one behind the camera, are unseen.
    away = objects_from_dict(model, {"objects": [
        {"class": "sphere", "params": {"x": 0.0, "y": 30.0, "r": 0.3, "c": "red"}},
        {"class": "sphere", "params": {"x": 6.0, "y": 0.0, "r": 0.3, "c": "red"}}]})
    assert fast((*objects, *away)) == [True, False, True, False, False]
    fast.release()


def test_the_id_pass_agrees_with_its_twin_on_random_scenes(require_gl):
    """Prior scenes of the shipped model through the three shapes' cameras at a quarter of
    their size: the GL id pass and the ray-cast one mark the same objects seen."""
    model = load_model(MODEL)
    obs = load_observations(ROOT / "examples" / "three_shapes" / "obs")
    import dataclasses

    cams = [dataclasses.replace(c, width=24, height=24, fx=c.fx / 4, fy=c.fy / 4,
                                cx=c.cx / 4, cy=c.cy / 4) for c in obs.cameras]
    fast = SeenPass(model, cams)
    rng = np.random.default_rng(3)
    from sppl.model.simulate import sample_objects

    marks = 0
    for _ in range(12):
        objects = sample_objects(model, rng)
        if not objects:
            continue
        assert fast(objects) == seen_reference(model, objects, cams)
        marks += len(objects)
    assert marks >= 10
    fast.release()


def test_samples_summary_and_posterior_mark_the_hidden_object(hidden_obs, tmp_path):
    """A chain started at the true scene: every written sample marks its objects as the
    ray-cast twin does, the summary's seen counts follow the marks, the printed summary leads
    with them, and posterior.nc holds them per slot."""
    model = load_model(MODEL)
    obs = load_observations(hidden_obs)
    out = tmp_path / "run"
    chain = ChainRun(model, obs, out, steps=12, seed=0, burn=0)
    objects, noise = load_scene(model, hidden_obs / "scene.json")
    chain.trace = chain.best = chain.sampler.make_trace(tuple(objects), noise)
    for step in range(1, 13):
        chain.after_sweep(step, chain.sampler.sweep(chain.trace))
    chain.close()
    result = chain.finish(False)
    samples = read_samples(out / "samples.jsonl")
    assert len(samples) == 12
    hidden_seen = 0
    for s in samples:
        objs = [make_object(model, model.object_class(o["class"]), o["params"])
                for o in s["objects"]]
        assert [o["seen"] for o in s["objects"]] == seen_reference(model, objs, obs.cameras)
        hidden_seen += sum(not o["seen"] for o in s["objects"])
    assert hidden_seen >= 1  # the sphere behind the cube, while the chain keeps it
    summary = result.summary
    n_seen = {str(k): sum(sum(o["seen"] for o in s["objects"]) == k for s in samples) / 12
              for k in range(4)}
    assert summary["n_seen"] == {k: v for k, v in n_seen.items() if v}
    text = format_summary(summary).splitlines()
    assert text[2].startswith("objects the cameras see: ")
    assert text[6].startswith("unseen objects the prior adds: ")
    assert any("(no camera sees it)" in line for line in text) == any(
        not o["seen"] for o in summary["map"]["objects"])
    post = posterior_arrays(load_run(out))
    assert post.dims["seen"] == ["slot"]
    assert (post.variables["seen"].sum(axis=-1) == post.variables["n_seen"]).all()
    assert (post.variables["seen"] <= post.variables["exists"]).all()
    assert post.variables["count_seen"].sum(axis=-1).tolist() == post.variables["n_seen"].tolist()


def test_summaries_without_seen_marks_stay_as_they_were():
    """Samples of an older sppl carry no marks: no seen counts, the old first lines."""
    samples = [{"step": 1, "score": 0.0, "log_likelihood": 0.0,
                "objects": [{"class": "cube", "params": {"x": 0.0}}], "noise": {}}]
    summary = summarise(samples, ["cube"], None, {}, extra={"steps_done": 1, "seconds": 0.0})
    assert "n_seen" not in summary
    assert "objects the cameras see" not in format_summary(summary)

