"""The pair refit jump (sppl/infer/pair_refit.py): two neighbouring objects taken out and fitted
again one after the other. Exact through deterministic fits: checked by prior recovery, Geweke
and the move checks, and the checks fail when its reverse density is left out."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from false_alarms import EACH
from test_merge import noisy_world
from test_refit import _example, _observed
from test_verify import seen_world
from toys import ball_class, block_class, toy_model

from sppl import verify
from sppl.infer import fit, pair_refit


def with_pair_refit(model, weight=4.0):
    weights = {**model.inference.jump_weights, "pair_refit": weight}
    return dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, jump_weights=weights))


def _toy():
    return with_pair_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]), 8.0)


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_with_pair_refits(false_alarm):
    """Without observations the fits climb the prior; the chain must still reproduce it
    (counts chi-square, marginals KS; false alarm at the marker's rate, Holm)."""
    report = verify.prior_recovery(_toy(), sweeps=40000, seed=3, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("pair_refit moves accepted").ok


def _symmetric(monkeypatch):
    """Pair refits whose ratio takes the proposal for symmetric (the reverse densities set
    to the forward ones)."""
    real = pair_refit.propose_pair_refit

    def symmetric(*args, **kwargs):
        p = real(*args, **kwargs)
        if p is None:
            return None
        return dataclasses.replace(p, log_q_ratio=0.0 if math.isfinite(p.log_q_ratio)
                                   else p.log_q_ratio, deferred=None)

    monkeypatch.setattr(pair_refit, "propose_pair_refit", symmetric)


@pytest.mark.slow
def test_prior_recovery_sees_a_pair_refit_taken_for_symmetric(monkeypatch):
    """The chain drifts towards the fitted values, the prior's modes: the same run fails
    (ball.r p 9e-16, block.s 3e-18 on this seed)."""
    _symmetric(monkeypatch)
    report = verify.prior_recovery(_toy(), sweeps=40000, seed=3, alpha=EACH)
    assert not report.passed, report.table()


def test_the_move_checks_see_a_pair_refit_without_its_reverse_density(require_gl,
                                                                       monkeypatch):
    """With the two reverse fits' densities left out, a pair refit and its reverse no longer
    have opposite ratios."""
    real = pair_refit.propose_pair_refit

    def without_back(*args, **kwargs):
        p = real(*args, **kwargs)
        return None if p is None else dataclasses.replace(p, deferred=None)

    monkeypatch.setattr(pair_refit, "propose_pair_refit", without_back)
    report = verify.move_checks(with_pair_refit(seen_world()), states=12, seed=5)
    assert not report.row("pair_refit: reverse undoes it").ok, report.table()


def test_the_partner_is_weighed_in_both_states(monkeypatch):
    """The ratio carries the partner's probability in the proposed state over that in the
    state left: with the weights made uniform, the ratio changes by exactly their log
    difference, and the reverse proposes the objects it started from."""
    from test_proposal_checks import flat_world

    from sppl.infer.chain import Sampler
    from sppl.model.trace import make_object
    from sppl.scoring.scorer import PriorScorer

    model = flat_world("tile", (0.3, 0.3), 1.5, 0.6, ("pair_refit",), 3)
    tile = model.classes[0]
    objects = tuple(make_object(model, tile, {"x": x, "y": y})
                    for x, y in ((0.9, 0.2), (-0.6, 0.5), (0.1, -0.9)))
    noise = {"image": {"sigma": 0.6}}
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    trace = sampler.make_trace(objects, noise)

    def proposal():
        return pair_refit.propose_pair_refit(sampler, trace, np.random.default_rng(4), first=0,
                                             second=2)

    right = proposal()
    after = sampler.make_trace(right.objects, noise)
    weighed = (pair_refit.partner_log_weights(sampler, right.objects, 0)[2]
               - pair_refit.partner_log_weights(sampler, objects, 0)[2])
    assert abs(weighed) > 1e-3  # the objects moved, and with them the weights
    monkeypatch.setattr(pair_refit, "partner_log_weights",
                        lambda sampler, objects, i: np.full(len(objects), -math.log(2)))
    left = proposal()
    assert [o.values for o in left.objects] == [o.values for o in right.objects]
    assert math.isclose(right.log_q_ratio - left.log_q_ratio, weighed, abs_tol=1e-9)
    back = right.tries.reverse(sampler, trace, right, after)
    assert back.objects == objects


def test_every_pair_refit_and_its_reverse(require_gl):
    """Against observations: the reverse, through the same scene without the two objects,
    gives back the trace with minus the log ratio."""
    report = verify.move_checks(with_pair_refit(seen_world()), states=12, seed=5)
    assert report.passed, report.table()
    assert "pair_refit: reverse undoes it" in {r.quantity for r in report.rows}


@pytest.mark.slow
@pytest.mark.false_alarm(EACH)
def test_geweke_with_pair_refits(false_alarm, require_gl):
    """With noise ten times the verify world's on 16x16 images (as for merges), where a pair
    refit is accepted now and then (on the verify world's 8x8 images, none of 198 was).
    False alarm at the marker's rate (Holm)."""
    report = verify.geweke(with_pair_refit(noisy_world()), chains=100, length=12, seed=7,
                           size=16, mc_draws=4000, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("pair_refit moves accepted").ok


# tabletop.scn's prior scene 18 (benchmarks/prior_scenes.py) as a chain held it (seed 10): the
# kraft box grown over the tall yellow box behind it, and the yellow box a small one beside.
_TRUE_BOXES = [
    {"class": "box", "params": {"x": -0.0356, "y": 0.2247, "a": 0.6100, "w": 0.0883,
                                "d": 0.2742, "h": 0.1495, "c": "yellow"}},
    {"class": "box", "params": {"x": -0.1883, "y": 0.0579, "a": -0.8587, "w": 0.1649,
                                "d": 0.1733, "h": 0.1213, "c": "kraft"}}]
_HELD_BOXES = [
    {"class": "box", "params": {"x": -0.0781, "y": 0.2879, "a": -0.3377, "w": 0.0976,
                                "d": 0.0737, "h": 0.1572, "c": "yellow"}},
    {"class": "box", "params": {"x": -0.1432, "y": 0.0960, "a": 0.7070, "w": 0.2874,
                                "d": 0.1646, "h": 0.1221, "c": "kraft"}}]
_OTHERS = [
    {"class": "mug", "params": {"x": -0.0213, "y": -0.2110, "a": 0.8899, "k": 0.7501,
                                "c": "blue"}},
    {"class": "box", "params": {"x": -0.2338, "y": -0.2152, "a": 1.0430, "w": 0.1360,
                                "d": 0.1053, "h": 0.0823, "c": "yellow"}},
    {"class": "mug", "params": {"x": 0.0564, "y": -0.0319, "a": -1.6812, "k": 0.6884,
                                "c": "blue"}}]


def _boxes_held_as_one(root, seed):
    """The held state's log joint, its single refits' best, and the pair's fits' (the yellow
    box first, then the kraft box), at the noise drawn with ``seed``."""
    from sppl.model.simulate import objects_from_dict
    from sppl.model.trace import make_object

    model, cameras, renderer = _example(root, "tabletop")
    noise = {"image": {"sigma": 0.05}, "depth": {"sigma": 0.01}}
    scene = {"objects": _TRUE_BOXES + _OTHERS, "noise": noise}
    _, sampler = _observed(root, model, cameras, renderer, scene, np.random.default_rng(seed))
    others = objects_from_dict(model, {"objects": _OTHERS})
    yellow, kraft = objects_from_dict(model, {"objects": _HELD_BOXES})
    held = sampler.make_trace(others + (yellow, kraft), noise).score
    singles = max(fit.scored_fit(sampler, sampler.make_trace(others + (keep,), noise), o.cls,
                                 o)[1] for o, keep in ((yellow, kraft), (kraft, yellow)))
    without = sampler.make_trace(others, noise)
    refitted = make_object(model, yellow.cls, fit.fit(sampler, without, yellow.cls, yellow))
    _, pair = fit.scored_fit(sampler, sampler.make_trace(others + (refitted,), noise),
                             kraft.cls, kraft)
    renderer.release()
    return held, singles, pair


def test_two_boxes_held_as_one_are_fitted_apart_as_a_pair(require_gl, root):
    """Fitted one after the other with both taken out, the two boxes come back apart: at each
    of three noise draws the pair's fits stand over 1,000 nats above the held state (they
    gained 3,111, 3,418 and 1,579), and over 500 above the better refit of either box alone,
    the other standing (373, 474 and 560: the yellow box cannot grow into the kraft box, and
    the kraft box, shrunk, uncovers yellow pixels that nothing explains)."""
    for seed in range(3):
        held, singles, pair = _boxes_held_as_one(root, seed)
        assert pair > held + 1000.0, (seed, pair - held)
        assert pair > singles + 500.0, (seed, pair - singles)
