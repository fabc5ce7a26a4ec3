"""Numerics of the accept decision: log space throughout, and no NaN ever reaches it.

A NaN acceptance ratio means the proposal is rejected and counted (``stats.nan``); the chain
only ever holds states whose score is a number (or -inf / +inf), and it keeps moving.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as scipy_stats
from toys import ball_class, toy_model

from sppl.infer import chain
from sppl.infer.chain import Sampler, accept
from sppl.model.trace import make_object


class DegenerateScorer:
    """A likelihood that breaks down on part of the space: NaN for a ball with x > 1, -inf
    for one with -1 < x < -0.5, +inf for one with x < -4, and 0 elsewhere."""

    terms: list = []
    cameras: dict = {}

    def evaluate(self, objects, parent=None, noise=None):
        return {(0, "x"): np.array([o.values["x"] for o in objects])}, {}

    def log_likelihood(self, stats, noise) -> float:
        xs = stats[(0, "x")]
        if (xs > 1).any():
            return math.nan
        if (xs < -4).any():
            return math.inf
        if ((xs > -1) & (xs < -0.5)).any():
            return -math.inf
        return 0.0


def test_no_nan_reaches_the_accept_decision_and_the_chain_keeps_moving(monkeypatch):
    model = toy_model([ball_class(rate=3.0)])
    sampler = Sampler(model, DegenerateScorer(), np.random.default_rng(0))
    seen = []

    def spy(log_alpha, rng):
        seen.append(log_alpha)
        return accept(log_alpha, rng)

    monkeypatch.setattr(chain, "accept", spy)
    # Start in a state of zero likelihood: a ball at x = -0.7.
    start = make_object(model, model.classes[0], {"x": -0.7, "y": 0.0, "r": 0.3, "c": "red"})
    trace = sampler.initial_trace((start,))
    assert trace.score == -math.inf
    scores = []
    for _ in range(3000):
        trace = sampler.sweep(trace)
        scores.append(trace.score)
    assert seen and not any(math.isnan(a) for a in seen)
    assert not any(math.isnan(s) for s in scores)
    nan = sum(sampler.stats.nan.values())
    proposed = sum(n for n, _ in sampler.stats.counts.values())
    accepted = sum(a for _, a in sampler.stats.counts.values())
    assert nan > 0, "the test never drove the sampler into a NaN state"
    assert 0 < accepted < proposed
    assert any(math.isfinite(s) for s in scores), "the chain never left the zero-density start"
    assert any(s == math.inf for s in scores), "the test never reached an infinite density"
    # The counts reach the summary.
    assert any("nan" in c for c in sampler.stats.as_dict().values())


def test_accept_at_the_edges_of_the_range_of_a_double():
    class Zero:
        def random(self):
            return 0.0  # numpy's random() can return exactly 0: log(0) must not be taken

    assert accept(-1.0, Zero()) and not accept(-math.inf, Zero())
    rng = np.random.default_rng(1)
    assert accept(math.inf, rng) and accept(0.0, rng) and accept(1e308, rng)
    assert not any(accept(-800.0, rng) for _ in range(1000))  # exp(-800) underflows to 0
    assert not accept(-math.inf, rng)


@pytest.mark.false_alarm(3e-6)
def test_accept_has_probability_exp_log_alpha():
    """Binomial test, seeded; false-alarm rate 1e-6 for each of the three ratios, 3e-6 in all."""
    rng = np.random.default_rng(2)
    n = 20000
    for p in (0.9, 0.3, 1e-3):
        k = sum(accept(math.log(p), rng) for _ in range(n))
        assert scipy_stats.binomtest(k, n, p).pvalue > 1e-6, (p, k)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_proposal_density_that_breaks_down_is_rejected_or_decided_without_nan(bad, monkeypatch):
    """A proposal whose own ratio is NaN or infinite: decided in log space, NaN rejected."""
    from sppl.infer import moves
    from sppl.scoring.scorer import PriorScorer

    model = toy_model([ball_class()])
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(3))
    real = moves.propose_birth

    def broken_birth(*args, **kwargs):
        p = real(*args, **kwargs)
        return None if p is None else moves.Proposal(p.move, p.label, p.objects, p.noise,
                                                     p.changed, bad, p.ratio_fn)

    monkeypatch.setattr(moves, "propose_birth", broken_birth)
    seen = []
    monkeypatch.setattr(chain, "accept", lambda a, rng: seen.append(a) or accept(a, rng))
    trace = sampler.initial_trace()
    for _ in range(300):
        trace = sampler.sweep(trace)
        assert not math.isnan(trace.score)
    assert not any(math.isnan(a) for a in seen)
    births = sampler.stats.counts[("birth", "ball")]
    if math.isnan(bad):
        assert sampler.stats.nan[("birth", "ball")] == births[0] > 0 and births[1] == 0
    elif bad == -math.inf:
        assert births[0] > 0 and births[1] == 0
    else:
        assert births[0] > 0 and births[1] > 0
