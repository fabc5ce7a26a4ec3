"""Cast shadows and latent lighting: both renderers against geometry and each other, the fast
scorer (whole and incremental) against full renders, the lighting moves against the prior,
and a colour that a fixed lighting misreads but a latent one keeps.

Statistical tests run at fixed seeds; each states its false-alarm rate.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from false_alarms import EACH, SLOW_EACH
from test_fast_scoring import _dense

from sppl import verify
from sppl.data.camera import Camera, focal_from_fov, look_at
from sppl.data.observations import CameraSpec, Observations
from sppl.errors import ModelErrors
from sppl.infer import moves
from sppl.infer.chain import Sampler
from sppl.lang import compile_model, load_model
from sppl.model.geometry import Part, scaling, translation
from sppl.model.simulate import render_observations, sample_noise, sample_objects
from sppl.model.trace import make_object
from sppl.model.types import RENDER_GROUP, RenderSettings
from sppl.output.samples import read_samples
from sppl.render import Renderer, raycast
from sppl.scoring.scorer import ReferenceScorer, Scorer

MODEL = Path(__file__).resolve().parent / "fixtures" / "lighting" / "latent_lighting.scn"
FLOOR = (0.6, 0.6, 0.6)
GROUND = Part("box", translation(0.0, 0.0, -0.1) @ scaling(8.0, 8.0, 0.1), FLOOR)
SHADOWS = RenderSettings(background=(0.1, 0.2, 0.3), ambient=0.35, light=(1.0, 0.0, 1.0),
                         shadows=True)


@pytest.fixture(params=["gl", "raycast"])
def render(request):
    if request.param == "raycast":
        yield lambda parts, camera, settings: raycast(parts, camera, settings)
        return
    request.getfixturevalue("require_gl")
    renderer = Renderer(SHADOWS)
    yield renderer.render
    renderer.release()


def top_down(f=50.0) -> Camera:
    """5 m above the origin looking down, 64x64: a ground point (x, y) is at column
    32 + f x / 5, row 32 - f y / 5."""
    return Camera("top", 64, 64, f, f, 32.0, 32.0,
                  look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)))


def _camera(name, width, height, eye):
    f = focal_from_fov(width, 55)
    return Camera(name, width, height, f, f, width / 2, height / 2,
                  look_at(eye, (0.0, 0.0, 0.3)), 8.0)


# --- shadows where geometry puts them ---------------------------------------------------------


def test_a_cube_shadows_the_ground_where_the_light_says(render):
    """A unit cube on the ground, the light at 45 degrees towards +x: its shadow covers the
    ground for x in [-1.5, -0.5] beside it (|y| < 0.5). The shadowed floor shows only the
    ambient share; the lit floor, at lambert cos 45 degrees, the rest as well."""
    cube = Part("box", np.eye(4), (0.9, 0.1, 0.1))
    rgb, _ = render([GROUND, cube], top_down(), SHADOWS)
    lit = np.array(FLOOR) * (0.35 + 0.65 / math.sqrt(2.0))
    dark = np.array(FLOOR) * 0.35
    assert np.allclose(rgb[32, 22], dark, atol=1e-4)  # (-1.0, 0): in the shadow
    assert np.allclose(rgb[32, 12], lit, atol=1e-4)  # (-2.0, 0): past its end
    assert np.allclose(rgb[22, 22], lit, atol=1e-4)  # (-1.0, 1.0): beside it
    assert np.allclose(rgb[32, 42], lit, atol=1e-4)  # (1.0, 0): on the lit side
    without, _ = render([GROUND, cube], top_down(), replace(SHADOWS, shadows=False))
    assert np.allclose(without[32, 22], lit, atol=1e-4)


def test_a_tall_box_shadows_a_sphere_beside_it(render):
    """A 2 m pillar between the light and a sphere: the sphere's lit side is darkened where
    the pillar's shadow crosses it, and only there."""
    pillar = Part("box", translation(0.0, 0.0, 0.0) @ scaling(0.3, 1.2, 2.0), (0.2, 0.2, 0.9))
    ball = Part("sphere", translation(-0.8, 0.0, 0.0) @ scaling(0.4, 0.4, 0.4), (0.9, 0.9, 0.2))
    camera = _camera("side", 64, 64, (-3.0, -2.5, 2.5))
    rgb, depth = render([GROUND, pillar, ball], camera, SHADOWS)
    plain, _ = render([GROUND, pillar, ball], camera, replace(SHADOWS, shadows=False))
    # Which pixels show the ball: its colour's ratio of red to blue.
    on_ball = (plain[..., 0] > 2.0 * plain[..., 2]) & (depth < camera.depth_max)
    darkened = np.abs(rgb - plain).max(axis=-1) > 0.05
    assert (on_ball & darkened).sum() > 20
    assert (on_ball & ~darkened).sum() > 20  # its far side, out of the light anyway


@pytest.mark.parametrize("seed", range(4))
def test_gl_matches_the_ray_caster_with_shadows(require_gl, seed):
    """Random boxes, spheres, cylinders and cones on a ground plane, lit from a random
    direction above the horizon: the two renderers shade the same pixels the same, shadows
    included (a pixel centre on a shadow's or a face's edge may go either way)."""
    from test_render import random_camera, random_scene

    rng = np.random.default_rng(seed)
    parts = [GROUND, *random_scene(rng)]
    camera = random_camera(rng, 48, 40, "z")
    azimuth, elevation = rng.uniform(-np.pi, np.pi), rng.uniform(0.3, 1.3)
    settings = replace(SHADOWS, light=(math.cos(elevation) * math.cos(azimuth),
                                       math.cos(elevation) * math.sin(azimuth),
                                       math.sin(elevation)), ambient=0.2)
    renderer = Renderer(settings)
    rgb, _ = renderer.render(parts, camera)
    renderer.release()
    ref, _ = raycast(parts, camera, settings)
    plain, _ = raycast(parts, camera, replace(settings, shadows=False))
    assert (np.abs(ref - plain).max(axis=-1) > 0.05).sum() > 5, "no shadow in view"
    assert np.mean(np.abs(rgb - ref).max(axis=-1) > 0.02) <= 0.01


def test_lighting_values_change_the_render_as_the_formula_says(render):
    """Intensity, gain and white balance at once, on the lit floor beside a cube."""
    settings = replace(SHADOWS, intensity=1.3, gain=0.9, red=1.1, blue=0.8)
    rgb, _ = render([GROUND], top_down(), settings)
    lam = 1.0 / math.sqrt(2.0)
    expected = np.array([0.9 * 1.1, 0.9, 0.9 * 0.8]) * np.array(FLOOR) * (0.35 + 1.3 * 0.65 * lam)
    assert np.allclose(rgb[32, 32], expected, atol=1e-4)


def test_azimuth_and_elevation_set_the_light_direction():
    settings = RenderSettings().with_values({"azimuth": 0.5, "elevation": 0.25})
    x, y, z = settings.direction
    assert math.atan2(y, x) == pytest.approx(0.5) and math.asin(z) == pytest.approx(0.25)
    # Only one given: the other is the fixed light's.
    keep = RenderSettings(light=(0.0, 1.0, 1.0)).with_values({"azimuth": 0.0})
    assert keep.direction == pytest.approx((math.sqrt(0.5), 0.0, math.sqrt(0.5)))


# --- the sheen --------------------------------------------------------------------------------


def test_the_sheen_adds_its_grey_to_every_part_and_not_to_the_background(render):
    """On the lit floor, the shadowed floor and the cube's top alike, a sheen adds the same
    grey, times the gain and white balance; the background keeps its colour."""
    cube = Part("box", np.eye(4), (0.9, 0.1, 0.1))
    small = Part("box", translation(0.0, 0.0, -0.1) @ scaling(5.0, 5.0, 0.1), FLOOR)
    balanced = replace(SHADOWS, gain=0.9, red=1.1, blue=0.8)
    plain, _ = render([small, cube], top_down(), balanced)
    rgb, _ = render([small, cube], top_down(), replace(balanced, sheen=0.07))
    grey = 0.07 * np.array([0.9 * 1.1, 0.9, 0.9 * 0.8])
    for row, column in [(32, 12), (32, 22), (32, 32)]:  # lit floor, its shadow, the cube
        assert np.allclose(rgb[row, column] - plain[row, column], grey, atol=1e-4)
    assert np.allclose(rgb[1, 1], plain[1, 1], atol=1e-6)  # (-3.1, 3.1): past the floor
    lam = 1.0 / math.sqrt(2.0)
    floor = np.array(FLOOR) * (0.35 + 0.65 * lam) + 0.07
    assert np.allclose(rgb[32, 12], floor * np.array([0.9 * 1.1, 0.9, 0.9 * 0.8]), atol=1e-4)


@pytest.mark.parametrize("seed", range(2))
def test_gl_matches_the_ray_caster_with_a_sheen(require_gl, seed):
    """Random scenes with shadows, a white balance and a sheen: the GL renderer (the sheen
    read from the Lighting block) and the ray caster (its own sum) shade alike, and the sheen
    changes what both draw."""
    from test_render import random_camera, random_scene

    rng = np.random.default_rng(10 + seed)
    parts = [GROUND, *random_scene(rng)]
    camera = random_camera(rng, 48, 40, "z")
    settings = replace(SHADOWS, ambient=0.5, sheen=0.06, gain=1.1, red=0.9, blue=1.2)
    renderer = Renderer(SHADOWS)
    rgb, _ = renderer.render(parts, camera, settings)
    without, _ = renderer.render(parts, camera, replace(settings, sheen=0.0))
    renderer.release()
    ref, depth = raycast(parts, camera, settings)
    assert np.mean(np.abs(rgb - ref).max(axis=-1) > 0.02) <= 0.01
    drawn = depth < camera.depth_max
    assert drawn.sum() > 100
    assert np.allclose((rgb - without)[drawn].mean(axis=0), 0.06 * np.array([0.99, 1.1, 1.32]),
                       atol=1e-3)


SHEEN_STEP = "    step render.gain = 0.03\n"


@pytest.fixture(scope="module")
def sheen_setting(require_gl, tmp_path_factory):
    """The latent-lighting fixture with a latent sheen as well."""
    text = MODEL.read_text()
    assert SHEEN_STEP in text
    text = text.replace("    shadows = true\n",
                        "    shadows = true\n    sheen : interval(0, 0.2) ~ uniform(0, 0.2)\n")
    text = text.replace(SHEEN_STEP, SHEEN_STEP + "    step render.sheen = 0.02\n")
    return _observed_setting(compile_model(text, MODEL), seed=5)


def _observed_setting(model, seed, lighting=None):
    """A prior scene of two or more objects and its observations by SPECS: (model, renderer,
    observations, truth, noise), the render group's noise updated by ``lighting``."""
    renderer = Renderer(model.render)
    rng = np.random.default_rng(seed)
    truth = sample_objects(model, rng)
    while len(truth) < 2:
        truth = sample_objects(model, rng)
    noise = sample_noise(model, rng)
    if lighting:
        noise[RENDER_GROUP].update(lighting)
    frames = render_observations(model, truth, noise, SPECS, renderer, rng)
    return model, renderer, Observations(MODEL.parent, frames), truth, noise


def test_a_latent_sheen_compiles_and_is_drawn_from_its_prior(sheen_setting):
    model, _, _, _, noise = sheen_setting
    assert "sheen" in [p.name for p in model.render.latent]
    assert 0.0 <= noise[RENDER_GROUP]["sheen"] <= 0.2


def test_fast_and_reference_scores_agree_with_a_latent_sheen(sheen_setting):
    model, renderer, obs, truth, noise = sheen_setting
    fast = _agree_on_prior_draws(model, renderer, obs, seed=2, draws=4)
    # A move of the sheen alone re-lights every pixel: the scorer must not piece the
    # proposal together from its parent's pixels.
    trace = Sampler(model, fast, np.random.default_rng(3)).make_trace(truth, noise)
    moved = {k: dict(v) for k, v in noise.items()}
    moved[RENDER_GROUP]["sheen"] = 0.2 - noise[RENDER_GROUP]["sheen"] / 2
    ref = ReferenceScorer(model, obs, renderer)
    _agree(fast.evaluate(truth, trace, moved)[0], ref.evaluate(truth, noise=moved)[0])


def test_simulate_draws_the_sheen(require_gl):
    """``sppl simulate``'s rendering (render_observations) draws a fixed sheen: the same
    scene is brighter by it on every part's pixel."""
    plain = compile_model(RENDER_MODEL.format(body="ambient = 0.5"), "m.scn")
    sheen = compile_model(RENDER_MODEL.format(body="ambient = 0.5\n sheen = 0.08"), "m.scn")
    assert sheen.render.sheen == 0.08 and not sheen.render.latent
    spec = CameraSpec(_camera("c", 32, 32, (2.0, -2.0, 1.5)), ("rgb",))
    images = []
    for model in (plain, sheen):
        objects = (make_object(model, model.classes[0], {"x": 0.0}),)
        renderer = Renderer(model.render)
        noise = {"image": {"sigma": 0.0}}
        images.append(render_observations(model, objects, noise, [spec], renderer,
                                          np.random.default_rng(0))[0].rgb)
        renderer.release()
    difference = images[1] - images[0]
    on_cube = np.abs(difference).max(axis=-1) > 1e-6
    assert on_cube.sum() > 20
    assert np.allclose(difference[on_cube], 0.08, atol=1e-5)


# --- the fast scorer with latent lighting and shadows -----------------------------------------

SPECS = [
    CameraSpec(_camera("a", 48, 48, (3.0, -2.6, 2.4)), ("rgb",)),
    CameraSpec(_camera("b", 40, 32, (-3.2, -1.6, 2.6)), ("rgb",)),
]


@pytest.fixture(scope="module")
def setting(require_gl):
    # A light low in the sky, whose shadows reach well beyond the objects.
    return _observed_setting(load_model(MODEL), seed=0,
                             lighting={"elevation": 0.6, "azimuth": 2.5})


def _agree(fast, ref):
    for key in ref:
        assert fast[key][1] == pytest.approx(ref[key][1], rel=1e-4, abs=1e-6)


def _agree_on_prior_draws(model, renderer, obs, seed, draws):
    """The fast path's scores against the reference's on prior draws of scenes and lighting;
    the fast scorer."""
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    assert fast.pixels is not None
    rng = np.random.default_rng(seed)
    for _ in range(draws):
        objects, noise = sample_objects(model, rng), sample_noise(model, rng)
        _agree(fast.evaluate(objects, noise=noise)[0], ref.evaluate(objects, noise=noise)[0])
    return fast


def test_fast_and_reference_scores_agree_under_random_lighting(setting):
    model, renderer, obs, _, _ = setting
    _agree_on_prior_draws(model, renderer, obs, seed=1, draws=6)


def _full_terms(scorer, trace):
    """Per camera, the whole image of a trace's per-pixel terms, rendered from nothing."""
    settings = scorer.settings_for(trace.noise)
    blocks, _ = scorer.pixels.render([scorer._drawn(trace.objects)],
                                     [scorer._lighting(trace.objects, settings)])
    return [_dense(block, camera) for block, camera in zip(blocks[0], scorer.pixels.cameras)]


def _proposals_match_full_renders(setting, sweeps=4):
    """Along a chain, every object and jump proposal is scored incrementally from its
    state; the per-pixel terms it pieces together equal a whole render's. The largest
    difference, and how many proposals were scored from their parent."""
    model, renderer, obs, truth, noise = setting
    fast = Scorer(model, obs, renderer)
    sampler = Sampler(model, fast, np.random.default_rng(3))
    trace = sampler.make_trace(truth, noise)
    worst, incremental = 0.0, 0
    for _ in range(sweeps):
        proposals = [moves.propose_parameters(model, trace, k, block, sampler.rng)
                     for k in range(len(trace.objects))
                     for block in moves.parameter_blocks(trace.objects[k].cls)]
        proposals += [sampler.propose_jump(trace) for _ in range(3)]
        for p in proposals:
            if p is None or not all(math.isfinite(o.log_prior) for o in p.changed):
                continue
            _, renders = fast.evaluate(p.objects, trace, p.noise)
            incremental += renders.pixels.parent is not None
            pieced = [_dense(b, c) for b, c in zip(renders.pixels.materialise(),
                                                   fast.pixels.cameras)]
            whole = _full_terms(fast, p)
            for a, b in zip(pieced, whole):
                worst = max(worst, float(np.abs(a - b).max()))
        trace = sampler.sweep(trace)
    return worst, incremental


def test_incremental_scoring_with_shadows_equals_full_renders(setting):
    worst, incremental = _proposals_match_full_renders(setting)
    assert incremental > 10
    assert worst <= 1e-5


def test_incremental_scoring_without_the_shadows_rectangles_is_caught(setting, monkeypatch):
    """Re-rendering only the moved objects' own rectangles misses their shadows on the
    floor: the pieced terms then differ from a whole render's."""
    monkeypatch.setattr(Scorer, "_shadow_rects",
                        lambda self, changed, objects, old, settings: [None] * len(self.frames))
    worst, _ = _proposals_match_full_renders(setting)
    assert worst > 1e-3


# --- the lighting moves -----------------------------------------------------------------------


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_recovers_the_lighting_priors(false_alarm):
    """No observations: the chain's lighting values follow their priors (KS tests, decided
    with the rest of the report by Holm's correction at the test's false-alarm rate)."""
    model = verify.with_prior_noise_steps(load_model(MODEL))
    report = verify.prior_recovery(model, sweeps=4000, seed=2, alpha=false_alarm)
    for name in ("ambient", "intensity", "azimuth", "elevation", "gain"):
        row = report.row(f"{RENDER_GROUP}.{name}")
        assert row.p_value is not None, row.observed  # tested, not left out as too short
    assert report.passed, report.table()


def _without_jacobian(propose):
    """A lighting move stepping intensity and gain on the log scale, x' = x exp(0.3 z), with
    the ratio of a symmetric step (0) where its Jacobian x'/x belongs: wrong."""

    def wrong(model, trace, kind, name, rng, factor=1.0):
        if kind != RENDER_GROUP or name not in ("intensity", "gain"):
            return propose(model, trace, kind, name, rng, factor)
        noise = {k: dict(v) for k, v in trace.noise.items()}
        noise[kind][name] *= math.exp(0.3 * float(rng.standard_normal()))
        return moves.Proposal("render", kind, trace.objects, noise, ())

    return wrong


def test_a_lighting_move_with_a_wrong_ratio_is_caught(monkeypatch):
    """The same run as above with the wrong move fails prior recovery on what it moves."""
    model = verify.with_prior_noise_steps(load_model(MODEL))
    monkeypatch.setattr(moves, "propose_noise", _without_jacobian(moves.propose_noise))
    report = verify.prior_recovery(model, sweeps=4000, seed=2)
    failed = {r.quantity for r in report.failures}
    assert {f"{RENDER_GROUP}.intensity", f"{RENDER_GROUP}.gain"} & failed, report.table()


def test_lighting_moves_and_their_reverses(require_gl):
    report = verify.move_checks(load_model(MODEL), states=10, seed=1)
    assert any(r.quantity.startswith("render:") for r in report.rows)
    assert report.passed, report.table()


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH)
def test_geweke_with_latent_lighting_and_shadows(require_gl, false_alarm):
    """The chains' lighting values stay at the prior when each sweep's observations are
    drawn from the current state (Holm, at the test's false-alarm rate)."""
    report = verify.geweke(load_model(MODEL), chains=40, length=10, seed=3, mc_draws=2000,
                           alpha=false_alarm)
    assert report.passed, report.table()


# --- lighting in the run's files --------------------------------------------------------------


def test_lighting_is_in_the_samples_the_summary_the_posterior_and_a_resumed_run(
        setting, tmp_path):
    from sppl.output.posterior import write_posterior
    from sppl.runs.run import run_chain

    model, _, obs, _, _ = setting
    reference = run_chain(model, obs, tmp_path / "whole", steps=8, seed=4, progress=False)
    samples = read_samples(tmp_path / "whole" / "samples.jsonl")
    assert set(samples[-1]["noise"][RENDER_GROUP]) == {"ambient", "intensity", "azimuth",
                                                      "elevation", "gain"}
    assert "gain" in reference.summary["noise"][RENDER_GROUP]
    assert reference.summary["acceptance"]["render"]["proposed"] > 0
    half = tmp_path / "half"
    run_chain(model, obs, half, steps=4, seed=4, progress=False)
    run_chain(model, obs, half, steps=8, seed=4, progress=False, resume=True)
    assert read_samples(half / "samples.jsonl") == samples
    pytest.importorskip("xarray")
    from sppl.output.posterior import open_posterior

    tree = open_posterior(write_posterior(tmp_path / "whole", tmp_path / "posterior.nc"))
    assert f"{RENDER_GROUP}_gain" in tree["posterior"]


# --- the language -----------------------------------------------------------------------------

RENDER_MODEL = """
class cube {{
    count ~ poisson(1)
    x : real ~ uniform(-1, 1)
    geometry box(0.5, 0.5, 0.5) at (x, 0) colour rgb(0.5, 0.2, 0.2)
}}
sensor image {{
    likelihood gaussian
    sigma : positive ~ gamma(2, 0.05)
}}
render {{
{body}
}}
"""


def _errors(body):
    with pytest.raises(ModelErrors) as caught:
        compile_model(RENDER_MODEL.format(body=body), "m.scn")
    return str(caught.value)


def test_render_settings_and_lighting_parameters_compile():
    model = compile_model(RENDER_MODEL.format(body="shadows = true\n intensity = 1.2\n"
                                              "gain : positive ~ gamma(50, 0.02)"), "m.scn")
    assert model.render.shadows and model.render.intensity == 1.2
    assert [p.name for p in model.render.latent] == ["gain"]
    assert model.noise_groups[-1][0] == RENDER_GROUP
    plain = compile_model(RENDER_MODEL.format(body="ambient = 0.3"), "m.scn")
    assert not plain.render.shadows and not plain.render.latent
    assert [g for g, _ in plain.noise_groups] == ["image"]


@pytest.mark.parametrize("body, message", [
    ("ambinet : interval(0, 1) ~ beta(4, 6)",
     "m.scn:12:1: the render block has no lighting parameter `ambinet` (did you mean `ambient`?)"),
    ("ambient : positive ~ gamma(2, 0.2)", "`ambient` lies in [0, 1]: its domain must too"),
    ("gain : real ~ normal(1, 0.1)", "`gain` is not negative"),
    ("shadows = yes", "`shadows` is `true` or `false`"),
    ("gain = 1.1\n gain : positive ~ gamma(50, 0.02)", "`gain` is already a latent lighting"),
    ("intensity = -1", "`intensity` lies in [0, inf), got -1"),
    ("sheen = 1.5", "`sheen` lies in [0, 1], got 1.5"),
    ("sheen = -0.05", "`sheen` lies in [0, 1], got -0.05"),
    ("sheen : positive ~ gamma(2, 0.02)", "`sheen` lies in [0, 1]: its domain must too"),
    ("shen = 0.05", "unknown render setting `shen` (did you mean `sheen`?)"),
])
def test_bad_render_blocks_are_one_line_errors(body, message):
    assert message in _errors(body)


# --- a colour near the palette's, under another light -----------------------------------------

PALETTE_MODEL = """
colours palette {{
    brown = rgb(0.50, 0.30, 0.12)
    rust  = rgb(0.62, 0.32, 0.11)
    olive = rgb(0.40, 0.40, 0.10)
}}
colours {{
    floor = rgb(0.60, 0.60, 0.60)
}}
class cube {{
    count ~ poisson(1)
    x : real ~ uniform(-1, 1)
    y : real ~ uniform(-1, 1)
    c : colour ~ categorical(palette)
    geometry box(0.6, 0.6, 0.6) at (x, y) colour c
}}
ground colour floor size 4
sensor image {{
    likelihood gaussian
    sigma : positive ~ gamma(2, 0.02)
}}
render {{
    background = rgb(0.5, 0.5, 0.5)
    ambient = 0.35
    light = (0.4, -0.3, 1)
{lighting}
}}
inference {{
    step x = 0.05
    step y = 0.05
    step image.sigma = 0.005
}}
"""

# What the camera saw: a light 15% brighter than the model's and a warmer white balance.
SEEN = {"intensity": 1.15, "red": 1.08, "blue": 0.92}
LATENT = """
    intensity : positive ~ gamma(25, 0.04)
    red : positive ~ gamma(100, 0.01)
    blue : positive ~ gamma(100, 0.01)
"""


def _colour_setting():
    fixed = compile_model(PALETTE_MODEL.format(lighting=""), "fixed.scn")
    latent = compile_model(PALETTE_MODEL.format(lighting=LATENT), "latent.scn")
    renderer = Renderer(fixed.render)
    truth = (make_object(fixed, fixed.classes[0], {"x": 0.1, "y": -0.2, "c": "brown"}),)
    parts = [*fixed.static_parts, *truth[0].parts]
    seen = replace(fixed.render, **SEEN)
    frames = []
    for spec in [CameraSpec(_camera("c", 48, 48, (2.6, -2.2, 2.2)), ("rgb",))]:
        rgb, _ = renderer.render(parts, spec.camera, seen)
        from sppl.data.observations import Frame

        frames.append(Frame(camera=spec.camera, rgb=rgb))
    return fixed, latent, renderer, Observations(Path("."), frames)


def _colour_after_chain(model, renderer, obs, seed=0, sweeps=60):
    """The cube's colour after a chain started from the true position, a palette colour
    other than the truth, and the model's own default lighting."""
    scorer = Scorer(model, obs, renderer)
    sampler = Sampler(model, scorer, np.random.default_rng(seed))
    start = (make_object(model, model.classes[0], {"x": 0.1, "y": -0.2, "c": "olive"}),)
    noise = {"image": {"sigma": 0.02}}
    if model.render.latent:
        noise[RENDER_GROUP] = {"intensity": 1.0, "red": 1.0, "blue": 1.0}
    trace = sampler.make_trace(start, noise)
    colours = []
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
        colours.append(trace.objects[0].values["c"] if len(trace.objects) == 1 else None)
    return colours, trace


def test_a_latent_lighting_keeps_the_colour_that_a_fixed_one_flips(require_gl):
    """A brown cube seen under a brighter, warmer light than the model's: with its lighting
    fixed the model explains the brighter pixels by the brighter palette colour (rust); with
    intensity and white balance latent, the floor's known grey pins the light down and the
    cube stays brown. First the exact scores, then the sampler's own choice."""
    fixed, latent, renderer, obs = _colour_setting()

    def score(model, c, lighting=None):
        scorer = Scorer(model, obs, renderer)
        objects = (make_object(model, model.classes[0], {"x": 0.1, "y": -0.2, "c": c}),)
        noise = {"image": {"sigma": 0.02}}
        if lighting is not None:
            noise[RENDER_GROUP] = lighting
        stats, _ = scorer.evaluate(objects, noise=noise)
        return scorer.log_likelihood(stats, noise)

    assert score(fixed, "rust") > score(fixed, "brown")
    assert score(latent, "brown", SEEN) > score(latent, "rust", SEEN)

    flipped, _ = _colour_after_chain(fixed, renderer, obs)
    kept, trace = _colour_after_chain(latent, renderer, obs)
    assert flipped[-20:] == ["rust"] * 20
    assert kept[-20:] == ["brown"] * 20
    assert trace.noise[RENDER_GROUP]["intensity"] == pytest.approx(1.15, abs=0.1)
