"""Parallel tempering (sppl/infer/tempering.py): the ladder of powers, the swap's ratio against
exact tempered posteriors, and a tempered run that resumes exactly.

The exact check needs tempered posteriors in closed form: a scorer whose log likelihood is
GAIN times the number of objects makes the posterior of a Poisson(lambda) class a Poisson
(lambda e^(beta GAIN)) count with every object's parameters from the prior, for any power
beta. Ladders started with every rung at an exact draw of its own target must keep each rung
there; a swap with a wrong ratio moves the counts between rungs."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest
from false_alarms import EACH
from scipy import stats
from test_resume import (
    SEED,
    STEPS,
    setup,  # noqa: F401 (a fixture)
)
from toys import ball_class, toy_model

from sppl.infer import tempering
from sppl.lang import compile_model
from sppl.model.trace import make_object
from sppl.output.samples import read_samples
from sppl.runs.checkpoint import CHECKPOINT
from sppl.runs.run import run_chain
from sppl.scoring.scorer import PriorScorer
from sppl.verify import chisquare_gof

GAIN = 1.2
RATE = 1.0
RUNGS, HOTTEST = 3, 0.1


class CountScorer(PriorScorer):
    """log L(x) = GAIN * |x|: no observations, a likelihood that only counts."""

    def evaluate(self, objects, parent=None, noise=None):
        return {"n": len(objects)}, {}

    def evaluate_batch(self, requests):
        return [self.evaluate(*r) for r in requests]

    def log_likelihood(self, stats, noise) -> float:
        return GAIN * stats.get("n", 0)


def tempered_model():
    model = toy_model([ball_class(rate=RATE)])
    return dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, tempered=RUNGS, tempered_from=HOTTEST))


def exact_rate(power: float) -> float:
    return RATE * math.exp(power * GAIN)


def exact_draw(sampler, power: float, rng):
    cls = sampler.model.classes[0]
    n = rng.poisson(exact_rate(power))
    objects = tuple(make_object(sampler.model, cls, cls.sample_prior(rng)) for _ in range(n))
    return sampler.make_trace(objects, {})


def final_counts(ladders=400, length=6, seed=0):
    """Per rung, the counts of ``ladders`` ladders after ``length`` sweeps from exact draws."""
    model = tempered_model()
    rng = np.random.default_rng(seed)
    counts = [[] for _ in range(RUNGS)]
    swaps = [0, 0]
    for _ in range(ladders):
        sampler = tempering.TemperedSampler(model, CountScorer(),
                                            np.random.default_rng(rng.integers(2**63)))
        cold = exact_draw(sampler, 1.0, rng)
        sampler.hot_traces = [exact_draw(sampler, p, rng) for p in sampler.powers[1:]]
        for _ in range(length):
            cold = sampler.sweep(cold)
        for i, t in enumerate([cold, *sampler.hot_traces]):
            counts[i].append(len(t.objects))
        for (move, _), (n, a) in sampler.stats.counts.items():
            if move == "swap":
                swaps[0] += n
                swaps[1] += a
    return counts, swaps


def count_p_values(counts) -> list[float]:
    ps = []
    for power, observed in zip(tempering.ladder(RUNGS, HOTTEST), counts):
        top = max(observed) + 1
        freq = np.bincount(observed, minlength=top + 1).astype(float)
        probs = stats.poisson.pmf(np.arange(top + 1), exact_rate(power))
        probs[-1] = stats.poisson.sf(top - 1, exact_rate(power))  # the tail in the last bin
        ps.append(chisquare_gof(freq, probs)[1])
    return ps


def test_the_ladder_is_geometric_from_the_posterior():
    assert tempering.ladder(1, 0.1) == [1.0]
    powers = tempering.ladder(4, 0.001)
    assert powers[0] == 1.0 and math.isclose(powers[-1], 0.001)
    assert all(math.isclose(a / b, 10.0) for a, b in itertools.pairwise(powers))


@pytest.mark.false_alarm(EACH)
def test_each_rung_stays_at_its_exact_tempered_posterior(false_alarm):
    """Chi-square of each rung's count against Poisson(lambda e^(beta GAIN)), Holm over the
    rungs at the marker's false-alarm rate; the swaps are accepted often enough to matter."""
    counts, (proposed, accepted) = final_counts()
    ps = count_p_values(counts)
    assert min(ps) * len(ps) > false_alarm, ps
    assert proposed > 1000 and 0.2 < accepted / proposed < 0.9


def test_a_swap_with_its_ratio_reversed_is_caught(monkeypatch):
    """The swap accepted with the ratio's sign flipped (the cold rung takes the hotter
    rung's smaller scenes): the cold rung's count fails its chi-square (p below 1e-8 on this
    seed)."""
    real = tempering.accept
    monkeypatch.setattr(tempering, "accept", lambda log_alpha, rng: real(-log_alpha, rng))
    counts, _ = final_counts()
    assert count_p_values(counts)[0] < 1e-8


def test_a_model_asks_for_tempering_and_bad_values_are_one_line_errors():
    text = ("class ball { count ~ poisson(1) x : real ~ normal(0, 1)\n"
            "geometry sphere(0.2) at (x, 0) colour rgb(1, 0, 0) }\n")
    model = compile_model(text + "inference { tempered = 4 tempered_from = 0.01 }")
    assert (model.inference.tempered, model.inference.tempered_from) == (4, 0.01)
    from sppl.errors import ModelError

    for bad, message in (("tempered = 0", "`tempered` is a number of chains"),
                         ("tempered = 2.5", "`tempered` is a number of chains"),
                         ("tempered_from = 0", "`tempered_from` is a power of the likelihood"),
                         ("tempered_from = 1.5", "`tempered_from` is a power")):
        with pytest.raises(ModelError) as info:
            compile_model(text + f"inference {{ {bad} }}")
        assert message in str(info.value)


def test_a_tempered_run_resumed_halfway_draws_the_samples_of_an_uninterrupted_one(
        setup, tmp_path):  # noqa: F811
    """The hotter rungs' states, generators and warm-ups are in the checkpoint."""
    model, obs, _, _ = setup
    hot = dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, tempered=3, tempered_from=0.1))
    reference = tmp_path / "reference"
    run_chain(hot, obs, reference, steps=2 * STEPS, seed=SEED, progress=False)
    out = tmp_path / "run"
    run_chain(hot, obs, out, steps=STEPS, seed=SEED, progress=False)
    assert len(json.loads((out / CHECKPOINT).read_text())["sampler"]["hot"]) == 2
    run_chain(hot, obs, out, steps=2 * STEPS, seed=SEED, progress=False, resume=True)
    assert read_samples(out / "samples.jsonl") == read_samples(reference / "samples.jsonl")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["acceptance"]["swap"]["accepted"] > 0
