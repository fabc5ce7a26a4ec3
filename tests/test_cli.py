"""The commands end to end, as a user runs them."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sppl.cli import main
from sppl.output.samples import read_samples

CAMERAS = {
    "w": 40, "h": 40, "fl_x": 45.0, "fl_y": 45.0, "cx": 20.0, "cy": 20.0, "depth_max": 8.0,
    "frames": [
        {"name": "rgb", "modalities": ["rgb"],
         "look_at": {"eye": [3.0, -2.5, 2.4], "target": [0, 0, 0.3], "up": [0, 0, 1]}},
        {"name": "depth", "modalities": ["depth"],
         "look_at": {"eye": [-3.0, -2.0, 2.6], "target": [0, 0, 0.3], "up": [0, 0, 1]}},
    ],
}
SCENE = {
    "objects": [{"class": "cube", "params": {"x": 0.3, "y": -0.2, "a": 0.2, "s": 0.7, "c": "red"}}],
    "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}},
}


def run(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "sppl", *map(str, args)],
        capture_output=True, text=True, timeout=timeout,
    )


@pytest.fixture(scope="module")
def obs(tmp_path_factory, root, require_gl):
    d = tmp_path_factory.mktemp("sim")
    (d / "cameras.json").write_text(json.dumps(CAMERAS))
    (d / "scene.json").write_text(json.dumps(SCENE))
    code = main(["simulate", str(root / "models" / "shapes.scn"), "--cameras", str(d / "cameras.json"),
                 "--scene", str(d / "scene.json"), "--out", str(d / "obs"), "--seed", "3"])
    assert code == 0
    return d / "obs"


def test_help_works_both_ways():
    for cmd in (["sppl", "--help"], [sys.executable, "-m", "sppl", "--help"]):
        r = subprocess.run(cmd, capture_output=True, text=True)
        assert r.returncode == 0
        assert "simulate" in r.stdout and "sample" in r.stdout and "check" in r.stdout


def test_check_lists_classes_and_parameters(root, capsys):
    assert main(["check", str(root / "models" / "shapes.scn")]) == 0
    out = capsys.readouterr().out
    for expected in ("class cube", "class cone", "class sphere", "periodic(", "gamma(2, 0.333"):
        assert expected in out


def test_bad_model_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.scn"
    bad.write_text("class cube {\n  count ~ poisson(1)\n  s : positive ~ gama(2, 1)\n"
                   "  geometry box(s, s, s) colour rgb(1, 0, 0)\n}\n")
    r = run("check", bad)
    assert r.returncode == 1
    assert r.stderr.startswith(f"error: {bad}:3:18: unknown distribution")
    assert "did you mean `gamma`" in r.stderr
    assert "Traceback" not in r.stderr


def test_missing_observations_is_one_clear_error(tmp_path, root):
    r = run("sample", root / "models" / "shapes.scn", "--obs", tmp_path / "nowhere",
            "--out", tmp_path / "run")
    assert r.returncode == 1
    assert "nowhere" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_simulate_writes_observations_and_truth(obs):
    t = json.loads((obs / "transforms.json").read_text())
    assert len(t["frames"]) == 2
    assert (obs / "images" / "rgb.png").exists() and (obs / "depth" / "depth.npy").exists()
    scene = json.loads((obs / "scene.json").read_text())
    assert scene["objects"][0]["class"] == "cube"
    assert scene["noise"]["depth"]["sigma"] == 0.05


def test_sample_streams_samples_and_summary(obs, root, tmp_path, capsys):
    out = tmp_path / "run"
    common = ["sample", str(root / "models" / "shapes.scn"), "--obs", str(obs), "--steps", "300",
              "--seed", "1", "-q"]
    args = [*common, "--out", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "MAP scene" in text and "acceptance" in text and "noise image.sigma" in text
    samples = read_samples(out / "samples.jsonl")
    assert [s["step"] for s in samples] == list(range(1, 301))
    summary = json.loads((out / "summary.json").read_text())
    assert {"map", "n_objects", "class_counts", "class_sets", "acceptance", "noise"} <= set(summary)
    assert sum(summary["n_objects"].values()) == pytest.approx(1.0)
    # Same seed, same samples.
    assert main([*common, "--out", str(tmp_path / "again")]) == 0
    assert read_samples(tmp_path / "again" / "samples.jsonl") == samples
    # An existing run is not overwritten without --force, and is replaced with it.
    assert main(args) == 1
    assert "already exists" in capsys.readouterr().err
    assert read_samples(out / "samples.jsonl") == samples
    assert main([*args, "--steps", "5", "--force"]) == 0
    assert [s["step"] for s in read_samples(out / "samples.jsonl")] == [1, 2, 3, 4, 5]
    assert json.loads((out / "summary.json").read_text())["steps_done"] == 5


def test_simulate_replaces_its_observations_only_with_force(obs, root, tmp_path, capsys):
    again = tmp_path / "obs"
    shutil.copytree(obs, again)
    (again / "images" / "stale.png").write_bytes(b"")  # inside images/: sppl's to replace
    args = ["simulate", str(root / "models" / "shapes.scn"), "--cameras",
            str(obs.parent / "cameras.json"), "--out", str(again), "--seed", "3"]
    assert main(args) == 1
    assert "already exists" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    assert not (again / "images" / "stale.png").exists()
    assert sorted(p.name for p in again.iterdir()) == sorted(p.name for p in obs.iterdir())


def old_run(out):
    """A run folder of two chains as `sppl sample` and `sppl report` leave it."""
    for folder in (out, out / "chain_0", out / "chain_1"):
        folder.mkdir(parents=True)
        for name in ("run.json", "summary.json", "summary.txt"):
            (folder / name).write_text("{}")
    for chain in ("chain_0", "chain_1"):
        for name in ("samples.jsonl", "checkpoint.json", "checkpoint.json.tmp"):
            (out / chain / name).write_text("")
    (out / "posterior.nc").write_bytes(b"")
    (out / "report").mkdir()
    (out / "report" / "index.html").write_text("")
    return out


def test_force_replaces_a_whole_run_folder(tmp_path, monkeypatch):
    from sppl.cli import _prepare_out
    from sppl.errors import UsageError

    monkeypatch.chdir(tmp_path)
    out = old_run(tmp_path / "run")
    with pytest.raises(UsageError, match="already exists"):
        _prepare_out(out, False)
    assert (out / "chain_1" / "samples.jsonl").exists()
    _prepare_out(out, True, inputs={"--obs": tmp_path / "obs"})
    assert out.is_dir() and list(out.iterdir()) == []


@pytest.mark.parametrize("change, message", [
    (lambda out: (out / "chain_1" / "mine.txt").write_text("x"), "chain_1/mine.txt"),
    (lambda out: (out / "notes").mkdir(), "it holds notes, which `sppl sample` does not write"),
    (lambda out: (out / "chain_0" / "old").symlink_to(out.parent),
     "chain_0/old, a symbolic link"),
    (lambda out: [shutil.rmtree(p) if p.is_dir() else p.unlink() for p in out.iterdir()
                  if p.name != "report"], "it has none of"),
], ids=["a-file-of-a-chain", "a-folder", "a-link", "no-run-files"])
def test_force_keeps_a_run_folder_holding_what_sppl_did_not_write(tmp_path, monkeypatch, change,
                                                                 message):
    from sppl.cli import _prepare_out
    from sppl.errors import UsageError

    monkeypatch.chdir(tmp_path)
    out = old_run(tmp_path / "run")
    change(out)
    before = sorted(str(p) for p in out.rglob("*"))
    with pytest.raises(UsageError, match="does not look like one") as error:
        _prepare_out(out, True)
    assert message in str(error.value)
    assert sorted(str(p) for p in out.rglob("*")) == before  # nothing deleted


def test_force_never_deletes_the_folder_it_runs_in_or_its_inputs(tmp_path, monkeypatch):
    from sppl.cli import _prepare_out
    from sppl.errors import UsageError

    out = old_run(tmp_path / "run")
    monkeypatch.chdir(out / "chain_0")
    with pytest.raises(UsageError, match="a folder that holds the current one"):
        _prepare_out(out, True)
    monkeypatch.chdir(tmp_path)
    (out / "obs").mkdir()
    with pytest.raises(UsageError, match="which --obs reads"):
        _prepare_out(out, True, inputs={"--obs": Path("run") / "obs"})
    sim = tmp_path / "sim"
    sim.mkdir()
    (sim / "transforms.json").write_text("{}")
    with pytest.raises(UsageError, match="which --cameras reads"):
        _prepare_out(sim, True, kind="obs", inputs={"--cameras": sim / "transforms.json"})
    assert (out / "chain_0" / "samples.jsonl").exists() and (sim / "transforms.json").exists()


def test_ctrl_c_leaves_readable_samples_and_summary(obs, root, tmp_path):
    out = tmp_path / "run"
    p = subprocess.Popen(
        [sys.executable, "-m", "sppl", "sample", str(root / "models" / "shapes.scn"), "--obs", str(obs),
         "--steps", "1000000", "--out", str(out), "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        time.sleep(0.5)
        if (out / "samples.jsonl").exists() and (out / "samples.jsonl").stat().st_size > 0:
            break
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    try:
        stdout, stderr = p.communicate(timeout=60)
    finally:
        p.kill()  # a run that did not stop must not outlive the test
    assert p.returncode == 130, stderr
    assert "interrupted after" in stdout
    samples = read_samples(out / "samples.jsonl")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["steps_done"] >= len(samples) > 0


def test_a_fourth_class_needs_no_python(tmp_path, root, require_gl):
    """A cylinder class added in a model file is simulated, sampled and found."""
    model = tmp_path / "four.scn"
    model.write_text(
        (root / "models" / "shapes.scn").read_text()
        + """
class cylinder {
    count ~ poisson(1)
    x : real ~ normal(0, sigma_position)
    y : real ~ normal(0, sigma_position)
    r : positive ~ gamma(size_shape, size_scale)
    h : positive ~ gamma(size_shape, size_scale)
    c : colour ~ categorical(red, green, blue)
    geometry cylinder(r, h) at (x, y) colour c
}
"""
    )
    scene = {"objects": [{"class": "cylinder",
                          "params": {"x": 0.2, "y": 0.1, "r": 0.45, "h": 0.8, "c": "green"}}],
             "noise": SCENE["noise"]}
    (tmp_path / "cameras.json").write_text(json.dumps(CAMERAS))
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    assert main(["simulate", str(model), "--cameras", str(tmp_path / "cameras.json"),
                 "--scene", str(tmp_path / "scene.json"), "--out", str(tmp_path / "obs")]) == 0
    assert main(["sample", str(model), "--obs", str(tmp_path / "obs"), "--steps", "2000",
                 "--seed", "0", "--out", str(tmp_path / "run"), "-q"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [o["class"] for o in summary["map"]["objects"]] == ["cylinder"]
    assert summary["map"]["objects"][0]["params"]["c"] == "green"
    assert summary["class_counts"]["cylinder"].get("1", 0) > 0.5


def test_sample_runs_on_the_shipped_example(root, tmp_path, require_gl):
    r = run("sample", root / "models" / "shapes.scn", "--obs", root / "examples" / "three_shapes" / "obs",
            "--steps", "200", "--out", tmp_path / "run", "-q")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["steps_done"] == 200 and summary["map"]["score"] > 0


@pytest.mark.slow
def test_the_shipped_example_is_solved_with_default_settings(root, require_gl):
    """The full check lives in benchmarks/time_to_solution.py; this is one seed of it."""
    r = subprocess.run(
        [sys.executable, str(root / "benchmarks" / "time_to_solution.py"), "--seeds", "0"],
        capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stderr
    assert "solved 1 of 1 seeds" in r.stdout, r.stdout
