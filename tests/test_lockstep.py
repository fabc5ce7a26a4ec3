"""Chains in lockstep (``sppl sample --chains N --lockstep``) are the chains run one by one.

Each chain has its own generator and the chains share only the scorer, which is a pure function
of the objects it is given, so the lockstep chains must draw exactly (byte for byte) the samples
of the same chains run one after another with the same seeds, on the fast path too. There the
full-scene hypotheses of a round are drawn together, each into its own framebuffer, and their
float64 sums are one matrix product for the batch; the comparison stays exact because a row of
that product has so far always come out equal to the product of the row alone (if a BLAS ever
made them differ in the last bit, the scores here would need a 1e-9 relative tolerance).
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal

import numpy as np
import pytest
from test_resume import small_observations

import sppl.runs.lockstep
from sppl.cli import main
from sppl.infer.chain import Sampler
from sppl.output.samples import read_samples
from sppl.render import Renderer
from sppl.runs.chains import run_chains
from sppl.runs.checkpoint import CHECKPOINT
from sppl.runs.lockstep import sweep_together
from sppl.runs.run import chain_folder, run_chain
from sppl.scoring.scorer import ReferenceScorer

STEPS = 12
SEED = 4
CHAINS = 3


@pytest.fixture(scope="module")
def setup(tmp_path_factory, root, require_gl):
    d = tmp_path_factory.mktemp("lockstep")
    return (*small_observations(d, root), d)


def one_by_one(model, obs, out, steps=2 * STEPS):
    """The samples of each chain of a run of CHAINS, run alone with its own scorer."""
    seeds = np.random.SeedSequence(SEED).spawn(CHAINS)
    for i in range(CHAINS):
        run_chain(model, obs, out / f"alone_{i}", steps=steps, seed=seeds[i], progress=False)
    return [(out / f"alone_{i}" / "samples.jsonl").read_bytes() for i in range(CHAINS)]


def lockstep_samples(out):
    return [(chain_folder(out, i) / "samples.jsonl").read_bytes() for i in range(CHAINS)]


@pytest.mark.parametrize("tries", [1, 3], ids=["single-try", "multiple-try"])
def test_lockstep_chains_draw_the_samples_of_the_chains_run_one_by_one(setup, tmp_path, tries):
    model, obs, _ = setup
    model = dataclasses.replace(model, inference=dataclasses.replace(model.inference,
                                                                     tries=tries))
    alone = one_by_one(model, obs, tmp_path)
    out = tmp_path / "lockstep"
    result = run_chains(model, obs, out, chains=CHAINS, steps=2 * STEPS, seed=SEED,
                        progress=False, lockstep=True)
    assert lockstep_samples(out) == alone
    assert json.loads((out / "run.json").read_text())["lockstep"] is True
    assert result.summary["chains"] == CHAINS and not result.summary["interrupted"]
    for i in range(CHAINS):
        assert json.loads((chain_folder(out, i) / CHECKPOINT).read_text())["step"] == 2 * STEPS


def test_lockstep_sweeps_on_the_reference_scorer_are_the_sweeps_of_each_chain(setup):
    """The driver itself, on the scorer that renders one hypothesis at a time: the traces
    (objects, noise, scores) after every round are exactly those of each chain's own sweeps."""
    model, obs, _ = setup
    scorer = ReferenceScorer(model, obs, Renderer(model.render))

    def samplers():
        return [Sampler(model, scorer, np.random.default_rng(s)) for s in range(CHAINS)]

    together, alone = samplers(), samplers()
    a = [s.initial_trace() for s in together]
    b = [s.initial_trace() for s in alone]
    for _ in range(8):
        a = sweep_together(together, a)
        b = [s.sweep(t) for s, t in zip(alone, b)]
        assert [t.as_dict() for t in a] == [t.as_dict() for t in b]
        assert [t.score for t in a] == [t.score for t in b]
    assert [s.stats.as_dict() for s in together] == [s.stats.as_dict() for s in alone]


def test_a_lockstep_run_resumed_halfway_draws_the_uninterrupted_samples(setup, tmp_path):
    model, obs, _ = setup
    alone = one_by_one(model, obs, tmp_path)
    out = tmp_path / "lockstep"
    run_chains(model, obs, out, chains=CHAINS, steps=STEPS, seed=SEED, progress=False,
               lockstep=True)
    result = run_chains(model, obs, out, chains=CHAINS, steps=2 * STEPS, seed=SEED,
                        progress=False, lockstep=True, resume=True)
    assert lockstep_samples(out) == alone
    assert result.summary["chain_steps_done"] == [2 * STEPS] * CHAINS


def test_sigint_stops_every_chain_at_the_end_of_the_round_and_resumes_exactly(
        setup, tmp_path, monkeypatch):
    model, obs, _ = setup
    alone = one_by_one(model, obs, tmp_path)
    rounds = []
    real = sppl.runs.lockstep.sweep_together

    def interrupting(samplers, traces):
        rounds.append(None)
        if len(rounds) == 5:
            os.kill(os.getpid(), signal.SIGINT)  # handled: every chain stops after this round
        return real(samplers, traces)

    monkeypatch.setattr(sppl.runs.lockstep, "sweep_together", interrupting)
    out = tmp_path / "lockstep"
    result = run_chains(model, obs, out, chains=CHAINS, steps=2 * STEPS, seed=SEED,
                        progress=False, lockstep=True)
    assert result.summary["interrupted"]
    for i in range(CHAINS):
        folder = chain_folder(out, i)
        assert read_samples(folder / "samples.jsonl") == [
            json.loads(line) for line in alone[i].decode().splitlines()[:5]]
        assert json.loads((folder / CHECKPOINT).read_text())["step"] == 5
        assert json.loads((folder / "summary.json").read_text())["steps_done"] == 5
    monkeypatch.setattr(sppl.runs.lockstep, "sweep_together", real)
    run_chains(model, obs, out, chains=CHAINS, steps=2 * STEPS, seed=SEED, progress=False,
               lockstep=True, resume=True)
    assert lockstep_samples(out) == alone


def test_sample_lockstep_on_the_shipped_example_then_resume_and_export(root, tmp_path,
                                                                        require_gl, capsys):
    out = tmp_path / "run"
    common = ["sample", str(root / "models" / "shapes.scn"), "--obs",
              str(root / "examples" / "three_shapes" / "obs"), "-q"]
    assert main([*common, "--chains", "2", "--lockstep", "--steps", "30", "--seed", "2",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["chain_steps_done"] == [30, 30] and summary["map"]["chain"] in (0, 1)
    assert (out / "posterior.nc").exists()
    assert json.loads((out / "run.json").read_text())["lockstep"] is True
    assert main(["sample", "--resume", str(out), "--steps", "40", "-q"]) == 0
    assert json.loads((out / "summary.json").read_text())["chain_steps_done"] == [40, 40]
    for i in range(2):
        steps = [s["step"] for s in read_samples(chain_folder(out, i) / "samples.jsonl")]
        assert steps == list(range(1, 41))
    # The same chains in processes: the same samples.
    processes = tmp_path / "processes"
    assert main([*common, "--chains", "2", "--steps", "40", "--seed", "2",
                 "--out", str(processes)]) == 0
    for i in range(2):
        assert ((chain_folder(out, i) / "samples.jsonl").read_bytes()
                == (chain_folder(processes, i) / "samples.jsonl").read_bytes())
    assert main(["export", str(out), "--out", str(tmp_path / "exported.nc")]) == 0
