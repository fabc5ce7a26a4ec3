"""The merge's focused choice of the object it takes away (sppl/infer/redundant.py): drawn as
its probability says, weighed the same way in a merge and in a split's reverse, and aimed at
the sliver a chain keeps beside an object it read too small."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from false_alarms import EACH, SLOW_EACH
from scipy import stats
from test_fitted_birth import _observed_sampler
from test_merge import noisy_world, prior_model, with_merges
from test_verify import seen_world

from sppl import verify
from sppl.infer import merge, redundant
from sppl.infer.chain import Sampler
from sppl.model.trace import make_object
from sppl.scoring.scorer import PriorScorer


def focused(model, focus=0.5):
    return dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, merge_focus=focus))


def test_without_a_focus_the_choice_is_uniform_and_draws_as_before():
    """merge_focus = 0 (every shipped model): q(k) = 1 / n, and the draw is the one integer
    the merge always drew, so that such a model's chains are what they were."""
    model = prior_model()
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    cls = model.classes[0]
    trace = sampler.make_trace(tuple(
        make_object(model, cls, {"x": x, "y": 0.0, "r": r, "c": "red"})
        for x, r in ((0.0, 0.2), (1.0, 0.9), (2.0, 0.05))), {})
    assert np.allclose(redundant.log_probs(sampler, trace), -math.log(3))
    assert "death_costs" not in trace.cache
    a, b = np.random.default_rng(4), np.random.default_rng(4)
    assert [redundant.choose(sampler, trace, a) for _ in range(20)] == [
        int(b.integers(3)) for _ in range(20)]


# Under the prior a death costs a few nats, where against images it costs hundreds: the checks
# without images weigh deaths at a nat apiece so that the focused choice is far from uniform
# there too. The choice is valid at any scale.
def strongly(monkeypatch):
    monkeypatch.setattr(redundant, "NATS", 1.0)


@pytest.mark.false_alarm(EACH)
def test_the_first_object_is_drawn_as_its_probability(false_alarm, monkeypatch):
    """Draws of ``choose`` against ``log_probs`` by chi-square (false alarm at the marker's
    rate), on a prior state whose deaths cost different amounts; the same draws are far from
    uniform, so a choice that ignored the focus would fail."""
    strongly(monkeypatch)
    model = focused(prior_model())
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    cls = model.classes[0]
    trace = sampler.make_trace(tuple(
        make_object(model, cls, {"x": x, "y": 0.0, "r": r, "c": "red"})
        for x, r in ((0.0, 0.2), (3.0, 0.3), (-3.0, 0.25), (0.5, 0.2))), {})
    p = np.exp(redundant.log_probs(sampler, trace))
    assert math.isclose(p.sum(), 1.0)
    assert p.max() > 1.2 / len(p) and p.min() >= 0.5 / len(p) - 1e-12
    rng = np.random.default_rng(11)
    draws = np.bincount([redundant.choose(sampler, trace, rng) for _ in range(4000)],
                        minlength=len(p))
    assert stats.chisquare(draws, 4000 * p).pvalue > false_alarm
    assert stats.chisquare(draws).pvalue < false_alarm


@pytest.mark.false_alarm(EACH)
def test_every_merge_and_split_and_its_reverse_with_a_focused_choice(require_gl, monkeypatch):
    """With the first object chosen by its death's cost, a merge and the split that undoes it
    still give back the trace with minus the log ratio: the split's reverse scores the
    choice in the state it proposes, as the merge scores it in its own."""
    strongly(monkeypatch)
    report = verify.move_checks(focused(with_merges(seen_world())), states=12, seed=5)
    assert report.passed, report.table()
    assert {"merge: reverse undoes it", "split: reverse undoes it"} <= {
        r.quantity for r in report.rows}


def test_a_split_that_takes_the_choice_for_uniform_is_caught(require_gl, monkeypatch):
    """The break the check above guards against: the split's reverse density with the
    merge's choice of its first object taken as 1 / n while the merge draws it by the cost of
    its death. Some merge or split is then no longer undone with minus its log ratio."""
    strongly(monkeypatch)

    def uniform(sampler, objects, noise, i, back, bound):
        return (lambda: back() - math.log(len(objects))), bound

    monkeypatch.setattr(merge, "_chosen_first", uniform)
    report = verify.move_checks(focused(with_merges(seen_world())), states=12, seed=5)
    failed = {r.quantity for r in report.rows if not r.ok}
    assert failed & {"merge: reverse undoes it", "split: reverse undoes it"}, report.table()


# shapes.scn's prior scene 17 (benchmarks/prior_scenes.py), its red cone alone: at chain seed
# 5 the chain ended with this cone 4 cm short and a thin red cone a metre behind it that
# painted its tip, 267 nats to lose where every other object of the state cost thousands.
CONE = {"x": -1.4298, "y": 0.0494, "r": 0.2444, "h": 1.2131, "c": "red"}
SHORT = {**CONE, "h": 1.1732}
BEHIND = {"x": -2.3393, "y": 0.5949, "r": 0.1952, "h": 0.9909, "c": "red"}
SPHERE = {"x": -0.1330, "y": 0.6997, "r": 0.4915, "c": "blue"}


def test_the_sliver_behind_a_short_cone_is_the_merge_choice(root, require_gl, tmp_path):
    """In that state the thin cone's death costs least by far, so a focused merge takes it
    away with probability near 1/2 + 1/6 where the uniform choice gave 1/3; merged into the
    short cone, the fit stands the cone up to its height and the merge is accepted."""
    _, _, noise, sampler = _observed_sampler(root, tmp_path, "shapes", [
        {"class": "cone", "params": CONE}, {"class": "sphere", "params": SPHERE}], seed=17)
    sampler.model = focused(sampler.model)
    cone, sphere = (sampler.model.object_class(n) for n in ("cone", "sphere"))
    state = sampler.make_trace((make_object(sampler.model, cone, SHORT),
                                make_object(sampler.model, sphere, SPHERE),
                                make_object(sampler.model, cone, BEHIND)), noise)
    costs = redundant.death_costs(sampler, state)
    assert costs[2] > -1000 and max(costs[:2]) < 5 * costs[2]
    q = np.exp(redundant.log_probs(sampler, state))
    assert q[2] > 0.6
    # The merge's fit, and the merge that proposes exactly it (its draws spread around it).
    without = sampler.make_trace(state.objects[1:2], noise)
    fits, log_p = merge.merged_fits(sampler, without, state.objects[0], [state.objects[2]])
    c = int(np.argmax(log_p))
    assert sampler.model.classes[c] is cone and abs(fits[c]["h"] - CONE["h"]) < 0.03
    target = make_object(sampler.model, cone, fits[c])
    proposal = merge.propose_merge(sampler, state, np.random.default_rng(2), i=2, j=0,
                                   more=(), target=target)
    new = sampler.evaluate(state, proposal)
    assert sampler.log_alpha(state, proposal, new) > 0


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH)
def test_prior_recovery_with_focused_merges(false_alarm, monkeypatch):
    """Without observations a death's cost is its prior's; the chain with focused merges must
    still reproduce the prior (counts chi-square, marginals KS; Holm at the marker's rate)."""
    strongly(monkeypatch)
    report = verify.prior_recovery(focused(prior_model()), sweeps=15000, seed=3,
                                   alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("merge moves accepted").ok
    assert report.row("split moves accepted").ok


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH)
def test_geweke_with_focused_merges(false_alarm, require_gl, monkeypatch):
    """Against observations, where a death's cost is mostly its pixels' (Holm at the
    marker's rate)."""
    strongly(monkeypatch)
    report = verify.geweke(focused(with_merges(noisy_world(), weight=2.0)), chains=100,
                           length=20, seed=7, size=8, mc_draws=4000, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("merge moves accepted").ok
    assert report.row("split moves accepted").ok
