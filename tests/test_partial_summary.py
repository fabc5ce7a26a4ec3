"""No summary is made of warm-up samples: a run with too few samples after burn-in gets a
summary marked partial, the same in summary.json, summary.txt, the printed summary, the report
and posterior.nc, and with none at all it has no posterior numbers.

The model is the shipped shapes.scn with a warm-up of WARMUP sweeps (adapt and anneal), on
24x24 cameras: each run here takes a fraction of a second.
"""

from __future__ import annotations

import json
import os
import signal

import pytest
from test_resume import small_observations

from sppl.cli import main
from sppl.lang import load_model
from sppl.output.posterior import open_posterior
from sppl.output.samples import MIN_SAMPLES, format_summary, summarise
from sppl.runs.run import run_chain

WARMUP = 20


def _sample(step: int) -> dict:
    return {"step": step, "score": 0.0, "log_likelihood": 0.0, "objects": [],
            "noise": {"image": {"sigma": 0.1}}}


def test_samples_before_the_burn_in_never_enter_the_summary():
    """The old summary fell back to every sample when none was left after burn-in."""
    samples = [_sample(s) for s in range(1, 61)]
    summary = summarise(samples, ["ball"], None, {}, burn=100)
    assert summary["samples_used"] == 0 and summary["n_objects"] == {}
    assert summary["noise"] == {} and summary["class_sets"] == {}
    assert summary["partial"].startswith("no samples after the burn-in of 100 steps")
    text = format_summary({**summary, "steps_done": 60})
    assert text.splitlines()[0].startswith("PARTIAL SUMMARY: no samples")
    assert "posterior: none" in text and "number of objects" not in text

    few = summarise(samples, ["ball"], None, {}, burn=55)  # steps 55..60
    assert few["samples_used"] == 6 and "only 6 samples" in few["partial"]
    assert few["n_objects"] == {"0": 1.0}
    enough = summarise(samples, ["ball"], None, {}, burn=60 - MIN_SAMPLES + 1)
    assert enough["samples_used"] == MIN_SAMPLES and enough["partial"] is None
    assert "PARTIAL" not in format_summary({**enough, "steps_done": 60})


@pytest.fixture(scope="module")
def warm(tmp_path_factory, root, require_gl):
    """(model file with a warm-up, observation folder)."""
    d = tmp_path_factory.mktemp("warm")
    _, _ = small_observations(d, root)
    text = (root / "models" / "shapes.scn").read_text()
    text = text.replace("    p_jump = 1\n", f"    p_jump = 1\n    adapt = {WARMUP}\n"
                        f"    anneal = {WARMUP}\n")
    assert f"adapt = {WARMUP}" in text
    (d / "warm.scn").write_text(text)
    return d / "warm.scn", d / "obs"


def _run(warm, out, *options):
    model, obs = warm
    return main(["sample", str(model), "--obs", str(obs), "--out", str(out), "-q", *options])


def _files(out):
    summary = json.loads((out / "summary.json").read_text())
    return summary, (out / "summary.txt").read_text()


def test_a_run_shorter_than_its_warm_up_has_no_posterior(warm, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(warm, out, "--steps", "12") == 0
    captured = capsys.readouterr()
    assert f"leaves 0 samples after the burn-in of {WARMUP} (the warm-up" in captured.err
    assert "warning: partial summary: no samples" in captured.err
    assert captured.out.startswith("PARTIAL SUMMARY: no samples after the burn-in of 20 steps")
    summary, text = _files(out)
    assert summary["samples_used"] == 0 and summary["burn"] == WARMUP
    assert summary["partial"] and summary["n_objects"] == {} and summary["noise"] == {}
    assert text.startswith("PARTIAL SUMMARY: no samples") and "posterior: none" in text
    assert not (out / "posterior.nc").exists()  # nothing to write: said on stderr
    assert "no posterior file" in captured.err


@pytest.mark.parametrize("burn, kept", [(40, 1), (50, 0)])
def test_a_burn_in_as_long_as_the_run_is_partial(warm, tmp_path, capsys, burn, kept):
    """--burn B keeps the steps from B on: with B = --steps one sample, beyond it none."""
    out = tmp_path / "run"
    assert _run(warm, out, "--steps", "40", "--burn", str(burn)) == 0
    err = capsys.readouterr().err
    assert f"leaves {kept} samples after the burn-in of {burn} (--burn)" in err
    summary, text = _files(out)
    assert summary["samples_used"] == kept and summary["partial"] and text.startswith("PARTIAL")


def test_a_short_burn_in_is_partial_in_every_file_and_the_report(warm, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(warm, out, "--steps", str(WARMUP + 3)) == 0  # steps 20..23 are kept
    summary, text = _files(out)
    assert summary["samples_used"] == 4 and "only 4 samples" in summary["partial"]
    assert text.startswith("PARTIAL SUMMARY: only 4 samples")
    attrs = open_posterior(out / "posterior.nc").attrs
    assert attrs["partial"] == summary["partial"]
    assert main(["report", str(out), "--no-truth"]) == 0
    page = (out / "report" / "index.html").read_text()
    assert "<p class='partial'>PARTIAL SUMMARY: only 4 samples" in page

    full = tmp_path / "full"
    assert _run(warm, full, "--steps", str(WARMUP + MIN_SAMPLES - 1)) == 0
    assert _files(full)[0]["partial"] is None
    assert "partial" not in open_posterior(full / "posterior.nc").attrs


def test_a_run_interrupted_in_its_warm_up_has_no_posterior(warm, tmp_path):
    """Stopped at step 5 of a warm-up of 20, with --steps 200: the interrupted run's burn-in
    (half what it did) is still never shorter than the warm-up."""
    model, obs = load_model(warm[0]), __import__("sppl").load_observations(warm[1])

    def interrupt(step, trace, best, sampler):
        if step == 5:
            os.kill(os.getpid(), signal.SIGINT)  # handled: the chain stops after this sweep
        return False

    out = tmp_path / "run"
    result = run_chain(model, obs, out, steps=200, seed=1, progress=False, callback=interrupt)
    summary, text = _files(out)
    assert result.summary == summary
    assert summary["interrupted"] and summary["steps_done"] == 5
    assert summary["samples_used"] == 0 and summary["burn"] == WARMUP and summary["partial"]
    assert text.startswith("PARTIAL SUMMARY: no samples")


def test_chains_and_resume_summarise_only_samples_after_the_warm_up(warm, tmp_path, capsys):
    """In lockstep (one process: seconds, where processes take half a minute); the pooled
    summary is made the same way for chains in processes (``run.combine_chains``)."""
    out = tmp_path / "run"
    assert _run(warm, out, "--steps", "12", "--chains", "2", "--lockstep") == 0
    summary, text = _files(out)
    assert summary["samples_used"] == 0 and summary["partial"] and text.startswith("PARTIAL")
    for i in range(2):
        assert json.loads((out / f"chain_{i}" / "summary.json").read_text())["partial"]
    capsys.readouterr()

    # Resumed to 30 steps: every chain keeps its steps 20..30, never one of the warm-up.
    assert main(["sample", "--resume", str(out), "--steps", "30", "-q"]) == 0
    summary, text = _files(out)
    assert summary["samples_used"] == 2 * 11 and summary["partial"] is None
    assert "PARTIAL" not in text and "PARTIAL" not in capsys.readouterr().out
    for i in range(2):
        chain = json.loads((out / f"chain_{i}" / "summary.json").read_text())
        assert chain["samples_used"] == 11 and chain["burn"] == WARMUP
    assert open_posterior(out / "posterior.nc").attrs["draws_per_chain"] == 11
