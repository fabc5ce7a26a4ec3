"""Changes of class that carry a parameter scaled (``change cube.s <-> 2 * ball.r``): the
carried value is multiplied by the factor, and the acceptance ratio counts the stretch of
parameter space that makes (the Jacobian). Prior recovery decides whether both are right."""

from __future__ import annotations

import pytest
from false_alarms import EACH

from sppl import verify
from sppl.errors import ModelError
from sppl.infer import moves
from sppl.lang import compile_model

SOURCE = """
class cube {
    count ~ poisson(1)
    x : real ~ normal(0, 1)
    s : positive ~ gamma(2, 1/3)
    geometry box(s, s, s) at (x, 0) colour rgb(1, 0, 0)
}
class ball {
    count ~ poisson(0.7)
    x : real ~ normal(0, 1)
    r : positive ~ gamma(3, 0.1)
    geometry sphere(r) at (x, 0) colour rgb(0, 0, 1)
}
change cube.s <-> 2 * ball.r
inference { jump_weights birth = 1, death = 1, change = 4, replace = 0 }
"""


def test_a_scaled_pairing_carries_the_value_times_its_factor_and_back():
    model = compile_model(SOURCE)
    cube, ball = model.classes
    assert moves.carried_parameters(ball, cube) == {"x": "x", "s": "r"}
    assert moves.carried_scales(ball, cube) == {"x": 1.0, "s": 2.0}
    assert moves.carried_scales(cube, ball) == {"x": 1.0, "r": 0.5}
    assert moves.log_jacobian_change(ball, cube) == pytest.approx(-moves.log_jacobian_change(
        cube, ball))
    assert all(r.ok for r in verify.change_declarations(model))


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_through_scaled_changes(false_alarm):
    """Counts (chi-square) and the sizes' marginals (KS) with most jumps changes; false alarm
    at the marker's rate (Holm)."""
    report = verify.prior_recovery(compile_model(SOURCE), sweeps=30_000, seed=3, alpha=false_alarm)
    assert report.passed, report.table()


def test_prior_recovery_sees_a_change_without_its_jacobian(monkeypatch):
    """The same run with the factor's Jacobian left out of the ratio: the chain favours the
    class whose parameter space the change shrinks, and the check fails."""
    monkeypatch.setattr(moves, "log_jacobian_change", lambda old, new: 0.0)
    report = verify.prior_recovery(compile_model(SOURCE), sweeps=30_000, seed=3, alpha=EACH)
    assert not report.passed, report.table()


@pytest.mark.parametrize("change, message", [
    ("change cube.x <-> 2 * ball.x", None),
    ("change cube.s <-> 0 * ball.r", "a change's factor must be positive"),
])
def test_factors_are_checked(change, message):
    source = SOURCE.replace("change cube.s <-> 2 * ball.r", change)
    if message is None:
        compile_model(source)  # two real parameters scale into each other
        return
    with pytest.raises(ModelError, match=message):
        compile_model(source)


def test_a_factor_between_bounded_parameters_is_an_error():
    source = SOURCE.replace("x : real ~ normal(0, 1)\n    s", "x : interval(-3, 3) ~ uniform(-3, 3)\n    s")
    source = source.replace("x : real ~ normal(0, 1)\n    r", "x : interval(-3, 3) ~ uniform(-3, 3)\n    r")
    with pytest.raises(ModelError, match="cannot be paired with a factor"):
        compile_model(source.replace("change cube.s <-> 2 * ball.r", "change cube.x <-> 2 * ball.x"))
