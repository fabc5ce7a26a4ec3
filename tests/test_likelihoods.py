"""Sensor likelihoods and the scorer, against a plain scipy computation of the same density."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats
from toys import gaussian_model

from sppl.data.observations import load_observations
from sppl.errors import SpplError
from sppl.model.likelihoods import Gaussian, available_likelihoods, get_likelihood
from sppl.model.simulate import objects_from_dict
from sppl.render import Renderer
from sppl.scoring.scorer import Scorer


def test_gaussian_matches_scipy_and_masks_missing_pixels():
    rng = np.random.default_rng(0)
    rendered = rng.uniform(1, 5, size=(6, 7)).astype(np.float32)
    observed = rendered + rng.normal(0, 0.3, size=rendered.shape).astype(np.float32)
    valid = rng.random(rendered.shape) > 0.3
    g = Gaussian()
    s = g.statistics(observed, rendered, valid)
    expected = stats.norm.logpdf(observed[valid], rendered[valid], 0.25).sum()
    assert s[0] == valid.sum()
    assert g.log_prob(s, {"sigma": 0.25}) == pytest.approx(expected, rel=1e-6)
    # RGB: no mask, every channel of every pixel counts.
    rgb_r, rgb_o = rng.random((4, 5, 3)), rng.random((4, 5, 3))
    s = g.statistics(rgb_o, rgb_r, None)
    assert g.log_prob(s, {"sigma": 0.1}) == pytest.approx(
        stats.norm.logpdf(rgb_o, rgb_r, 0.1).sum(), rel=1e-9
    )


# The sample sd of n = 40,000 normal draws has a relative standard error sqrt(1 / 2n) = 0.0035:
# 2% is 5.7 of them, a two-sided rate of 1.5e-8.
@pytest.mark.false_alarm(1.5e-8)
def test_gaussian_noise_has_the_declared_scale():
    rendered = np.zeros((200, 200), dtype=np.float32)
    noisy = Gaussian().sample(rendered, {"sigma": 0.05}, np.random.default_rng(1))
    assert noisy.std() == pytest.approx(0.05, rel=0.02)


def test_registry_finds_by_name_and_reports_unknown_names(registered):
    assert "gaussian" in available_likelihoods()
    assert isinstance(get_likelihood("gaussian"), Gaussian)
    with pytest.raises(SpplError, match="unknown likelihood 'gausian'.*gaussian"):
        get_likelihood("gausian")

    class Laplace(Gaussian):
        def log_prob(self, stats_, noise):  # not a real Laplace: only the lookup matters here
            return 0.0

    registered("test-laplace", Laplace)
    assert isinstance(get_likelihood("test-laplace"), Laplace)


def test_scorer_equals_reference_scoring_on_the_example(root, require_gl):
    """The fast path (GL render, cached statistics) against numpy/scipy scoring of the same
    renders, on the shipped example's true scene, with Gaussian likelihoods on both sensors
    (the shipped model's depth mixture has its own twin tests, tests/test_robust.py)."""
    model = gaussian_model(root, "shapes.scn")
    obs = load_observations(root / "examples" / "three_shapes" / "obs")
    truth = json.loads((root / "examples" / "three_shapes" / "scene.json").read_text())
    objects = objects_from_dict(model, truth)
    renderer = Renderer(model.render)
    scorer = Scorer(model, obs, renderer)
    stats_, renders = scorer.evaluate(objects)
    noise = truth["noise"]
    fast = scorer.log_likelihood(stats_, noise)
    parts = [p for o in objects for p in o.parts]
    reference = 0.0
    for frame in obs.frames:
        rgb, depth = renderer.render(parts, frame.camera)
        if frame.rgb is not None:
            reference += stats.norm.logpdf(frame.rgb, rgb, noise["image"]["sigma"]).sum()
        if frame.depth is not None:
            v = frame.depth_valid
            reference += stats.norm.logpdf(frame.depth[v], depth[v], noise["depth"]["sigma"]).sum()
    assert fast == pytest.approx(reference, rel=1e-6)
    # The true scene explains the observations better than the empty one.
    assert fast > scorer.log_likelihood(scorer.statistics(()), noise) + 1000


def test_gaussian_statistics_sum_in_float64():
    """A 640x480 RGB residual, float32 as renders are: the sum of squares is the exact one to
    double rounding. Summed in float32 these are 1.4 nats off at sigma 0.05 (124 at 1080p)."""
    rng = np.random.default_rng(7)
    rendered = rng.random((480, 640, 3), dtype=np.float32)
    observed = (rendered + rng.normal(0, 0.05, rendered.shape)).astype(np.float32)
    n, ssr = Gaussian().statistics(observed, rendered, None)
    exact = math.fsum((observed.astype(np.float64) - rendered.astype(np.float64)).ravel() ** 2)
    assert n == rendered.size
    assert abs(ssr - exact) <= 1e-12 * exact
    float32_sum = float(np.dot((observed - rendered).ravel(), (observed - rendered).ravel()))
    assert abs(float32_sum - exact) > 1e-9 * exact  # the error the float64 sum removes


@pytest.mark.parametrize("sigma", [1e-200, 1e-160, 5e-324, 1e-100, 1e100, 1e160, 1e300])
def test_gaussian_scores_tiny_and_huge_scales_without_exceptions(sigma):
    """sigma * sigma underflows below 1e-154 and overflows above 1e154: scored through
    log sigma, the density is finite or -inf, and where finite it is the exact value."""
    g = Gaussian()
    for n, ssr in ((10.0, 0.0), (10.0, 1e-300), (10.0, 2.5), (10.0, 1e300)):
        value = g.log_prob(np.array([n, ssr]), {"sigma": sigma})
        log_quad = (math.log(ssr) - 2.0 * math.log(sigma)) if ssr else -math.inf
        if log_quad > 709.0:
            assert value == -math.inf, (n, ssr)
            continue
        expected = (-0.5 * n * (math.log(2 * math.pi) + 2 * math.log(sigma))
                    - 0.5 * math.exp(log_quad))
        assert math.isfinite(value) and value == pytest.approx(expected, rel=1e-12), (n, ssr)


def test_gaussian_scale_outside_its_domain_has_no_density():
    g = Gaussian()
    stats_ = np.array([4.0, 1.0])
    for sigma in (0.0, -1.0, math.inf):
        assert g.log_prob(stats_, {"sigma": sigma}) == -math.inf
    assert math.isnan(g.log_prob(stats_, {"sigma": math.nan}))
    assert g.log_prob(np.array([0.0, 0.0]), {"sigma": 0.0}) == 0.0  # nothing observed


# -- which GL-side statistics serve a likelihood -------------------------------------------------

def test_the_shipped_likelihoods_declare_their_gl_statistics():
    from sppl.model.gl_statistics import registered_gl_statistics
    from sppl.model.likelihoods import gpu_statistics
    from sppl.model.robust import Mixture, StudentT, _PerPixel

    found = registered_gl_statistics()
    assert found["squared_residual"].reference is Gaussian.statistics
    assert not found["squared_residual"].per_pixel and found["squared_residual"].shader is None
    assert found["pixel_log_density"].reference is _PerPixel.statistics
    assert found["pixel_log_density"].shader == "likelihood.glsl"
    assert gpu_statistics(Gaussian()) == "squared_residual"
    assert gpu_statistics(Mixture()) == gpu_statistics(StudentT()) == "pixel_log_density"
    assert gpu_statistics(get_likelihood("mixture", {"inlier": "laplace"})) == "pixel_log_density"


def test_a_subclass_that_redefines_what_the_gl_side_computes_is_scored_in_numpy():
    from sppl.model.likelihoods import gpu_statistics
    from sppl.model.robust import Mixture, StudentT

    class OwnStatistics(Gaussian):
        def statistics(self, observed, rendered, valid=None):
            return super().statistics(observed, rendered, valid)

    class Declared(OwnStatistics):
        gl_statistics = "squared_residual"  # its author vouches they are the same

    class OwnLogProb(Gaussian):
        def log_prob(self, stats, noise):
            return super().log_prob(stats, noise) - 1.0

    class NoneDeclared(Gaussian):
        gl_statistics = None

    class OwnDensity(StudentT):
        def pixel_log_density(self, *args, **kwargs):
            return super().pixel_log_density(*args, **kwargs)

    class OwnUniforms(Mixture):
        def uniforms(self, values, k, high):
            return super().uniforms(values, k, high)

    class OwnSampling(Mixture):
        def sample(self, rendered, noise, rng, depth_max=None):
            return super().sample(rendered, noise, rng, depth_max)

    class PerPixelGaussian(Gaussian):
        per_pixel = True  # statistics of another shape than the sums

    assert gpu_statistics(OwnStatistics()) is None
    assert gpu_statistics(Declared()) == "squared_residual"
    assert gpu_statistics(OwnLogProb()) == "squared_residual"
    assert gpu_statistics(NoneDeclared()) is None
    assert gpu_statistics(OwnDensity()) is None
    assert gpu_statistics(OwnUniforms()) is None
    assert gpu_statistics(OwnSampling()) == "pixel_log_density"
    assert gpu_statistics(PerPixelGaussian()) is None


def test_gl_statistics_are_registered_once_and_declared_by_a_registered_name():
    from sppl.model.gl_statistics import register_gl_statistics, registered_gl_statistics
    from sppl.model.likelihoods import gpu_statistics

    with pytest.raises(SpplError, match="already registered"):
        register_gl_statistics("squared_residual", Gaussian.statistics)
    with pytest.raises(SpplError, match="shader"):
        register_gl_statistics("test-no-shader", Gaussian.statistics, per_pixel=True)
    assert "test-no-shader" not in registered_gl_statistics()

    class Misspelt(Gaussian):
        gl_statistics = "squared_residuals"

    with pytest.raises(SpplError, match="'squared_residuals'.*squared_residual"):
        gpu_statistics(Misspelt())
