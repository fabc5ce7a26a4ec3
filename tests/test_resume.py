"""Nothing lost: checkpoints, resumed runs, and runs killed at any moment.

A chain resumed from its checkpoint must draw exactly the samples of the uninterrupted chain
(same seed), whether it stopped cleanly, was killed in the middle of writing a sample or a
checkpoint, or was SIGKILLed at a random moment. Every comparison is exact: no tolerance.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from test_cli import CAMERAS, SCENE

from sppl.cli import main
from sppl.data.observations import load_observations
from sppl.lang import load_model
from sppl.output.samples import read_samples
from sppl.runs.chains import run_chains
from sppl.runs.checkpoint import CHECKPOINT
from sppl.runs.run import run_chain

STEPS = 16  # N; the reference run draws 2N
SEED = 5


def small_observations(d, root):
    """The shipped model and observations of its test scene by 24x24 cameras, simulated into
    ``d``: small enough for runs that are repeated and compared."""
    cameras = {**CAMERAS, "w": 24, "h": 24, "fl_x": 27.0, "fl_y": 27.0, "cx": 12.0, "cy": 12.0}
    (d / "cameras.json").write_text(json.dumps(cameras))
    (d / "scene.json").write_text(json.dumps(SCENE))
    model_path = root / "models" / "shapes.scn"
    assert main(["simulate", str(model_path), "--cameras", str(d / "cameras.json"),
                 "--scene", str(d / "scene.json"), "--out", str(d / "obs"), "--seed", "1"]) == 0
    return load_model(model_path), load_observations(d / "obs")


@pytest.fixture(scope="module")
def setup(tmp_path_factory, root, require_gl):
    d = tmp_path_factory.mktemp("resume")
    model, obs = small_observations(d, root)
    reference = d / "reference"
    run_chain(model, obs, reference, steps=2 * STEPS, seed=SEED, progress=False)
    return model, obs, d, read_samples(reference / "samples.jsonl")


class Killed(Exception):
    """Stands for the process dying: nothing after the raise runs, no last checkpoint."""


def die_at(step):
    def callback(s, trace, best, sampler):
        if s == step:
            raise Killed()
        return False

    return callback


def test_a_run_resumed_halfway_draws_the_samples_of_an_uninterrupted_one(setup, tmp_path):
    model, obs, _, reference = setup
    assert len(reference) == 2 * STEPS
    out = tmp_path / "run"
    first = run_chain(model, obs, out, steps=STEPS, seed=SEED, progress=False)
    assert first.summary["steps_done"] == STEPS and not first.summary["interrupted"]
    assert json.loads((out / CHECKPOINT).read_text())["step"] == STEPS
    second = run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == reference
    assert second.summary["resumed_from"] == STEPS
    assert second.summary["steps_done"] == 2 * STEPS
    # The move counts carry over: the summary counts every move of both halves.
    proposed = sum(m["proposed"] for m in second.summary["acceptance"].values())
    full = json.loads((setup[2] / "reference" / "summary.json").read_text())
    assert proposed == sum(m["proposed"] for m in full["acceptance"].values())
    assert second.summary["map"] == full["map"]


@pytest.mark.parametrize("checkpoint_seconds", [0.0, float("inf")], ids=["every-sweep", "start"])
def test_killed_mid_sample_write_resumes_exactly(setup, tmp_path, checkpoint_seconds):
    """The process dies after step 11 and while writing step 12's sample: the samples after
    the last checkpoint and the torn line are drawn again."""
    model, obs, _, reference = setup
    out = tmp_path / "run"
    with pytest.raises(Killed):
        run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False,
                  checkpoint_seconds=checkpoint_seconds, callback=die_at(11))
    with open(out / "samples.jsonl", "a") as f:
        f.write(json.dumps(reference[11])[:40])  # a torn line: the kill came mid-write
    assert read_samples(out / "samples.jsonl") == reference[:11]
    ckpt_step = json.loads((out / CHECKPOINT).read_text())["step"]
    assert ckpt_step == (10 if checkpoint_seconds == 0 else 0)
    run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == reference
    assert (out / "samples.jsonl").read_text().endswith("\n")


def test_killed_mid_checkpoint_write_keeps_the_previous_checkpoint(setup, tmp_path, monkeypatch):
    """The process dies with the new checkpoint half written: the old one is still whole."""
    import sppl.runs.checkpoint as checkpoint

    model, obs, _, reference = setup
    out = tmp_path / "run"
    calls = []
    real_replace = os.replace

    def dying_replace(src, dst):
        calls.append(dst)
        if len(calls) == 8:  # the checkpoint after step 7: torn, never renamed
            with open(src, "r+") as f:
                f.truncate(os.path.getsize(src) // 2)
            raise Killed()
        real_replace(src, dst)

    monkeypatch.setattr(checkpoint.os, "replace", dying_replace)
    with pytest.raises(Killed):
        run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False,
                  checkpoint_seconds=0.0)
    monkeypatch.setattr(checkpoint.os, "replace", real_replace)
    assert json.loads((out / CHECKPOINT).read_text())["step"] == 6
    assert (out / (CHECKPOINT + ".tmp")).exists()
    run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == reference


def test_sigint_stops_at_the_end_of_a_sweep_and_resumes_exactly(setup, tmp_path):
    model, obs, _, reference = setup
    out = tmp_path / "run"

    def interrupt(step, trace, best, sampler):
        if step == 9:
            os.kill(os.getpid(), signal.SIGINT)  # handled: the chain stops after this sweep
        return False

    result = run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False,
                       callback=interrupt)
    assert result.summary["interrupted"] and result.summary["steps_done"] == 9
    assert read_samples(out / "samples.jsonl") == reference[:9]
    assert json.loads((out / CHECKPOINT).read_text())["step"] == 9
    assert json.loads((out / "summary.json").read_text())["steps_done"] == 9
    run_chain(model, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == reference


# -- the command ---------------------------------------------------------------------------------


def sample_command(model, obs, out, *more):
    return [sys.executable, "-m", "sppl", "sample", str(model), "--obs", str(obs),
            "--out", str(out), "--seed", str(SEED), "-q", *map(str, more)]


def test_sigkill_at_a_random_moment_loses_at_most_the_sample_being_written(setup, tmp_path,
                                                                           root):
    """``sppl sample`` is SIGKILLed at a moment drawn at random (seeded) once it has written
    samples, checkpointing after every sweep. What it wrote is a byte-for-byte prefix of the
    uninterrupted run's samples file (a torn last line at most); it loses at most the sample
    being written, and ``--resume`` completes it exactly.

    How many it lost, counted: each sweep's sample is written and flushed, then the checkpoint
    of that sweep is written, before the next sweep starts. So when the checkpoint on disk says
    step c, the chain had finished at most c + 1 sweeps, and a samples file with c or c + 1
    whole samples lost at most one (the one being written, if the kill came between the sweep's
    end and its write) and nothing that a flush had handed to the system. (That each sample is
    flushed as it is written, with no checkpoint right behind it, is
    ``test_sigkill_loses_at_most_the_sample_being_written`` below.)"""
    _, _, d, _ = setup
    model = root / "models" / "shapes.scn"
    out = tmp_path / "killed"
    p = subprocess.Popen(sample_command(model, d / "obs", out, "--steps", 10**6,
                                        "--checkpoint-every", 0),
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    samples = out / "samples.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (samples.exists() and samples.stat().st_size):
        time.sleep(0.05)
    time.sleep(np.random.default_rng(7).uniform(0.0, 1.0))
    p.kill()
    p.wait(timeout=60)
    assert p.returncode == -signal.SIGKILL
    written = samples.read_bytes()
    got = read_samples(samples)
    assert got, p.stderr.read().decode()
    checkpointed = json.loads((out / CHECKPOINT).read_text())["step"]
    assert [s["step"] for s in got] == list(range(1, len(got) + 1))
    lost_at_most = checkpointed + 1 - len(got)  # sweeps finished, at most, minus samples kept
    assert lost_at_most in (0, 1), (checkpointed, len(got))

    steps = len(got) + 10
    reference = tmp_path / "reference"
    assert main(["sample", str(model), "--obs", str(d / "obs"), "--out", str(reference),
                 "--seed", str(SEED), "--steps", str(steps), "-q"]) == 0
    whole = (reference / "samples.jsonl").read_bytes()
    assert written == whole[: len(written)]  # a prefix, byte for byte, torn line and all
    assert main(["sample", "--resume", str(out), "--steps", str(steps), "-q"]) == 0
    assert samples.read_bytes() == whole


def test_sigterm_stops_cleanly_with_samples_summary_and_checkpoint_agreeing(setup, tmp_path,
                                                                           root):
    _, _, d, _ = setup
    out = tmp_path / "run"
    p = subprocess.Popen(sample_command(root / "models" / "shapes.scn", d / "obs", out,
                                        "--steps", 10**6),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    samples = out / "samples.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (samples.exists() and samples.stat().st_size):
        time.sleep(0.05)
    p.terminate()
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    assert "interrupted after" in stdout and f"sppl sample --resume {out}" in stderr
    summary = json.loads((out / "summary.json").read_text())
    done = summary["steps_done"]
    assert summary["interrupted"] and done > 0
    assert [s["step"] for s in read_samples(samples)] == list(range(1, done + 1))
    assert json.loads((out / CHECKPOINT).read_text())["step"] == done


KILL_SCRIPT = """
import os, signal, sys
from pathlib import Path
import numpy as np
from sppl.lang import load_model
from sppl.data.observations import load_observations
from sppl.runs.run import run_chain
from sppl.output.samples import SampleWriter

model, obs, out, step, torn = sys.argv[1], sys.argv[2], Path(sys.argv[3]), int(sys.argv[4]), sys.argv[5] == "torn"
write = SampleWriter.write

def write_then_die(self, s, trace, seen=None):
    if s == step and torn:  # die half way through the sample's line
        self.file.write('{"step": ' + str(s) + ', "score": ')
        self.file.flush()
        os.kill(os.getpid(), signal.SIGKILL)
    write(self, s, trace, seen)
    if s == step:  # die just after the sample is written
        os.kill(os.getpid(), signal.SIGKILL)

SampleWriter.write = write_then_die
run_chain(load_model(model), load_observations(obs), out, steps=10**6, seed=SEED, progress=False,
          checkpoint_seconds=0.5)
""".replace("SEED", str(SEED))


@pytest.mark.parametrize("torn", [False, True], ids=["after-a-write", "mid-write"])
def test_sigkill_loses_at_most_the_sample_being_written(setup, tmp_path, root, torn):
    """A process SIGKILLed at a step drawn at random loses no sample it finished writing:
    every sample is flushed as it is written, so the samples since the last flush are at most
    the one being written."""
    _, _, d, reference = setup
    step = int(np.random.default_rng(11 + torn).integers(3, 2 * STEPS))
    out = tmp_path / "run"
    script = tmp_path / "kill.py"
    script.write_text(KILL_SCRIPT)
    r = subprocess.run([sys.executable, str(script), str(root / "models" / "shapes.scn"),
                        str(d / "obs"), str(out), str(step), "torn" if torn else "whole"],
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(root)})  # this tree's sppl
    assert r.returncode == -signal.SIGKILL, r.stderr
    got = read_samples(out / "samples.jsonl")
    lost = step - len(got)
    assert lost == (1 if torn else 0)
    assert got == reference[: len(got)]


def test_several_chains_resume_each_from_its_checkpoint(setup, tmp_path):
    model, obs, _, _ = setup
    out = tmp_path / "run"
    run_chains(model, obs, out, chains=2, steps=6, seed=SEED, progress=False)
    result = run_chains(model, obs, out, chains=2, steps=12, seed=SEED, progress=False,
                        resume=True)
    assert result.summary["chain_steps_done"] == [12, 12]
    seeds = np.random.SeedSequence(SEED).spawn(2)
    for i in range(2):
        alone = tmp_path / f"alone_{i}"
        run_chain(model, obs, alone, steps=12, seed=seeds[i], progress=False)
        chain = out / f"chain_{i}"
        assert read_samples(chain / "samples.jsonl") == read_samples(alone / "samples.jsonl")
        assert json.loads((chain / "summary.json").read_text())["resumed_from"] == 6


# -- what --resume refuses -----------------------------------------------------------------------


def test_resume_errors(setup, tmp_path, capsys):
    model, obs, d, _ = setup
    out = tmp_path / "run"
    run_chain(model, obs, out, steps=4, seed=SEED, progress=False)
    cases = [
        (["--resume", str(tmp_path / "nowhere")], "not a run folder"),
        (["--resume", str(out)], "already drawn 4 of 4 steps"),
        (["--resume", str(out), "--steps", "8", "--seed", "9"], "--seed 9 differs"),
        (["--resume", str(out), "--force"], "choose one"),
        (["--resume", str(out), "--out", str(tmp_path / "other")], "leave out --out"),
    ]
    for args, message in cases:
        assert main(["sample", *args, "-q"]) == 1
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    changed = tmp_path / "changed.scn"
    changed.write_text(model.source.replace("poisson(1)", "poisson(2)", 1))
    assert main(["sample", str(changed), "--resume", str(out), "--steps", "8", "-q"]) == 1
    assert "model has changed since this run started" in capsys.readouterr().err


def test_a_damaged_checkpoint_is_a_clear_error(setup, tmp_path, capsys):
    model, obs, _, _ = setup
    out = tmp_path / "run"
    run_chain(model, obs, out, steps=4, seed=SEED, progress=False)
    (out / CHECKPOINT).write_text('{"format": 1, "step": 4}')
    assert main(["sample", "--resume", str(out), "--steps", "8", "-q"]) == 1
    err = capsys.readouterr().err
    assert "checkpoint is damaged" in err and len(err.strip().splitlines()) == 1


def test_resume_continues_with_the_recorded_paths(setup, tmp_path, monkeypatch):
    model, obs, d, reference = setup
    monkeypatch.chdir(d)
    run_chain(model, load_observations("obs"), d / "rel", steps=STEPS, seed=SEED,
              progress=False)
    assert main(["sample", "--resume", "rel", "--steps", str(2 * STEPS), "-q"]) == 0
    assert read_samples(d / "rel" / "samples.jsonl") == reference


def test_a_run_resumed_in_its_warm_up_draws_the_samples_of_an_uninterrupted_one(setup,
                                                                                 tmp_path):
    """The adapted steps and the annealing schedule are part of the chain's state: a run
    stopped in the middle of its warm-up resumes with the same scales and powers."""
    model, obs, _, _ = setup
    warm = dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, adapt=3 * STEPS // 2, anneal=STEPS + 4))
    reference = tmp_path / "reference"
    run_chain(warm, obs, reference, steps=2 * STEPS, seed=SEED, progress=False)
    out = tmp_path / "run"
    run_chain(warm, obs, out, steps=STEPS, seed=SEED, progress=False)
    state = json.loads((out / CHECKPOINT).read_text())["sampler"]["warmup"]
    assert state["sweep"] == STEPS and state["log_factors"]
    run_chain(warm, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == read_samples(reference / "samples.jsonl")
    # The warm-up is burned whatever --burn says.
    summary = json.loads((out / "summary.json").read_text())
    assert summary["burn"] == 3 * STEPS // 2
