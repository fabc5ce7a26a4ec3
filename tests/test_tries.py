"""Multiple-try births, deaths and replaces (sppl/infer/tries.py): exact for the set-valued
posterior, checked the way every jump is (prior recovery, Geweke, each move and its reverse),
and the checks fail when the multiple-try ratio is wrong."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from false_alarms import EACH
from test_verify import seen_world
from toys import ball_class, block_class, toy_model

from sppl import verify
from sppl.infer import tries
from sppl.infer.chain import Sampler
from sppl.model.simulate import sample_objects
from sppl.scoring.scorer import PriorScorer


def with_tries(model, m):
    return dataclasses.replace(model, inference=dataclasses.replace(model.inference, tries=m))


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_with_multiple_tries(false_alarm):
    """Counts (chi-square against Poisson) and every marginal (KS, chi-square); false alarm at
    the marker's rate
    (Holm)."""
    model = with_tries(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]), 4)
    report = verify.prior_recovery(model, sweeps=6000, seed=3, alpha=false_alarm)
    assert report.passed, report.table()
    accepted = {r.quantity for r in report.rows if r.quantity.endswith("moves accepted")}
    assert {"birth moves accepted", "death moves accepted", "replace moves accepted"} <= accepted


def test_prior_recovery_sees_a_multiple_try_birth_without_its_mean(monkeypatch):
    """The birth weighed by the sum of the candidates' weights instead of their mean (the 1/M
    left out): births are accepted M times too often, and the count test fails."""
    real = tries._log_mean
    monkeypatch.setattr(tries, "_log_mean",
                        lambda log_w: real(log_w) + np.log(len(log_w)))
    model = with_tries(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]), 4)
    report = verify.prior_recovery(model, sweeps=6000, seed=3, alpha=EACH)
    assert not report.passed, report.table()
    assert any(r.quantity.startswith("count") for r in report.failures)


def test_every_multiple_try_jump_and_its_reverse(require_gl):
    """Each jump undone with the same candidates gives back the trace, with minus the log
    ratio (against observations, so that data-driven candidates are among them)."""
    report = verify.move_checks(with_tries(seen_world(), 3), states=12, seed=5)
    assert report.passed, report.table()
    checked = {r.quantity for r in report.rows}
    assert {"birth: reverse undoes it", "death: reverse undoes it",
            "replace: reverse undoes it"} <= checked, checked


@pytest.mark.false_alarm(EACH)
def test_geweke_with_multiple_tries(false_alarm, require_gl):
    """Successive-conditional chains with 3 tries per jump stay at the prior (false alarm at
    the marker's rate,
    Holm)."""
    report = verify.geweke(with_tries(seen_world(), 3), chains=100, length=12, seed=7, size=8,
                           mc_draws=4000, alpha=false_alarm)
    assert report.passed, report.table()


def test_one_try_is_the_single_try_jump():
    """With tries = 1 the sampler takes the single-try code path: same draws, same chain."""
    model = toy_model([ball_class(rate=2.0), block_class(rate=0.7)])
    chains = []
    for m in (1,):
        sampler = Sampler(with_tries(model, m), PriorScorer(), np.random.default_rng(3))
        trace = sampler.initial_trace(sample_objects(model, np.random.default_rng(4)))
        for _ in range(200):
            trace = sampler.sweep(trace)
        chains.append(trace)
    plain = Sampler(model, PriorScorer(), np.random.default_rng(3))
    trace = plain.initial_trace(sample_objects(model, np.random.default_rng(4)))
    for _ in range(200):
        trace = plain.sweep(trace)
    assert [dict(o.values) for o in trace.objects] == [dict(o.values) for o in chains[0].objects]


@pytest.mark.parametrize("bad", ["tries = 0", "tries = 2.5"])
def test_bad_tries_are_errors(bad):
    from sppl.errors import ModelError
    from sppl.lang import compile_model

    with pytest.raises(ModelError, match="`tries` is a number of candidates"):
        compile_model("class ball { count ~ poisson(1) x : real ~ normal(0, 1)\n"
                      "geometry sphere(0.2) at (x, 0) colour rgb(1, 0, 0) }\n"
                      f"inference {{ {bad} }}")
