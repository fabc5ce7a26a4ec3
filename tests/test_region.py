"""A region restricting where objects may be: its normaliser, its draws, its errors, and the
sampler with it (every move, prior recovery against rejection sampling).

Statistical tests run at fixed seeds; each states its false-alarm rate. Reports are decided
together by Holm's correction at ``verify.ALPHA`` = 1% family-wise.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from false_alarms import EACH, SLOW_EACH
from scipy import stats

from sppl import cli, verify
from sppl.data.camera import Camera, focal_from_fov, look_at
from sppl.errors import ModelErrors
from sppl.infer.chain import Sampler
from sppl.lang.compile import compile_model
from sppl.model.distributions import Normal, Uniform
from sppl.model.region import (
    RegionError,
    bind_region,
    box,
    camera_footprint,
    cameras_region,
    polygon,
    restrict,
)
from sppl.model.simulate import sample_noise, sample_objects
from sppl.model.trace import make_object
from sppl.scoring.scorer import PriorScorer

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "region" / "regions.scn"
POLYGON = "region polygon((-1, -3), (3, -1), (2, 3), (-2, 2), (0, 0.5))"


def model_with(region: str, extra: str = "", jumps: str = ""):
    """The fixture with a region; ``jumps`` replaces its jump weights (all seven)."""
    text = FIXTURE.read_text()
    if jumps:
        text = "\n".join(f"    jump_weights {jumps}" if line.strip().startswith("jump_weights")
                         else line for line in text.splitlines()) + "\n"
    return compile_model(text + extra + region + "\n", str(FIXTURE))


LIGHT = "birth = 1, death = 1, change = 1, replace = 1"


def camera(eye=(3.0, -2.6, 2.4), size=32):
    f = focal_from_fov(size, 50.0)
    return Camera("front", size, size, f, f, size / 2, size / 2, look_at(eye, (0.0, 0.0, 0.0)),
                  depth_max=8.0)


# -- the normaliser ---------------------------------------------------------------------------


def test_box_normaliser_is_the_product_of_cdf_differences():
    r = restrict(box(-1, -2, 3, 1), ("x", "y"), Normal(0.5, 2), Normal(0, 1.5))
    expected = (stats.norm.cdf(3, 0.5, 2) - stats.norm.cdf(-1, 0.5, 2)) * (
        stats.norm.cdf(1, 0, 1.5) - stats.norm.cdf(-2, 0, 1.5))
    assert math.exp(r.log_mass) == pytest.approx(expected, rel=1e-12)
    assert r.error == 0.0


def test_polygon_normaliser_agrees_with_boxes_it_is_made_of():
    """An L of two boxes as one polygon: quadrature against the exact CDF products (and a
    uniform prior, whose density has corners inside the polygon)."""
    for px, py in [(Normal(0.5, 2), Normal(0, 1.5)), (Uniform(-2, 2.5), Normal(1, 0.7))]:
        ell = polygon([(-1, -2), (3, -2), (3, 0), (1, 0), (1, 2), (-1, 2)])
        a = restrict(box(-1, -2, 3, 0), ("x", "y"), px, py)
        b = restrict(box(-1, 0, 1, 2), ("x", "y"), px, py)
        r = restrict(ell, ("x", "y"), px, py)
        expected = math.exp(a.log_mass) + math.exp(b.log_mass)
        assert math.exp(r.log_mass) == pytest.approx(expected, rel=1e-9)
        assert r.error <= 1e-9 * expected


def test_sections_of_a_polygon_with_a_hole():
    ring = shapely.Polygon([(0, 0), (4, 0), (4, 4), (0, 4)], [[(1, 1), (3, 1), (3, 3), (1, 3)]])
    from sppl.model.region import Region

    region = Region("polygon", ring)
    assert region.sections(0, [2.0])[0] == [(0.0, 1.0), (3.0, 4.0)]
    assert region.sections(1, [0.5])[0] == [(0.0, 4.0)]
    assert region.sections(0, [5.0])[0] == []


def test_a_camera_footprint_is_the_ground_its_image_covers():
    """Ground points inside the footprint project into the image (in front, within
    depth_max), and points outside do not: checked on a grid against ``Camera.project``."""
    cam = camera()
    shape = camera_footprint(cam)
    assert shape.area > 1.0
    xs, ys = np.meshgrid(np.linspace(-8, 8, 161), np.linspace(-8, 8, 161))
    pts = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    pix, depth = cam.project(pts)
    seen = ((depth > cam.near) & (depth <= cam.depth_max) & (pix[:, 0] >= 0)
            & (pix[:, 0] <= cam.width) & (pix[:, 1] >= 0) & (pix[:, 1] <= cam.height))
    inside = shapely.intersects_xy(shape.buffer(1e-9), pts[:, 0], pts[:, 1])
    near_edge = shapely.distance(shape.boundary, shapely.points(pts[:, :2])) < 1e-6
    assert np.array_equal(seen[~near_edge], inside[~near_edge])


# -- draws and densities ----------------------------------------------------------------------


def test_draws_and_conditionals_stay_inside_and_integrate_to_one():
    model = model_with(POLYGON)
    ball = model.object_class("ball")
    rng = np.random.default_rng(0)
    draws = [ball.sample_prior(rng) for _ in range(300)]
    assert all(ball.restriction.contains(v) for v in draws)
    # One coordinate given: the conditional draw stays inside, and its density over y, on a
    # fine grid, integrates to one.
    given = ball.sample_prior(rng, given={"x": 0.7})
    assert given["x"] == 0.7 and ball.restriction.contains(given)
    ys = np.linspace(-6, 6, 24001)
    dens = [math.exp(ball.log_prior({**given, "y": y}, only=["y"])) for y in ys]
    assert np.trapezoid(dens, ys) == pytest.approx(1.0, abs=2e-3)
    assert ball.log_prior({**given, "x": 40.0}) == -math.inf


def test_prior_declarations_check_the_normaliser():
    """The region's draws against rejection sampling and Z against the share of prior draws
    inside (binomial): both pass as built, and a normaliser off by 20% fails. False alarm 1%."""
    model = model_with(POLYGON)
    assert verify.prior_declarations(model, draws=1500, seed=1).passed
    ball = model.object_class("ball")
    wrong = dataclasses.replace(ball.restriction, log_mass=ball.restriction.log_mass + 0.2)
    broken = dataclasses.replace(model, classes=(
        dataclasses.replace(ball, restriction=wrong), *model.classes[1:]))
    report = verify.prior_declarations(broken, draws=1500, seed=1)
    assert not report.passed
    assert [r.quantity for r in report.failures] == ["ball: the region's normaliser"]


# -- errors -------------------------------------------------------------------------------------


@pytest.mark.parametrize("text, message", [
    ("region box(1, 0, 0, 2)", "the box (1, 0, 0, 2) is empty"),
    ("region polygon((0, 0), (1, 1), (2, 2))", "the polygon is degenerate"),
    ("region polygon((0, 0), (1, 1), (1, 0), (0, 1))", "the polygon's edges cross"),
    ("region polygon((0, 0), (1, 1))", "a polygon needs at least 3 corners"),
    ("region polygon((0, 0), 1, (1, 1))", "a polygon's corners are (x, y) pairs"),
    ("region circle(1)", "unknown region `circle`"),
    ("region box(1, 2, 3)", "`box` takes four numbers"),
    ("region box(100, 100, 101, 101)", "holds no prior mass"),
    ("region cameras\nregion box(0, 0, 1, 1)", "the region is already given on line"),
])
def test_bad_regions_are_one_line_errors(text, message):
    with pytest.raises(ModelErrors) as info:
        model_with(text)
    first = str(info.value).splitlines()[0]
    assert message in first and "regions.scn:" in first


def test_a_camera_region_names_known_cameras():
    model = model_with('region cameras(front, "side")')
    with pytest.raises(RegionError, match=r"regions\.scn:\d+:1: region cameras: unknown "
                                          r"camera 'side'; the observations have 'front'"):
        bind_region(model, [camera()])
    with pytest.raises(RegionError, match="no cameras to take the region from"):
        Sampler(model_with("region cameras"), PriorScorer(), np.random.default_rng(0))
    away = Camera("up", 8, 8, 8.0, 8.0, 4, 4, look_at((0, 0, 2), (0, 0.01, 5)), depth_max=8.0)
    with pytest.raises(RegionError, match="no camera sees the ground"):
        cameras_region([away])


def test_sppl_verify_reports_a_bad_region_in_one_line(tmp_path, capsys):
    path = tmp_path / "bad.scn"
    path.write_text(FIXTURE.read_text() + "region polygon((0, 0), (1, 1), (2, 2))\n")
    assert cli.main(["verify", str(path), "--steps", "100"]) != 0
    err = capsys.readouterr().err
    assert "bad.scn:" in err and "degenerate" in err and "Traceback" not in err


# -- the sampler with a region -------------------------------------------------------------------


@pytest.mark.parametrize("region", [POLYGON, "region box(-1, -2, 3, 1)"])
def test_every_move_and_its_reverse_with_a_region(require_gl, region):
    """Birth (from the prior and near unexplained pixels), death, change, replace, refit,
    merge, split, parameter and noise moves with a region, with rendered observations."""
    model = model_with(region)
    report = verify.move_checks(model, states=12, seed=5, size=16)
    assert report.passed, report.table()
    moved = {r.quantity.split(":")[0] for r in report.rows}
    assert {"birth", "death", "change", "replace", "parameters", "noise"} <= moved


def test_fitted_births_and_deaths_and_their_reverses_with_a_region(require_gl):
    """Fitted births and deaths with a region (24x24 cameras, so that objects leave blobs to
    seed): every one undone by its reverse with minus its log ratio."""
    model = model_with("region box(-1, -2, 3, 1)",
                       jumps=LIGHT + ", fitted_birth = 3, fitted_death = 3")
    report = verify.move_checks(model, states=16, seed=5, size=24)
    assert report.passed, report.table()
    moved = {r.quantity.split(":")[0] for r in report.rows}
    assert {"fitted_birth", "fitted_death"} <= moved, report.table()


def test_a_chain_with_a_region_never_leaves_it(require_gl):
    """Every state of a short chain on rendered observations (every jump weighed) keeps
    every object inside the region, a change that carries only one coordinate included."""
    model = model_with(POLYGON, "change ball.x <-> block.y\n")
    sim = verify.Simulator(model, verify.verify_cameras(model, 16), _renderer())
    rng = np.random.default_rng(2)
    objs = sample_objects(model, rng)
    sampler = sim.sampler(sim.observe(sim.render(objs), sample_noise(model, rng), rng),
                          rng, Sampler)
    prior = Sampler(model, PriorScorer(), rng)  # where every jump is often accepted
    # A merge of the prior's is accepted about one time in ten (a red ball and a blue block
    # are unlikely partners), so the prior chain runs long enough to see one.
    for s, sweeps in ((sampler, 150), (prior, 400)):
        trace = s.initial_trace(objs)
        for _ in range(sweeps):
            trace = s.sweep(trace)
            assert all(o.cls.restriction.contains(o.values) for o in trace.objects)
    moved = prior.stats.by_move()
    assert all(moved[j][1] > 0 for j in ("birth", "death", "change", "replace", "merge",
                                         "split", "parameters")), moved


def test_a_given_scene_is_scored_and_moved_with_the_bound_region(require_gl):
    """Objects made from the model before the sampler bound `region cameras` (a starting
    scene, a truth to score) become objects of the sampler's classes: one the cameras do not
    see has no prior density, one they see carries the region's normaliser, and a chain from
    them draws its classes' changes and births inside the region."""
    model = model_with("region cameras", jumps=LIGHT)
    sim = verify.Simulator(model, verify.verify_cameras(model, 16), _renderer())
    rng = np.random.default_rng(4)
    ball, block = model.object_class("ball"), model.object_class("block")
    seen = make_object(model, ball, {"x": 0.0, "y": 0.0, "r": 0.3, "c": "red"})
    unseen = make_object(model, block, {"x": 40.0, "y": 0.0, "a": 0.0, "s": 0.4, "c": "red"})
    noise = sample_noise(model, rng)
    sampler = sim.sampler(sim.observe(sim.render([seen]), noise, rng), rng, Sampler)
    bound = sampler.model.object_class("ball")
    assert bound is not ball and bound.restriction is not None

    trace = sampler.make_trace((seen,), noise)
    assert trace.objects[0].cls is bound
    mass = bound.restriction.log_mass
    assert mass < -1e-3  # the cameras see a part of the ground the prior could put it on
    assert trace.objects[0].log_prior == pytest.approx(seen.log_prior - mass)
    assert trace.log_prior == pytest.approx(
        sampler.make_trace((make_object(sampler.model, bound, seen.values),), noise).log_prior)
    assert sampler.make_trace((seen, unseen), noise).log_prior == -math.inf
    # The chain's own objects pass through as they are.
    assert sampler.make_trace(trace.objects, noise).objects[0] is trace.objects[0]

    trace = sampler.initial_trace((seen,))
    for _ in range(60):
        trace = sampler.sweep(trace)
        assert all(o.cls is sampler.model.object_class(o.cls.name) for o in trace.objects)
        assert all(o.cls.restriction.contains(o.values) for o in trace.objects)


def _renderer():
    from sppl.render import Renderer

    return Renderer()


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_with_a_region(false_alarm):
    """With no observations the chain visits the restricted prior: each class's count is
    Poisson(lambda) (the rate is the count in the region) and its positions those of
    rejection sampling, decided by Holm at the test's false-alarm rate. Leaving -log Z out of the object's prior
    makes the counts Poisson(lambda Z), which the same test rejects at this seed."""
    model = model_with("region box(-1, -2, 3, 1)", jumps=LIGHT)
    one = dataclasses.replace(model, classes=model.classes[1:])  # block: rate 1, quick to mix
    report = verify.prior_recovery(one, sweeps=4000, seed=4, reference_draws=2000,
                                   alpha=false_alarm)
    assert report.passed, report.table()
    assert "rejection" in report.row("block.x").expected
    assert report.row("count of block").p_value is not None

    # Births that draw from the unrestricted prior while their ratio assumes the restricted
    # one (so that they would need the normaliser in their ratio) give Poisson(lambda Z).
    unrestricted = UnrestrictedDraws(one.classes[0].restriction)
    wrong = dataclasses.replace(one, classes=(
        dataclasses.replace(one.classes[0], restriction=unrestricted),))
    # These draws put objects outside the region, where both the old and the new object of a
    # replace have density -inf: the ratio is -inf - -inf, NaN, which the sampler counts and
    # rejects; numpy's warning about it says nothing the test does not know.
    with np.errstate(invalid="ignore"):
        bad = verify.prior_recovery(wrong, sweeps=4000, seed=4, reference_draws=2000)
    assert bad.row("count of block").p_value < 1e-4 and not bad.passed


class UnrestrictedDraws:
    """A restriction whose draws ignore the region (its density still restricted)."""

    def __init__(self, restriction):
        self.r = restriction

    def __getattr__(self, name):
        return getattr(self.r, name)

    def sample(self, rng, values, given):
        for name, prior in zip(self.r.names, (self.r.x_prior, self.r.y_prior)):
            if name not in given:
                values[name] = prior.sample(rng)


def test_a_change_between_classes_weighs_their_normalisers():
    """From one ball, a change to a block carrying x, y and c: the log acceptance ratio by
    hand is log [lambda_block p_block(x, y, c) Z_ball / (lambda_ball p_ball(x, y, c) Z_block)]
    (the dropped and drawn parameters cancel against their proposals); the normalisers differ
    because the classes' position priors do, and the sampler's ratio must count them."""
    model = model_with("region box(-1, -2, 3, 1)", jumps=LIGHT)
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    ball, _ = model.classes
    values = {"x": 0.4, "y": -0.3, "r": 0.3, "c": "red"}
    trace = sampler.initial_trace((make_object(model, ball, values),))
    for _ in range(50):
        p = sampler.propose_jump(trace)
        if p is not None and p.move == "change":
            break
    new = sampler.evaluate(trace, p)
    z_ball = (stats.norm.cdf(3, 0.5, 2) - stats.norm.cdf(-1, 0.5, 2)) * (
        stats.norm.cdf(1, 0, 1.5) - stats.norm.cdf(-2, 0, 1.5))
    z_block = (stats.norm.cdf(3, 0, 2) - stats.norm.cdf(-1, 0, 2)) * (
        stats.norm.cdf(1, 0, 2) - stats.norm.cdf(-2, 0, 2))
    expected = (math.log(1.0) + stats.norm.logpdf(0.4, 0, 2) + stats.norm.logpdf(-0.3, 0, 2)
                + math.log(0.5) - math.log(z_block)) - (
        math.log(2.0) + stats.norm.logpdf(0.4, 0.5, 2) + stats.norm.logpdf(-0.3, 0, 1.5)
        + math.log(0.3) - math.log(z_ball))
    assert sampler.log_alpha(trace, p, new) == pytest.approx(expected, abs=1e-9)


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH)
@pytest.mark.parametrize("region", [POLYGON, "region box(-1, -2, 3, 1)"])
def test_prior_recovery_with_a_region_long(region, false_alarm):
    report = verify.prior_recovery(model_with(region), sweeps=40_000, seed=6,
                                   reference_draws=10_000, alpha=false_alarm)
    assert report.passed, report.table()
    assert not any("untested" in r.observed for r in report.rows), report.table()


@pytest.mark.false_alarm(EACH)
def test_sppl_verify_with_a_camera_region(require_gl, tmp_path, capsys, false_alarm):
    """`region cameras` is verified as the ground the verify cameras see."""
    path = tmp_path / "cameras.scn"
    path.write_text(model_with("region cameras", jumps=LIGHT).source)
    code = cli.main(["verify", str(path), "--steps", "1000", "--geweke-chains", "20",
                     "--geweke-length", "6", "--seed", "3", "--alpha", str(false_alarm)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "the region's normaliser" in out


def test_sppl_sample_names_an_unknown_camera_in_one_line(require_gl, tmp_path, capsys, root):
    path = tmp_path / "named.scn"
    path.write_text(FIXTURE.read_text() + "region cameras(rgb_front, top)\n")
    code = cli.main(["sample", str(path), "--obs", str(root / "examples" / "three_shapes" / "obs"),
                     "--out", str(tmp_path / "run"), "--steps", "5"])
    err = capsys.readouterr().err
    assert code != 0 and "Traceback" not in err
    assert "named.scn:" in err and "unknown camera 'top'" in err
    assert "'rgb_front', 'depth_side'" in err


def test_sppl_check_shows_the_region(tmp_path, capsys):
    path = tmp_path / "boxed.scn"
    path.write_text(model_with("region box(-1, -2, 3, 1)").source)
    assert cli.main(["check", str(path)]) == 0
    assert "region: box(-1, -2, 3, 1); prior mass inside: ball 0.4382, block 0.3328" in (
        capsys.readouterr().out)
