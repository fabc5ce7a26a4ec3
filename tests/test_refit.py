"""The refit jump (sppl/infer/fit.py): an object replaced by one of any class fitted to the scene
without it. Exact through a deterministic fit: checked by prior recovery, Geweke and the move
checks, and the checks fail when the reverse density is left out."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from false_alarms import EACH
from test_verify import seen_world
from toys import ball_class, block_class, gaussian_model, toy_model

from sppl import verify
from sppl.infer import fit


def with_refit(model, weight=4.0):
    weights = {**model.inference.jump_weights, "refit": weight}
    return dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, jump_weights=weights))


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_with_refits(false_alarm):
    """Without observations the fit climbs the prior; the chain must still reproduce it
    (counts chi-square, marginals KS; false alarm at the marker's rate, Holm)."""
    model = with_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]))
    report = verify.prior_recovery(model, sweeps=15000, seed=3, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("refit moves accepted").ok


def test_prior_recovery_sees_a_refit_taken_for_symmetric(monkeypatch):
    """A refit whose ratio takes the proposal for symmetric (the reverse density set to the
    forward one): the chain drifts towards the fitted values, and the check fails."""
    real = fit.propose_refit

    def symmetric(*args, **kwargs):
        p = real(*args, **kwargs)
        if p is None:
            return None
        return dataclasses.replace(p, log_q_ratio=0.0 if math.isfinite(p.log_q_ratio)
                                   else p.log_q_ratio, deferred=None)

    monkeypatch.setattr(fit, "propose_refit", symmetric)
    model = with_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]))
    report = verify.prior_recovery(model, sweeps=15000, seed=3, alpha=EACH)
    assert not report.passed, report.table()


def test_the_refitted_class_is_weighed_in_both_ratios(monkeypatch):
    """The refitted object's class is drawn by ``fit.draw_class`` from ``refitted_classes``'s
    probabilities (their draws are checked against ``fit.class_log_prob`` by sppl verify,
    tests/test_fitted_birth.py); here, that a refit's ratio divides by exactly the drawn
    class's probability, and its reverse multiplies by that of the class it gives back,
    worked out from the new object."""
    from sppl.infer.chain import Sampler
    from sppl.model.trace import make_object
    from sppl.scoring.scorer import PriorScorer

    model = with_refit(toy_model([ball_class(rate=0.8), block_class(rate=0.5)]))
    block = model.classes[1]
    objects = (make_object(model, block, {"x": 0.9, "y": 0.2, "a": 0.1, "s": 0.4, "c": "blue"}),)
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    trace = sampler.make_trace(objects, {})
    empty = sampler.make_trace((), {})

    def proposal():
        p = fit.propose_refit(sampler, trace, np.random.default_rng(4), k=0, state=empty)
        after = sampler.make_trace(p.objects, {})
        return p, p.tries.reverse(sampler, trace, p, after)

    right, right_back = proposal()
    right_deferred = right.deferred()
    _, log_p = fit.refitted_classes(sampler, empty, objects[0])
    _, log_p_back = fit.refitted_classes(sampler, empty, right.changed[0])
    assert not np.allclose(log_p, log_p[0])  # the fits tell the classes apart
    monkeypatch.setattr(fit, "class_log_prob", lambda log_p, c: 0.0)
    left, _ = proposal()
    c = model.classes.index(right.changed[0].cls)
    assert left.changed[0].values == right.changed[0].values
    assert math.isclose(right.log_q_ratio - left.log_q_ratio, -log_p[c], abs_tol=1e-9)
    assert math.isclose(right_deferred - left.deferred(), log_p_back[model.classes.index(block)],
                        abs_tol=1e-9)
    assert right_back.changed[0] is objects[0]


def test_every_refit_and_its_reverse(require_gl):
    """Against observations: the reverse, through the same scene without the object, gives
    back the trace with minus the log ratio."""
    report = verify.move_checks(with_refit(seen_world()), states=12, seed=5)
    assert report.passed, report.table()
    assert "refit: reverse undoes it" in {r.quantity for r in report.rows}


@pytest.mark.false_alarm(EACH)
def test_geweke_with_refits(false_alarm, require_gl):
    """False alarm 1% (Holm)."""
    report = verify.geweke(with_refit(seen_world()), chains=100, length=12, seed=7, size=8,
                           mc_draws=4000, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("refit moves accepted").ok


def _observed_scene(seed):
    """A prior scene of two or more objects of ``seen_world`` observed by its cameras: the
    model, a sampler given the observations, the objects, and the state without the first."""
    from sppl.infer.chain import Sampler
    from sppl.model.simulate import sample_noise, sample_objects

    model = seen_world()
    sim = verify.Simulator(model, verify.verify_cameras(model, 8), _renderer(model))
    rng = np.random.default_rng(seed)
    objects = ()
    while len(objects) < 2:
        objects = sample_objects(model, rng)
    noise = sample_noise(model, rng)
    sampler = sim.sampler(sim.observe(sim.render(objects), noise, rng), rng, Sampler)
    return model, sampler, objects, sampler.make_trace(objects[1:], noise)


def test_the_fit_is_deterministic_and_improves_the_scene(require_gl):
    """Fitted twice from the same scene it gives the same values, and they score at least as
    well as where it started."""
    model, sampler, objects, state = _observed_scene(2)
    for cls in model.classes:
        a = fit.fit(sampler, state, cls, objects[0])
        b = fit.fit(sampler, state, cls, objects[0])
        assert a == b
        for start in fit._starts(cls, objects[0]):
            assert fit._score(sampler, state, cls, a) >= fit._score(sampler, state, cls, start)


def test_the_fits_memo_changes_no_fit_and_saves_scores(require_gl, monkeypatch):
    """Each point a fit scores twice is rendered once (a search's step back, the shared
    starts); the fit is the same values as with every point rendered anew."""
    model, sampler, objects, state = _observed_scene(4)
    real, calls = fit._score, []

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(fit, "_score", counted)
    remembered = [fit.fit(sampler, state, cls, objects[0]) for cls in model.classes]
    with_memo = len(calls)
    # Every score the memo gives is the one a fresh render gives.
    memo = fit._Scores.__call__

    def checked(self, values):
        s = memo(self, values)
        assert s == real(self.sampler, self.state, self.cls, values), values
        return s

    monkeypatch.setattr(fit._Scores, "__call__", checked)
    for cls in model.classes:
        fit.fit(sampler, state, cls, objects[0])
    monkeypatch.setattr(fit._Scores, "__call__",
                        lambda self, values: counted(self.sampler, self.state, self.cls, values))
    calls.clear()
    assert [fit.fit(sampler, state, cls, objects[0]) for cls in model.classes] == remembered
    assert with_memo < len(calls)


def _renderer(model):
    from sppl.render import Renderer

    return Renderer(model.render)


def _example(root, name):
    """A shipped model, its example's cameras, and a renderer for it."""
    from sppl.data.observations import load_cameras
    from sppl.lang import load_model

    model = load_model(root / "models" / f"{name}.scn")
    cameras = load_cameras(root / "examples" / "models" / name / "cameras.json")
    return model, cameras, _renderer(model)


def _observed(root, model, cameras, renderer, scene, rng):
    """A scene's objects, and a sampler scoring against observations rendered from it."""
    from sppl.data.observations import Observations
    from sppl.infer.chain import Sampler
    from sppl.model.simulate import objects_from_dict, render_observations
    from sppl.scoring.scorer import Scorer

    truth = objects_from_dict(model, scene)
    frames = render_observations(model, truth, scene["noise"], cameras, renderer, rng)
    return truth, Sampler(model, Scorer(model, Observations(root, frames), renderer), rng)


@pytest.mark.parametrize("weights", ["refit = 1"])
def test_a_model_weighs_refits(weights):
    from sppl.lang import compile_model

    model = compile_model("class ball { count ~ poisson(1) x : real ~ normal(0, 1)\n"
                          "geometry sphere(0.2) at (x, 0) colour rgb(1, 0, 0) }\n"
                          f"inference {{ jump_weights birth = 1, death = 1, {weights} }}")
    assert model.inference.jump_weights["refit"] == 1.0


def test_the_bound_of_a_reverse_density_is_never_below_it(root):
    """The bound that lets a chain skip a reverse fit is at least the density at any fit,
    and reached where the fit is the value itself (categorical parameters aside)."""
    from sppl.lang import load_model

    rng = np.random.default_rng(4)
    for name in ("shapes.scn", "tabletop.scn", "shapes_plus.scn"):
        model = load_model(root / "models" / name)
        for cls in model.classes:
            for _ in range(50):
                values = cls.sample_prior(rng)
                fitted = dict(values)
                bound = fit.log_density_bound(cls, values)
                assert fit.log_density(cls, values, fitted) <= bound + 1e-9
                for p in cls.parameters:
                    if p.continuous:
                        fitted[p.name] += float(rng.normal(0.0, p.proposal_scale))
                    else:
                        fitted[p.name] = p.sample(rng, fitted)
                assert fit.log_density(cls, values, fitted) <= bound + 1e-9


def _shapes_chain(root, sampler_class, sweeps=240):
    """Sweeps of a chain on the three shapes, which jumps every sweep (refits, merges and
    splits among the jumps): each sweep's state and the sampler."""
    from sppl.data.observations import load_observations
    from sppl.render import Renderer
    from sppl.scoring.scorer import Scorer

    model = gaussian_model(root, "shapes.scn")
    # The jumps whose reverse fits are deferred, without fitted births and deaths (whose
    # deferral is the same code), as this chain was first checked with.
    weights = {**model.inference.jump_weights, "fitted_birth": 0.0, "fitted_death": 0.0}
    model = dataclasses.replace(model, inference=dataclasses.replace(
        model.inference, jump_weights=weights))
    obs = load_observations(root / "examples" / "three_shapes" / "obs")
    sampler = sampler_class(model, Scorer(model, obs, Renderer(model.render)),
                            np.random.default_rng(8))
    trace, states = sampler.initial_trace(), []
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
        states.append((trace.score, tuple(o.as_dict()["params"].get("x") for o in trace.objects)))
    return states, sampler


def test_a_reverse_fit_left_undone_changes_no_decision(require_gl, root, monkeypatch):
    """A chain that computes a refit's, merge's or split's reverse fit only where its bound
    cannot decide draws exactly the states of one that always computes it; most are left
    undone; and a bound set too low (a ratio that can exceed it) changes the chain."""
    from sppl.infer.chain import Sampler, accept

    class Eager(Sampler):
        def _accept_deferred(self, trace, proposal, new):
            log_alpha = self.log_alpha(trace, proposal, new)
            return None if math.isnan(log_alpha) else accept(log_alpha, self.rng)

    from sppl.infer import merge

    # Where each move makes its deferred reverse density: a refit's, a merge's, a split's.
    makers = ((fit, "refit_back"), (fit, "refitted_back"), (merge, "merged_back"))
    real = {name: getattr(module, name) for module, name in makers}
    asked = {"made": 0, "computed": 0}

    def counted(name):
        def make(*args, **kwargs):
            back, bound = real[name](*args, **kwargs)
            asked["made"] += 1

            def computed():
                asked["computed"] += 1
                return back()

            return computed, bound
        return make

    for module, name in makers:
        monkeypatch.setattr(module, name, counted(name))
    lazy, sampler = _shapes_chain(root, Sampler)
    made, computed = asked["made"], asked["computed"]
    eager, _ = _shapes_chain(root, Eager)
    assert lazy == eager
    assert made > 20 and computed < made / 2, (made, computed)
    accepted = sum(sampler.stats.counts[k][1] for k in sampler.stats.counts
                   if k[0] in ("refit", "merge", "split"))
    assert accepted > 0

    def too_low(name):
        def make(*args, **kwargs):
            back, bound = real[name](*args, **kwargs)
            return back, bound - 1000.0
        return make

    for module, name in makers:
        monkeypatch.setattr(module, name, too_low(name))
    wrong, _ = _shapes_chain(root, Sampler)
    assert wrong != eager


def test_a_sphere_refitted_as_a_cube_finds_the_small_cube(require_gl, root):
    """A small cube (side 0.22 m, turned 0.35 rad) on shapes.scn, seen by the example's
    cameras, explained by a sphere in its place: the refit as a cube lands on it (side within
    2 cm, turn within 0.15 rad modulo the cube's quarter turn, place within 3 cm) in at least
    9 of 10 scenes, the cube's place drawn from a fixed seed. 9 do. With the start's side and
    turn from one fixed prior draw (0.6 m) 5 did; the search walked away from the pixels, as
    the sphere of scene 20 of the prior benchmark did when refitted as a sphere, to one 4 mm
    across. Without the turns tried before and after the search, 8."""
    from sppl.model.trace import make_object

    model, cameras, renderer = _example(root, "shapes")
    found = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        cube = {"x": 0.4 + 0.2 * rng.standard_normal(), "y": -0.6 + 0.2 * rng.standard_normal(),
                "a": 0.35, "s": 0.22, "c": "red"}
        scene = {"objects": [{"class": "cube", "params": cube},
                             {"class": "sphere", "params": {"x": -0.8, "y": 0.7, "r": 0.4,
                                                            "c": "blue"}}],
                 "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}}}
        truth, sampler = _observed(root, model, cameras, renderer, scene, rng)
        state = sampler.make_trace(truth[1:], scene["noise"])
        sphere = make_object(model, model.object_class("sphere"),
                             {"x": cube["x"], "y": cube["y"], "r": 0.12, "c": "red"})
        fitted = fit.fit(sampler, state, model.object_class("cube"), sphere)
        turn = (fitted["a"] - 0.35 + math.pi / 4) % (math.pi / 2) - math.pi / 4
        found.append(abs(fitted["s"] - 0.22) < 0.02 and abs(turn) < 0.15
                     and math.hypot(fitted["x"] - cube["x"], fitted["y"] - cube["y"]) < 0.03)
    renderer.release()
    assert sum(found) >= 9, found


def _large_sphere_fits(root, seeds=range(10)):
    """blocks.scn, its example's cameras: a large yellow sphere beside a small brown cylinder, and
    a chain's reading of the sphere as a small yellow cylinder on its far side and a small
    yellow cube on its near one; the merge's fit of a sphere from those two (scene 8 of the
    prior benchmark in miniature). Which fits land on the large sphere, within 3 cm."""
    from sppl.model.trace import make_object

    model, cameras, renderer = _example(root, "blocks")
    found = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        x, y = -0.8 + 0.2 * rng.standard_normal(), 0.6 + 0.2 * rng.standard_normal()
        ball = {"x": x, "y": y, "size": "large", "material": "rubber", "c": "yellow"}
        scene = {"objects": [{"class": "sphere", "params": ball},
                             {"class": "cylinder", "params": {"x": x - 0.59, "y": y - 0.28,
                                                              "size": "small",
                                                              "material": "rubber",
                                                              "c": "brown"}}],
                 "noise": {"image": {"sigma": 0.05, "outlier": 0.0},
                           "depth": {"sigma": 0.05, "outlier": 0.0}}}
        truth, sampler = _observed(root, model, cameras, renderer, scene, rng)
        # The chain's noise: with some pixels taken for outliers, a wrong size costs less.
        state = sampler.make_trace(truth[1:], {"image": {"sigma": 0.05, "outlier": 0.01},
                                               "depth": {"sigma": 0.05, "outlier": 0.025}})
        small = {"size": "small", "material": "rubber", "c": "yellow"}
        cylinder = make_object(model, model.object_class("cylinder"),
                               {"x": x, "y": y + 0.25, **small})
        cube = make_object(model, model.object_class("cube"),
                           {"x": x - 0.17, "y": y - 0.06, "a": -0.45, **small})
        fitted = fit.fit(sampler, state, model.object_class("sphere"), cylinder, also=(cube,))
        found.append(fitted["size"] == "large" and math.hypot(fitted["x"] - x,
                                                              fitted["y"] - y) < 0.03)
    renderer.release()
    return found


def test_a_merge_fits_the_large_sphere_two_small_objects_stand_for(require_gl, root):
    """In at least 9 of 10 such scenes (the sphere's place drawn from a fixed seed) the fit
    finds the large sphere, searching with each size held; 10 do. A search that moves the
    size only at the start and the end (as the fit did before) finds it in at most 5: it
    found it in none, each time fitting a small sphere where the cube stood."""
    assert sum(_large_sphere_fits(root)) >= 9


def test_the_large_sphere_is_missed_without_a_search_per_size(require_gl, root, monkeypatch):
    monkeypatch.setattr(fit, "shaping", lambda cls: ())
    assert sum(_large_sphere_fits(root)) <= 5


def test_the_categoricals_that_shape_an_object(root):
    from sppl.lang import load_model

    blocks = load_model(root / "models" / "blocks.scn")
    assert {c.name: fit.shaping(c) for c in blocks.classes} == {
        "cube": ("size",), "sphere": ("size",), "cylinder": ("size",)}
    tabletop = load_model(root / "models" / "tabletop.scn")
    assert all(fit.shaping(c) == () for c in tabletop.classes)


def _small_sphere_fits(root, seeds=range(10)):
    """shapes.scn, its example's cameras: a red sphere 9 cm in radius 0.9 m from a large red
    cube, read by the chain as a small red cube in its place (shapes_plus.scn's prior scene 17
    in miniature, chain seed 6); the refit of that cube as a sphere. Which fits land on the
    sphere (radius within 1 cm, place within 3 cm)."""
    from sppl.model.trace import make_object

    model, cameras, renderer = _example(root, "shapes")
    found = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        x, y = 0.6 + 0.1 * rng.standard_normal(), 1.1 + 0.1 * rng.standard_normal()
        scene = {"objects": [{"class": "sphere", "params": {"x": x, "y": y, "r": 0.09,
                                                            "c": "red"}},
                             {"class": "cube", "params": {"x": 0.65, "y": 0.2, "a": -0.11,
                                                          "s": 0.55, "c": "red"}}],
                 "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}}}
        truth, sampler = _observed(root, model, cameras, renderer, scene, rng)
        state = sampler.make_trace(truth[1:], scene["noise"])
        cube = make_object(model, model.object_class("cube"),
                           {"x": x, "y": y, "a": 0.17, "s": 0.14, "c": "red"})
        fitted = fit.fit(sampler, state, sampler.model.object_class("sphere"), cube)
        found.append(abs(fitted["r"] - 0.09) < 0.01
                     and math.hypot(fitted["x"] - x, fitted["y"] - y) < 0.03)
    renderer.release()
    return found


def test_a_small_cube_refitted_as_a_sphere_finds_the_small_sphere(require_gl, root):
    """In at least 8 of 10 such scenes (the sphere's place drawn from a fixed seed) the fit
    finds the sphere, starting also from the prior's draws sized to the cube's span; 9 do
    (the tenth stays at the sized start's radius, 7.7 cm)."""
    assert sum(_small_sphere_fits(root)) >= 8


def test_the_small_sphere_is_missed_without_sized_starts(require_gl, root, monkeypatch):
    """Started from the prior's draws of its radius alone, tens of centimetres, most of them
    overlapping the cube, the fit finds the sphere in at most 4 of the 10: it found it in 1,
    each other time ending far smaller or away from the pixels."""
    monkeypatch.setattr(fit, "_sized", lambda cls, values, size: values)
    assert sum(_small_sphere_fits(root)) <= 4


def test_an_objects_span_is_its_bounding_box_diagonal(root):
    """``geometry.span``: a cube of side s, square to the axes, spans s sqrt(3); turned an
    eighth of a turn, its box is s sqrt(2) wide; a sphere of radius r spans 2 r sqrt(3) (its
    mesh's bounds, within 1%). A start sized to a cube's span spans it."""
    from sppl.lang import load_model
    from sppl.model.geometry import span
    from sppl.model.trace import make_object

    model = load_model(root / "models" / "shapes.scn")
    cube, sphere = model.object_class("cube"), model.object_class("sphere")
    square = make_object(model, cube, {"x": 0.3, "y": -0.2, "a": 0.0, "s": 0.3, "c": "red"})
    turned = make_object(model, cube, {"x": 0.3, "y": -0.2, "a": -math.pi / 4, "s": 0.3,
                                       "c": "red"})
    ball = make_object(model, sphere, {"x": 1.0, "y": 1.0, "r": 0.2, "c": "blue"})
    assert span(square.parts) == pytest.approx(0.3 * math.sqrt(3), rel=1e-9)
    assert span(turned.parts) == pytest.approx(0.3 * math.sqrt(2 * 2 + 1), rel=1e-9)
    assert span(ball.parts) == pytest.approx(0.4 * math.sqrt(3), rel=0.01)
    sized = fit._sized(sphere, dict(ball.values), span(turned.parts))
    assert span(make_object(model, sphere, sized).parts) == pytest.approx(span(turned.parts),
                                                                          rel=1e-6)
    assert (sized["x"], sized["y"], sized["c"]) == (1.0, 1.0, "blue")


def _turned_cube_fit(root, seed, anchor):
    """examples/occlusion (shapes.scn, its one camera, its scene with noise drawn at
    ``seed``): the red cube as a chain held it (occlusion, chain seed 1), turned 3.3 degrees
    too far and shifted to make up for it, fitted again from there beside the far cone and
    the blue sphere that chain held, as a merge fits it (with ``anchor`` scores of anchored
    steps) or a refit (0). (the start's log joint, the fit's)."""
    from sppl.data.observations import load_cameras
    from sppl.lang import load_model
    from sppl.model.simulate import objects_from_dict
    from sppl.model.trace import make_object

    model = load_model(root / "models" / "shapes.scn")
    cameras = load_cameras(root / "examples" / "occlusion" / "cameras.json")
    renderer = _renderer(model)
    scene = json.loads((root / "examples" / "occlusion" / "scene.json").read_text())
    _, sampler = _observed(root, model, cameras, renderer, scene,
                           np.random.default_rng(seed))
    held = [{"class": "cone", "params": {"x": -1.1837, "y": 0.1255, "r": 0.2854, "h": 0.8036,
                                         "c": "green"}},
            {"class": "sphere", "params": {"x": 0.2985, "y": 1.2022, "r": 0.3001,
                                           "c": "blue"}}]
    state = sampler.make_trace(objects_from_dict(model, {"objects": held}), scene["noise"])
    cube = make_object(model, model.object_class("cube"),
                       {"x": 0.8833, "y": 0.0191, "a": -0.0581, "s": 0.8038, "c": "red"})
    start = sampler.make_trace(state.objects + (cube,), scene["noise"]).score
    _, score = fit.scored_fit(sampler, state, cube.cls, cube, anchor=anchor)
    renderer.release()
    return start, score


def test_a_turned_cube_is_fitted_by_turning_it_about_a_corner(require_gl, root):
    """The anchored steps turn the cube about a corner back towards square (the truth: 0
    degrees) and the pattern search moves it on from there: at each of three noise draws the
    fit gains over 30 nats (it gained 79, 165 and 38). shapes.scn's merges make 96 at most."""
    from sppl.lang import load_model

    assert load_model(root / "models" / "shapes.scn").inference.merge_anchor == 96
    for seed in range(3):
        start, score = _turned_cube_fit(root, seed, anchor=96)
        assert score > start + 30.0, seed


def test_the_turned_cube_stays_without_anchored_steps(require_gl, root):
    """Without them (a refit's fit) every step of one parameter uncovers or overpaints a
    column of pixels: at the same draws the fit gains less than 5 nats (it stayed at the
    start)."""
    for seed in range(3):
        start, score = _turned_cube_fit(root, seed, anchor=0)
        assert score < start + 5.0, seed


def test_an_anchored_step_keeps_one_corner_where_it_stands(root):
    """Each of ``_corner_shifts``' moves puts one corner of the stepped object's box back on
    the same corner of the object before: a cube turned by 0.1 rad about each of its four
    bottom corners (four moves), a sphere grown by 5 cm from each of its box's four sides'
    corners (four); the plain step, a move of zero, is none of them."""
    from sppl.lang import load_model
    from sppl.render.bounds import world_corners

    model = load_model(root / "models" / "shapes.scn")
    cube, sphere = model.object_class("cube"), model.object_class("sphere")
    for cls, values, name, step in ((cube, {"x": 0.3, "y": -0.2, "a": 0.2, "s": 0.3,
                                            "c": "red"}, "a", 0.1),
                                    (sphere, {"x": 1.0, "y": 1.0, "r": 0.2, "c": "blue"},
                                     "r", 0.05)):
        stepped = {**values, name: values[name] + step}
        shifts = fit._corner_shifts(cls, values, stepped)
        assert len(shifts) == 4
        before = world_corners(cls.parts(values))[:2].T
        for shift in shifts:
            moved = {**stepped, "x": stepped["x"] + shift[0], "y": stepped["y"] + shift[1]}
            after = world_corners(cls.parts(moved))[:2].T
            assert np.isclose(before, after, atol=1e-9).all(axis=1).any()
            assert np.abs(shift).max() > 1e-3
    assert fit.anchored_parameters(cube) == ("a", "s")
    assert fit.anchored_parameters(sphere) == ("r",)
