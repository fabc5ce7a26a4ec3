"""The checks of the proposals that look at the observations (``sppl.verify.proposals``):
they pass on the code, and fail on copies of it broken on purpose, each with the sampler left
as it is and only the density the ratio uses made wrong:

  (i)   the density replaced by the prior;
  (ii)  the density's spread halved (a birth's kernel, a refit's spreads, a merge partner's
        radius and pixel scale);
  (iii) the thesis's literal birth ratio (ordered tuple: one more 1 / (N_c + 1) on a birth)
        is no density error, so the sampler-against-density checks cannot see it; it differs
        from the right ratio only with two objects of a class, and the chain against the
        exact posterior of a model of up to two strips (``joint_check``, slow) rejects it.

What each break is caught by: the birth's and the refit's density as the prior, or with half
its spread, by the importance identity (p < 1e-9); a merge partner's density made uniform by
the chi-square of the partners, and its scales halved by the identity; the refit's density
as the prior also by the joint check on one tile; the refit's choice of object made uniform,
or its focus halved, by the chi-square of the objects chosen; the thesis ratio by the joint check on two
strips. The joint check does not catch a wrong birth density in either setting (births aim
at pixels that noise leaves, or are seldom accepted).

False alarms. Each test runs at a fixed seed, so it is deterministic. A passing test's
``Report`` decides its rows together by Holm's correction at ALPHA = 1e-3 (the chance over
seeds that a right sampler fails it), small enough for the default suite's family-wise budget
of 1% to absorb every such test. A test that expects a failure asserts a p-value far below
that (below 1e-6), so it has no false alarm to speak of; it fails only if the check lost its
power.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from toys import COLOURS

from sppl import verify
from sppl.infer import fit as fitting
from sppl.infer import merge, misfit, redundant
from sppl.infer.birth import BirthProposal
from sppl.infer.chain import Sampler
from sppl.model.distributions import Categorical, Gamma, Normal, Uniform
from sppl.model.domains import Finite, Interval, Positive, Real
from sppl.model.geometry import Part, scaling, translation
from sppl.model.trace import make_object
from sppl.model.types import InferenceSettings, Model, ObjectClass, Parameter, Sensor
from sppl.verify import Report
from sppl.verify import proposals as pc

# The false-alarm rate of each passing test (Holm over its rows): 1e-3.
ALPHA = 1e-3
# What a test that expects the check to fail requires of the smallest p-value.
POWER = 1e-6


def _ball(v):
    r = v["r"]
    colour = (0.9, 0.2, 0.2) if v["c"] == "red" else (0.2, 0.3, 0.9)
    return (Part("sphere", translation(v["x"], v["y"], 0) @ scaling(r, r, r), colour),)


def seen_balls() -> Model:
    """Balls near the origin, big enough to leave unexplained pixels on 16x16 cameras, with
    every data-driven jump switched on."""
    ball = ObjectClass(
        "ball", 1.5,
        (Parameter("x", Real(), Normal(0.0, 0.6), 0.3), Parameter("y", Real(), Normal(0.0, 0.6), 0.3),
         Parameter("r", Positive(), Gamma(4.0, 0.08), 0.08),
         Parameter("c", Finite(COLOURS), Categorical(COLOURS, (0.4, 0.6)))),
        _ball, position=("x", "y"),
    )
    sensors = {
        "image": Sensor("image", "gaussian", (Parameter("sigma", Positive(), Gamma(2.0, 0.05), 0.02),)),
        "depth": Sensor("depth", "gaussian", (Parameter("sigma", Positive(), Gamma(2.0, 0.1), 0.04),)),
    }
    weights = {"birth": 1.0, "death": 1.0, "replace": 1.0, "refit": 1.0, "merge": 1.0,
               "split": 1.0}
    return Model((ball,), sensors, InferenceSettings(p_jump=1.0, jump_weights=weights,
                                                     refit_focus=0.75))


@pytest.fixture(scope="module")
def setting(require_gl):
    from sppl.render import Renderer

    model = seen_balls()
    found = pc.observed_state(model, Renderer(model.render), size=16, seed=3)
    assert found is not None
    return found


@pytest.fixture(scope="module")
def wide(require_gl):
    """The same on 48x48 cameras, where objects stand pixels apart, so that a merge's
    partners are not all equally likely."""
    from sppl.render import Renderer

    model = seen_balls()
    found = pc.observed_state(model, Renderer(model.render), size=48, seed=3)
    assert found is not None
    return found


def _smallest_p(report: Report) -> float:
    return min(r.p_value for r in report.rows if r.p_value is not None)


def birth_report(setting, seed=0, draws=30, weights=3000) -> Report:
    sampler, state, _ = setting
    rng = np.random.default_rng(seed)
    return Report(pc.birth_rows(sampler, state, sampler.model.classes[0], rng, draws, weights),
                  ALPHA)


def refit_report(setting, seed=0, draws=25, weights=3000) -> Report:
    sampler, state, missing = setting
    rng = np.random.default_rng(seed)
    return Report(pc.refit_rows(sampler, state, sampler.model.classes[0], missing, rng, draws,
                                weights), ALPHA)


def partner_report(setting, seed=0, draws=2000) -> Report:
    # The state is the one the pilot finds at this seed; its partners tell a wrong density
    # only with enough draws: 600 sufficed until a merge could take up to eight objects,
    # which draws its random numbers in another order and so finds another state. Since the
    # partners' colour counts, the best of 15 prior states left partners too near uniform to
    # tell a uniform density (p 0.16); the best of 30 tells it.
    sampler, state, _ = setting
    rng = np.random.default_rng(seed)
    crowded = pc.crowded_state(sampler, state.noise, rng, tries=30)
    assert crowded is not None
    return Report(pc.partner_rows(sampler, *crowded, rng, draws), ALPHA)


def refit_choice_report(setting, seed=0, draws=1000) -> Report:
    sampler, state, _ = setting
    rng = np.random.default_rng(seed)
    chosen = pc.misfit_state(sampler, state.noise, rng, tries=15)
    assert chosen is not None
    return Report(pc.refit_choice_rows(sampler, chosen, rng, draws), ALPHA)


def merge_first_report(setting, monkeypatch, seed=0, draws=1000) -> Report:
    """The merge's first object with ``merge_focus`` set, in the crowded state the partners'
    check uses, its deaths weighed at a nat apiece (redundant.NATS) so that 48x48 cameras'
    costs, tens of nats, make the choice far from uniform."""
    import dataclasses

    monkeypatch.setattr(redundant, "NATS", 1.0)
    sampler, state, _ = setting
    focused = dataclasses.replace(sampler.model, inference=dataclasses.replace(
        sampler.model.inference, merge_focus=0.75))
    sampler = Sampler(focused, sampler.scorer, np.random.default_rng(seed))
    crowded = pc.crowded_state(sampler, state.noise, np.random.default_rng(seed), tries=30)
    assert crowded is not None
    state = crowded[0]
    p = np.exp(redundant.log_probs(sampler, state))
    assert len(p) >= 2 and p.max() > 1.5 / len(p), p
    return Report(pc.merge_first_rows(sampler, state, np.random.default_rng(seed), draws),
                  ALPHA)


# -- the ways to break each density, sampling left as it is -----------------------------------


def birth_density_is_prior(monkeypatch):
    monkeypatch.setattr(BirthProposal, "log_density",
                        lambda self, cls, values, trace: cls.log_prior(values))


def birth_spread_halved(monkeypatch):
    right = BirthProposal.log_density

    def halved(self, cls, values, trace):
        spread = self.spread
        self.spread = spread / 2
        try:
            return right(self, cls, values, trace)
        finally:
            self.spread = spread

    monkeypatch.setattr(BirthProposal, "log_density", halved)


def refit_density_is_prior(monkeypatch):
    monkeypatch.setattr(fitting, "log_mixture",
                        lambda sampler, state, cls, values, fitted: cls.log_prior(values))


def refit_spreads_halved(monkeypatch):
    right = fitting.log_density

    def halved(cls, values, fitted):
        spreads = fitting.SPREADS
        fitting.SPREADS = tuple(c / 2 for c in spreads)
        try:
            return right(cls, values, fitted)
        finally:
            fitting.SPREADS = spreads

    monkeypatch.setattr(fitting, "log_density", halved)


def _partners_drawn_right(monkeypatch, wrong):
    """Merges choose their partner with the right probabilities, while their ratio (and a
    split's reverse) use ``wrong``."""
    right_weights, right_merge = merge.partner_log_weights, merge.propose_merge

    def propose_merge(sampler, trace, rng, i=None, j=None, state=None, target=None, more=None):
        n = len(trace.objects)
        if n >= 2 and j is None:
            i = int(rng.integers(n)) if i is None else i
            p = np.exp(right_weights(trace.objects, i, merge.screen_of(sampler)))
            j = int(rng.choice(n, p=p))
        return right_merge(sampler, trace, rng, i=i, j=j, state=state, target=target, more=more)

    monkeypatch.setattr(merge, "partner_log_weights", wrong)
    monkeypatch.setattr(merge, "propose_merge", propose_merge)


def partner_density_is_uniform(monkeypatch):
    def uniform(objects, i, screen=None):
        logw = np.full(len(objects), -math.log(len(objects) - 1))
        logw[i] = -math.inf
        return logw

    _partners_drawn_right(monkeypatch, uniform)


def partner_scales_halved(monkeypatch):
    right = merge.partner_log_weights

    def halved(objects, i, screen=None):
        radius, pixels = merge.RADIUS, merge.PIXELS
        merge.RADIUS, merge.PIXELS = radius / 2, pixels / 2
        try:
            return right(objects, i, screen)
        finally:
            merge.RADIUS, merge.PIXELS = radius, pixels

    _partners_drawn_right(monkeypatch, halved)


def _objects_chosen_right(monkeypatch, wrong):
    """Refits choose their object with the right probabilities, while their ratio (in both
    states) uses ``wrong``."""
    right = misfit.choice_log_probs

    def choose(sampler, trace, rng):
        p = np.exp(right(sampler, trace))
        return int(rng.choice(len(p), p=p / p.sum()))

    monkeypatch.setattr(misfit, "choice_log_probs", wrong)
    monkeypatch.setattr(misfit, "choose", choose)


def refit_choice_is_uniform(monkeypatch):
    _objects_chosen_right(monkeypatch,
                          lambda sampler, trace, focus=None: np.full(
                              len(trace.objects), -math.log(len(trace.objects))))


def refit_choice_focus_halved(monkeypatch):
    right = misfit.choice_log_probs

    def halved(sampler, trace, focus=None):
        return right(sampler, trace, sampler.model.inference.refit_focus / 2)

    _objects_chosen_right(monkeypatch, halved)


def merge_first_is_uniform(monkeypatch):
    """The merge draws its first object uniformly while its ratio weighs the focused choice."""
    monkeypatch.setattr(redundant, "choose",
                        lambda sampler, trace, rng: int(rng.integers(len(trace.objects))))


# -- the checks pass on the code ---------------------------------------------------------------


def test_the_state_leaves_pixels_unexplained(setting):
    sampler, state, _ = setting
    assert len(sampler.birth.points(state)) >= 2
    assert sampler.birth.weight > 0


def test_birth_sampler_matches_its_density(setting):
    """False alarm 1e-3 (Holm over the class's coordinates and the identity)."""
    report = birth_report(setting)
    assert report.passed, report.table()
    assert {"birth of ball: x given the rest", "birth of ball: c given the rest",
            "birth of ball: E[r/q] over a region"} <= {r.quantity for r in report.rows}


def test_refit_sampler_matches_its_density(setting):
    """False alarm 1e-3 (Holm). (At seed 0 the x row's p is 1e-4 on 25 draws: a chance
    low, as 300 draws at seeds 10 and 11 give p 0.90 and 0.16 on it.)"""
    report = refit_report(setting, seed=1)
    assert report.passed, report.table()


def test_merge_partners_match_their_probabilities(wide):
    """False alarm 1e-3 (Holm)."""
    report = partner_report(wide)
    assert report.passed, report.table()


def test_refit_objects_match_their_probabilities(wide):
    """False alarm 1e-3 (Holm); the state's choice is far from uniform."""
    report = refit_choice_report(wide)
    assert report.passed, report.table()
    sampler, state, _ = wide
    chosen = pc.misfit_state(sampler, state.noise, np.random.default_rng(0), tries=15)
    p = np.exp(misfit.choice_log_probs(sampler, chosen))
    assert p.max() > 1.5 / len(p), p


def test_merge_first_objects_match_their_probabilities(wide, monkeypatch):
    """False alarm 1e-3 (Holm); the state's choice is far from uniform."""
    report = merge_first_report(wide, monkeypatch)
    assert report.passed, report.table()


def test_the_refit_aims_at_the_object_the_pixels_disagree_with(wide):
    """The missing ball put back a metre off its place gains disagreeing pixels (beyond those
    the heavy noise of these cameras leaves everywhere) and the refit's chance; the same
    state with the model's focus at 0 chooses uniformly, with the generator's draws of before
    (one integer) and no term in the ratio."""
    import dataclasses

    sampler, state, missing = wide
    right = sampler.make_trace(state.objects + (missing,), state.noise)
    moved = dataclasses.replace(missing, values={**missing.values,
                                                 "x": missing.values["x"] + 1.0})
    moved = make_object(sampler.model, missing.cls, moved.values)
    wrong = sampler.make_trace(state.objects + (moved,), state.noise)
    m_right, m_wrong = misfit.misfits(sampler, right), misfit.misfits(sampler, wrong)
    assert m_wrong[-1] > m_right[-1] + 50, (m_right, m_wrong)
    p_right = np.exp(misfit.choice_log_probs(sampler, right))
    p = np.exp(misfit.choice_log_probs(sampler, wrong))
    assert p[-1] > p_right[-1] and abs(p.sum() - 1) < 1e-12, (p_right, p)

    flat = dataclasses.replace(sampler.model, inference=dataclasses.replace(
        sampler.model.inference, refit_focus=0.0))
    plain = Sampler(flat, sampler.scorer, np.random.default_rng(0))
    n = len(wrong.objects)
    assert np.allclose(misfit.choice_log_probs(plain, wrong), -math.log(n))
    picks = [misfit.choose(plain, wrong, np.random.default_rng(s)) for s in range(20)]
    assert picks == [int(np.random.default_rng(s).integers(n)) for s in range(20)]
    proposal = fitting.propose_refit(plain, wrong, np.random.default_rng(1))
    assert proposal.ratio_fn is None


# -- and fail on each broken density -----------------------------------------------------------


@pytest.mark.parametrize("brk", [birth_density_is_prior, birth_spread_halved])
def test_a_wrong_birth_density_is_caught(setting, monkeypatch, brk):
    brk(monkeypatch)
    report = birth_report(setting)
    assert _smallest_p(report) < POWER, report.table()


@pytest.mark.parametrize("brk", [refit_density_is_prior, refit_spreads_halved])
def test_a_wrong_refit_density_is_caught(setting, monkeypatch, brk):
    brk(monkeypatch)
    report = refit_report(setting)
    assert _smallest_p(report) < POWER, report.table()


@pytest.mark.parametrize("brk", [refit_choice_is_uniform, refit_choice_focus_halved])
def test_a_wrong_refit_choice_is_caught(wide, monkeypatch, brk):
    brk(monkeypatch)
    report = refit_choice_report(wide)
    assert _smallest_p(report) < POWER, report.table()


def test_a_wrong_merge_first_choice_is_caught(wide, monkeypatch):
    merge_first_is_uniform(monkeypatch)
    report = merge_first_report(wide, monkeypatch)
    assert _smallest_p(report) < POWER, report.table()


@pytest.mark.parametrize("brk", [partner_density_is_uniform, partner_scales_halved])
def test_a_wrong_partner_density_is_caught(wide, monkeypatch, brk):
    brk(monkeypatch)
    report = partner_report(wide)
    assert _smallest_p(report) < POWER, report.table()


# -- slow: the chain against the exact posterior -----------------------------------------------


def flat_world(name: str, size: tuple[float, float], y_half: float, sigma: float,
               weights, max_objects: int) -> Model:
    """Flat red boxes of ``size`` (x, y) lying on the ground, placed uniformly in
    [-1.5, 1.5] x [-y_half, y_half], seen by an RGB sensor whose noise scale has prior mean
    ``sigma``; every data-driven move among ``weights``."""

    def parts(v):
        m = translation(v["x"], v["y"], 0) @ scaling(size[0], size[1], 0.05)
        return (Part("box", m, (0.9, 0.2, 0.2)),)

    cls = ObjectClass(
        name, 1.0,
        (Parameter("x", Interval(-1.5, 1.5), Uniform(-1.5, 1.5), 0.3),
         Parameter("y", Interval(-y_half, y_half), Uniform(-y_half, y_half), 0.3)),
        parts, position=("x", "y"),
    )
    sensors = {"image": Sensor("image", "gaussian",
                               (Parameter("sigma", Positive(), Gamma(4.0, sigma / 4), 0.1),))}
    return Model((cls,), sensors,
                 InferenceSettings(p_jump=1.0, jump_weights=dict.fromkeys(weights, 1.0)),
                 max_objects=max_objects)


def one_tile() -> Model:
    """At most one flat tile, its place in a 3 m square, seen by one 8x8 RGB camera with
    noise so large (sigma near 0.6) that the place is known to half a metre: the posterior is
    broad enough for a grid of 31 x 31 cells, and births and deaths are accepted. Rays of
    the pixels the tile leaves unexplained land on it (it lies on the ground), so births
    aim at it."""
    return flat_world("tile", (1.6, 1.6), 1.5, 0.6, ("birth", "death", "replace", "refit"), 1)


def joint_report(**kw) -> Report:
    model = one_tile()
    truth = (make_object(model, model.classes[0], {"x": 0.3, "y": -0.2}),)
    return verify.joint_check(model, truth, {"image": {"sigma": 0.6}}, chains=200, length=8,
                          cells=31, size=8, p_empty=0.5, alpha=ALPHA, **kw)


@pytest.mark.slow
def test_joint_check_passes_on_the_code(require_gl):
    """Chains with data-driven births, refits and replaces on fixed observations stay at the
    exact posterior. False alarm 1e-3 (Holm), up to the grid's error."""
    report = joint_report(seed=0)
    assert report.passed, report.table()
    note = report.notes[-1]
    assert "birth proposals could use unexplained pixels" in note


@pytest.mark.slow
def test_joint_check_sees_a_refit_scored_by_the_prior(require_gl, monkeypatch):
    """The same run with the refit's density replaced by the prior (its sampling left as it
    is) drifts from the exact posterior (p about 1e-6 on the tile's x). With the birth's
    density replaced by the prior, or either density's spread halved, this run still passes:
    births and deaths are too seldom accepted here for their ratios to show; the sampler-
    against-density checks above catch those."""
    refit_density_is_prior(monkeypatch)
    report = joint_report(seed=0)
    assert _smallest_p(report) < 1e-5, report.table()


def thesis_ratio(monkeypatch):
    """The thesis's birth/death ratio read literally: the ordered-tuple prior
    prod_c Poisson(N_c; lambda_c) gains lambda_c / (N_c + 1) on a birth where the set-valued
    target gains lambda_c, so a birth's ratio has an extra 1 / (N_c + 1) and a death's the
    inverse (the same as ``test_verify.ThesisRatioSampler``, patched into every sampler)."""
    right = Sampler.log_alpha

    def log_alpha(self, trace, proposal, new):
        a = right(self, trace, proposal, new)
        if proposal.move == "birth":
            return a - math.log(sum(o.cls.name == proposal.label for o in new.objects))
        if proposal.move == "death":
            return a + math.log(sum(o.cls.name == proposal.label for o in trace.objects))
        return a

    monkeypatch.setattr(Sampler, "log_alpha", log_alpha)


def two_strips() -> Model:
    """At most two strips 40 m long, seen through noise so heavy (sigma near 2) that one, two
    or no strips are all likely, and births and deaths are often accepted. A strip reaches
    past the camera's view at either end wherever it lies, so the likelihood does not depend
    on y: the exact posterior needs one cell in y and 31 in x, 496 pairs of cells."""
    return flat_world("strip", (0.8, 40.0), 1.0, 2.0, ("birth", "death", "replace"), 2)


def strips_report(seed=0) -> Report:
    model = two_strips()
    truth = (make_object(model, model.classes[0], {"x": 0.3, "y": 0.0}),)
    return verify.joint_check(model, truth, {"image": {"sigma": 2.0}}, chains=400, length=30,
                          cells={"x": 31, "y": 1}, size=8, seed=seed, p_empty=0.3,
                          alpha=ALPHA)


@pytest.mark.slow
def test_the_likelihood_of_a_strip_does_not_depend_on_its_y(require_gl):
    """What lets the joint check use one cell in y: exact, to the last bit of the sums."""
    from sppl.render import Renderer
    from sppl.verify import Simulator, verify_cameras

    model = two_strips()
    sim = Simulator(model, verify_cameras(model, 8), Renderer(model.render))
    cls = model.classes[0]
    for x in (-1.2, 0.3):
        renders = [sim.render((make_object(model, cls, {"x": x, "y": y}),))[0][0]
                   for y in (-1.0, 0.0, 1.0)]
        assert all(np.array_equal(renders[0], r) for r in renders[1:])


@pytest.mark.slow
def test_joint_check_with_two_objects_passes_on_the_code(require_gl):
    """Births (near unexplained pixels), deaths and replaces with up to two strips stay at
    the exact posterior. False alarm 1e-3 (Holm), up to the grid's error."""
    report = strips_report()
    assert report.passed, report.table()


@pytest.mark.slow
def test_joint_check_rejects_the_thesis_ratio_with_observations(require_gl, monkeypatch):
    """The literal thesis ratio, with data-driven births on fixed observations: two strips
    lose posterior mass to one (0.18 of the chains end with two, against 0.27 exactly;
    p 2e-5 on 400 chains)."""
    thesis_ratio(monkeypatch)
    report = strips_report()
    assert not report.passed and _smallest_p(report) < 1e-4, report.table()
