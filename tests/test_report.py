"""Several chains, the posterior file and the HTML report, end to end on a small scene."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from sppl.cli import main
from sppl.output.samples import read_samples

CAMERAS = {
    "w": 32, "h": 32, "fl_x": 36.0, "fl_y": 36.0, "cx": 16.0, "cy": 16.0, "depth_max": 8.0,
    "frames": [
        {"name": "rgb", "modalities": ["rgb"],
         "look_at": {"eye": [3.0, -2.5, 2.4], "target": [0, 0, 0.3], "up": [0, 0, 1]}},
        {"name": "depth", "modalities": ["depth"],
         "look_at": {"eye": [-3.0, -2.0, 2.6], "target": [0, 0, 0.3], "up": [0, 0, 1]}},
    ],
}
SCENE = {
    "objects": [
        {"class": "cube", "params": {"x": 0.4, "y": -0.3, "a": 0.2, "s": 0.7, "c": "red"}},
        {"class": "sphere", "params": {"x": -0.6, "y": 0.5, "r": 0.35, "c": "blue"}},
    ],
    "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}},
}
STEPS = 200


@pytest.fixture(scope="module")
def model(root):
    return root / "models" / "shapes.scn"


@pytest.fixture(scope="module")
def obs(tmp_path_factory, model, require_gl):
    d = tmp_path_factory.mktemp("report_sim")
    (d / "cameras.json").write_text(json.dumps(CAMERAS))
    (d / "scene.json").write_text(json.dumps(SCENE))
    assert main(["simulate", str(model), "--cameras", str(d / "cameras.json"),
                 "--scene", str(d / "scene.json"), "--out", str(d / "obs"), "--seed", "2"]) == 0
    return d / "obs"


@pytest.fixture(scope="module")
def two_chains(tmp_path_factory, model, obs):
    out = tmp_path_factory.mktemp("runs") / "two"
    assert main(["sample", str(model), "--obs", str(obs), "--steps", str(STEPS), "--chains", "2",
                 "--seed", "5", "--out", str(out), "-q"]) == 0
    return out


def test_chains_run_into_their_own_folders_with_spawned_seeds(two_chains):
    meta = json.loads((two_chains / "run.json").read_text())
    assert meta["chains"] == 2 and meta["seed"] == 5
    assert not (two_chains / "samples.jsonl").exists()
    samples = []
    for i in range(2):
        chain = two_chains / f"chain_{i}"
        chain_meta = json.loads((chain / "run.json").read_text())
        # The i-th stream of SeedSequence(5).spawn(2), recorded so the chain can be rerun alone.
        assert chain_meta["seed"] == {"entropy": 5, "spawn_key": [i]}
        assert chain_meta["chain"] == i and chain_meta["master_seed"] == 5
        s = read_samples(chain / "samples.jsonl")
        assert [x["step"] for x in s] == list(range(1, STEPS + 1))
        samples.append(s)
    assert samples[0] != samples[1]  # independent streams


def test_the_top_summary_pools_the_chains(two_chains):
    summary = json.loads((two_chains / "summary.json").read_text())
    chains = [json.loads((two_chains / f"chain_{i}" / "summary.json").read_text())
              for i in range(2)]
    assert summary["chains"] == 2
    assert summary["samples_used"] == sum(c["samples_used"] for c in chains)
    best = max(range(2), key=lambda i: chains[i]["map"]["score"])
    assert summary["map"]["chain"] == best
    assert summary["map"]["score"] == chains[best]["map"]["score"]
    for key, c in summary["acceptance_by_class"].items():
        assert c["proposed"] == sum(ch["acceptance_by_class"].get(key, {"proposed": 0})["proposed"]
                                    for ch in chains)
    d = summary["diagnostics"]
    assert {"n_objects", "log joint", "image_sigma", "depth_sigma"} <= set(d)
    assert all(f"count[{c}]" in d for c in ("cube", "cone", "sphere"))
    assert d["log joint"]["rhat"] is not None and d["log joint"]["ess_bulk"] > 0
    assert "R-hat" in (two_chains / "summary.txt").read_text()
    # The pooled summary leads with the number of objects the cameras see.
    assert sum(summary["n_seen"].values()) == pytest.approx(1.0) and "n_seen" in d
    assert (two_chains / "summary.txt").read_text().splitlines()[2].startswith(
        "objects the cameras see: ")


def test_the_same_seed_gives_the_same_chains(two_chains, model, obs, tmp_path):
    again = tmp_path / "again"
    assert main(["sample", str(model), "--obs", str(obs), "--steps", str(STEPS), "--chains", "2",
                 "--seed", "5", "--out", str(again), "-q"]) == 0
    for i in range(2):
        assert (read_samples(again / f"chain_{i}" / "samples.jsonl")
                == read_samples(two_chains / f"chain_{i}" / "samples.jsonl"))


def test_the_posterior_file_pads_objects_into_slots(two_chains, tmp_path, capsys):
    from sppl.output.posterior import open_posterior

    out = tmp_path / "exported.nc"
    assert main(["export", str(two_chains), "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    assert (two_chains / "posterior.nc").exists()  # `sample` wrote one too
    tree = open_posterior(out)
    post, stats = tree["posterior"].dataset, tree["sample_stats"].dataset
    summary = json.loads((two_chains / "summary.json").read_text())
    assert dict(post.sizes)["chain"] == 2
    assert dict(post.sizes)["draw"] == STEPS - summary["burn"] + 1
    assert list(post["class"].values) == ["cube", "cone", "sphere"]
    exists = post["exists"].values.astype(bool)
    n = post["n_objects"].values
    assert (exists.sum(axis=-1) == n).all()
    assert (post["count"].values.sum(axis=-1) == n).all()
    # Real objects come first in their slots; every empty slot is NaN / "".
    assert (np.diff(exists.astype(int), axis=-1) <= 0).all()
    assert np.isnan(post["x"].values[~exists]).all() and np.isfinite(post["x"].values[exists]).all()
    assert (post["object_class"].values[~exists] == -1).all()
    assert (post["c"].values[~exists] == -1).all()
    assert set(post["c_label"].values) <= {"red", "green", "blue"}
    assert post["c"].attrs["flag_meanings"].split() == list(post["c_label"].values)
    # The chain-0 draws are the chain's samples after burn-in, in order, numbered by sweep.
    kept = [s for s in read_samples(two_chains / "chain_0" / "samples.jsonl")
            if s["step"] >= summary["burn"]][: post.sizes["draw"]]
    assert list(post["draw"].values) == [s["step"] for s in kept]
    assert (stats["step"].values == post["draw"].values).all()
    assert np.allclose(stats["lp"].values[0], [s["score"] for s in kept])
    assert (n[0] == [len(s["objects"]) for s in kept]).all()
    classes = list(post["class"].values)
    first = sorted(kept[0]["objects"], key=lambda o: (classes.index(o["class"]),
                                                      o["params"]["x"], o["params"]["y"]))
    assert [classes[k] for k in post["object_class"].values[0, 0, : len(first)]] == \
        [o["class"] for o in first]
    colours = list(post["c_label"].values)
    assert [colours[k] for k in post["c"].values[0, 0, : len(first)]] == \
        [o["params"]["c"] for o in first]
    assert tree.attrs["seed"] == 5 and tree.attrs["chains"] == 2


def test_the_posterior_file_opens_in_arviz_summary_with_no_arguments(two_chains):
    """Every variable is a number: string categoricals in the posterior group made ArviZ's
    summary fail with a TypeError."""
    import warnings

    import arviz_stats
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # R-hat of a slot that never changes
        table = arviz_stats.summary(xr.open_datatree(two_chains / "posterior.nc"))
    assert {"n_objects", "count[cube]", "object_class[0]", "c[0]", "exists[0]"} <= set(table.index)
    assert table.loc["n_objects", "mean"] > 0


def test_one_chain_keeps_its_layout_and_gets_a_posterior_file(model, obs, tmp_path):
    from sppl.output.posterior import diagnostics, load_run, posterior_arrays

    out = tmp_path / "one"
    assert main(["sample", str(model), "--obs", str(obs), "--steps", "60", "--out", str(out),
                 "-q"]) == 0
    assert (out / "samples.jsonl").exists() and not (out / "chain_0").exists()
    assert (out / "posterior.nc").exists()
    d = diagnostics(posterior_arrays(load_run(out)))
    assert d["n_objects"]["rhat"] is None  # R-hat needs two chains
    from sppl.output.report import write_report

    page = write_report(out).read_text()
    assert "--chains 4" in page and "traces.png" in page


def test_export_of_a_folder_that_is_no_run_is_one_clear_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "sppl", "export", str(tmp_path)],
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 1
    assert "run.json" in r.stderr and "Traceback" not in r.stderr


@pytest.fixture(scope="module")
def report(two_chains):
    assert main(["report", str(two_chains)]) == 0
    return two_chains / "report" / "index.html"


def test_the_report_has_every_section_and_its_figures(report):
    page = report.read_text()
    from sppl.output.report import EXPLAIN

    for heading in ("The scene in 3D", "The cameras", "Posterior predictive",
                    "The posterior over counts", "Occupancy", "Each MAP object", "Traces",
                    "Acceptance rates", "R-hat", "The MAP scene against the truth",
                    "What the cameras see"):
        assert heading in page, heading
    for text in EXPLAIN.values():  # every explanation, once
        assert page.count(text) == 1
    images = re.findall(r'<img src="([^"]+)"', page)
    for name in ("camera_rgb.png", "camera_depth.png", "predictive_rgb.png",
                 "predictive_depth.png", "counts.png", "occupancy.png", "traces.png",
                 "acceptance.png"):
        assert name in images
    assert any(i.startswith("object_0_") for i in images)
    for i in images:  # every figure is a PNG beside the page
        assert (report.parent / i).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Nothing to fetch: the one script file is three.js, beside the page.
    assert re.findall(r'<script src="([^"]+)"', page) == ["three.min.js"]
    assert (report.parent / "three.min.js").exists()
    assert "http" not in page


def test_the_report_without_a_truth(two_chains, tmp_path):
    from sppl.output.report import write_report

    page = write_report(two_chains, out=tmp_path / "r", truth=False).read_text()
    assert "against the truth" not in page and "occupancy.png" in page


def test_the_report_opens_in_headless_chromium_with_nothing_missing(report):
    from browser import check_page, require_chromium

    result = check_page(report, require_chromium())
    assert result.images >= 8
    assert result.problems == []


def _view_data(page: str) -> dict:
    raw = re.search(r'<script type="application/json" id="sppl-view-data">(.*?)</script>',
                    page, re.DOTALL).group(1)
    return json.loads(raw.replace("<\\/", "</"))


def _parts(data: dict, scene: int) -> int:
    return sum(len(o["parts"]) for o in data["scenes"][scene])


def _hue_pixels(image, colour, min_chroma: float = 60) -> int:
    """Pixels of ``image`` (H, W, 3 bytes) with the hue of ``colour`` (RGB in [0, 1]): their
    colour minus its grey points the same way as the colour's, and is far from grey."""
    px = np.asarray(image, dtype=float)[..., :3]
    chroma = px - px.mean(axis=-1, keepdims=True)
    c = np.asarray(colour, dtype=float) - np.mean(colour)
    norm = np.linalg.norm(chroma, axis=-1)
    cosine = (chroma @ c) / np.maximum(norm * np.linalg.norm(c), 1e-9)
    return int(((norm > min_chroma) & (cosine > 0.95)).sum())


# Each unit shape's centre (sppl/model/geometry.py): where to look for it on the screen.
UNIT_CENTRES = {"box": (0, 0, 0.5), "cylinder": (0, 0, 0.5), "cone": (0, 0, 0.25),
                "sphere": (0, 0, 1.0)}


def test_the_3d_view_draws_the_map_ghosts_and_cameras_in_headless_chromium(report, model):
    """The view draws (a WebGL frame, read back; a screenshot holding each MAP object's
    colour where the object's centre projects), holds what the page's data says, replays the
    chain, and logs no error."""
    import io

    from browser import check_page, require_chromium
    from PIL import Image

    from sppl.lang import load_model

    data = _view_data(report.read_text())
    centres = []
    for o in data["scenes"][data["map"]]:
        part = o["parts"][0]
        matrix = np.reshape(part["m"], (4, 4)).T  # column-major
        centres.append((matrix @ [*UNIT_CENTRES[part["p"]], 1.0])[:3].tolist())
    hidden = "spplView.show({map: false, ghosts: false, truth: false, cameras: false})"
    result = check_page(report, require_chromium(), wait_for="window.spplViewReady === true",
                        screenshot="#sppl-view-canvas", evaluate=(
                            "spplView.counts()",
                            f"{hidden}, spplView.colouredPixels()",  # the grey ground alone
                            "spplView.show({cameras: true}), spplView.colouredPixels()",
                            "spplView.setFrame(0), spplView.counts()",
                            "spplView.setFrame(1e9), spplView.counts()",
                            "spplView.show({cameras: false, map: true}), spplView."
                            + "colouredPixels()",
                            f"spplView.project({json.dumps(centres)})",
                        ))
    assert result.problems == []
    counts, grey, cameras, first, last, solid, on_screen = result.values
    chain = next(c for c in data["chains"] if c["chain"] == data["map_chain"])
    assert counts == {"solid": _parts(data, data["map"]), "ghosts": len(data["ghosts"]),
                      "truth": _parts(data, data["truth"]), "cameras": 2,
                      "chains": 2, "frames": len(chain["frames"])}
    assert counts["solid"] == 2 and counts["ghosts"] == 30
    assert grey == 0 < cameras  # nothing coloured but what is drawn on purpose
    assert first["solid"] == _parts(data, chain["frames"][0]["scene"])
    assert last["solid"] == counts["solid"]  # the slider's end is the MAP
    assert solid > 200
    shot = np.asarray(Image.open(io.BytesIO(result.screenshot)).convert("RGB"))
    assert shot.shape[1] > 300
    colours = load_model(model).colours
    map_objects = json.loads((report.parent.parent / "summary.json").read_text())["map"]["objects"]
    for o, (u, v) in zip(map_objects, on_screen, strict=True):
        # Around where its centre projects, the MAP object's colour (shaded, not grey).
        u, v = int(u), int(v)
        patch = shot[v - 2:v + 3, u - 2:u + 3]
        assert _hue_pixels(patch, colours[o["params"]["c"]]) >= 20, (o, patch)


def test_the_browser_check_sees_a_missing_image_and_a_script_error(tmp_path):
    """The check above would pass on a page it could not read: make sure it can fail."""
    from browser import check_page, require_chromium

    Image = pytest.importorskip("PIL.Image")
    Image.new("RGB", (4, 4)).save(tmp_path / "here.png")
    page = tmp_path / "index.html"
    # The remote image is on this machine's loopback: a page that asks for it would ask the
    # network for it anywhere else.
    page.write_text("<!DOCTYPE html><html><body><img src='here.png'><img src='gone.png'>"
                    "<img src='http://127.0.0.1:9/remote.png'>"
                    "<script>undefined_function();</script></body></html>")
    result = check_page(page, require_chromium())
    assert result.images == 3
    assert sorted(u.rsplit("/", 1)[-1] for u in result.broken_images) == ["gone.png",
                                                                          "remote.png"]
    assert any("undefined_function" in e for e in result.exceptions), result
    assert result.remote_requests == ["http://127.0.0.1:9/remote.png"]
    assert len(result.problems) >= 3


def test_ctrl_c_stops_every_chain_with_a_summary(model, obs, tmp_path):
    out = tmp_path / "run"
    p = subprocess.Popen(
        [sys.executable, "-m", "sppl", "sample", str(model), "--obs", str(obs), "--chains", "2",
         "--steps", "1000000", "--out", str(out), "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    files = [out / f"chain_{i}" / "samples.jsonl" for i in range(2)]
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        time.sleep(0.5)
        if all(f.exists() and f.stat().st_size > 0 for f in files):
            break
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    try:
        stdout, stderr = p.communicate(timeout=120)
    finally:
        p.kill()  # a run that did not stop must not outlive the test
    assert p.returncode == 130, stderr
    assert "interrupted after" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["chains"] == 2
    for i in range(2):
        chain = json.loads((out / f"chain_{i}" / "summary.json").read_text())
        assert chain["interrupted"] and chain["steps_done"] >= len(read_samples(files[i])) > 0
