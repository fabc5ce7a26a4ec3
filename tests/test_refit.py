"""The refit jump (sppl/fit.py): an object replaced by one of any class fitted to the scene
without it. Exact through a deterministic fit: checked by prior recovery, Geweke and the move
checks, and the checks fail when the reverse density is left out."""

from __future__ import annotations

import dataclasses

import pytest
from test_verify import seen_world
from toys import ball_class, block_class, toy_model

from sppl import fit, verify


def with_refit(model, weight=4.0):
    weights = {**model.inference.jump_weights, "refit": weight}
    return dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, jump_weights=weights))


def test_prior_recovery_with_refits():
    """Without observations the fit climbs the prior; the chain must still reproduce it
    (counts chi-square, marginals KS; false alarm 1%, Holm)."""
    model = with_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]))
    report = verify.prior_recovery(model, sweeps=15000, seed=3)
    assert report.passed, report.table()
    assert report.row("refit moves accepted").ok


def test_prior_recovery_sees_a_refit_taken_for_symmetric(monkeypatch):
    """A refit whose ratio takes the proposal for symmetric (the reverse density set to the
    forward one): the chain drifts towards the fitted values, and the check fails."""
    real = fit.log_mixture
    last = {}

    def symmetric(sampler, state, cls, values, fitted):
        if "forward" in last:  # the second call of a proposal: the reverse density
            return last.pop("forward")
        last["forward"] = real(sampler, state, cls, values, fitted)
        return last["forward"]

    monkeypatch.setattr(fit, "log_mixture", symmetric)
    model = with_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]))
    report = verify.prior_recovery(model, sweeps=15000, seed=3)
    assert not report.passed, report.table()


def test_every_refit_and_its_reverse(require_gl):
    """Against observations: the reverse, through the same scene without the object, gives
    back the trace with minus the log ratio."""
    report = verify.move_checks(with_refit(seen_world()), states=12, seed=5)
    assert report.passed, report.table()
    assert "refit: reverse undoes it" in {r.quantity for r in report.rows}


def test_geweke_with_refits(require_gl):
    """False alarm 1% (Holm)."""
    report = verify.geweke(with_refit(seen_world()), chains=100, length=12, seed=7, size=8,
                           mc_draws=4000)
    assert report.passed, report.table()
    assert report.row("refit moves accepted").ok


def test_the_fit_is_deterministic_and_improves_the_scene(require_gl):
    """Fitted twice from the same scene it gives the same values, and they score at least as
    well as where it started."""
    import numpy as np

    from sppl.chain import Sampler
    from sppl.simulate import sample_noise, sample_objects

    model = seen_world()
    sim = verify._Simulator(model, verify.verify_cameras(model, 8), _renderer(model))
    rng = np.random.default_rng(2)
    objects = ()
    while len(objects) < 2:
        objects = sample_objects(model, rng)
    noise = sample_noise(model, rng)
    sampler = sim.sampler(sim.observe(sim.render(objects), noise, rng), rng, Sampler)
    state = sampler.make_trace(objects[1:], noise)
    for cls in model.classes:
        a = fit.fit(sampler, state, cls, objects[0])
        b = fit.fit(sampler, state, cls, objects[0])
        assert a == b
        start = fit._start(cls, objects[0])
        assert fit._score(sampler, state, cls, a) >= fit._score(sampler, state, cls, start)


def _renderer(model):
    from sppl.render import Renderer

    return Renderer(model.render)


@pytest.mark.parametrize("weights", ["refit = 1"])
def test_a_model_weighs_refits(weights):
    from sppl.lang import compile_model

    model = compile_model("class ball { count ~ poisson(1) x : real ~ normal(0, 1)\n"
                          "geometry sphere(0.2) at (x, 0) colour rgb(1, 0, 0) }\n"
                          f"inference {{ jump_weights birth = 1, death = 1, {weights} }}")
    assert model.inference.jump_weights["refit"] == 1.0
