"""Sensor likelihoods and the scorer, against a plain scipy computation of the same density."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from sppl.errors import SpplError
from sppl.lang import load_model
from sppl.likelihoods import Gaussian, available_likelihoods, get_likelihood, register_likelihood
from sppl.observations import load_observations
from sppl.render import Renderer
from sppl.scoring import Scorer
from sppl.simulate import objects_from_dict


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


def test_gaussian_noise_has_the_declared_scale():
    rendered = np.zeros((200, 200), dtype=np.float32)
    noisy = Gaussian().sample(rendered, {"sigma": 0.05}, np.random.default_rng(1))
    assert noisy.std() == pytest.approx(0.05, rel=0.02)


def test_registry_finds_by_name_and_reports_unknown_names():
    assert "gaussian" in available_likelihoods()
    assert isinstance(get_likelihood("gaussian"), Gaussian)
    with pytest.raises(SpplError, match="unknown likelihood 'gausian'.*gaussian"):
        get_likelihood("gausian")

    class Laplace(Gaussian):
        def log_prob(self, stats_, noise):  # not a real Laplace: only the lookup matters here
            return 0.0

    register_likelihood("test-laplace", Laplace)
    assert isinstance(get_likelihood("test-laplace"), Laplace)


def test_scorer_equals_reference_scoring_on_the_example(root, require_gl):
    """The fast path (GL render, cached statistics) against numpy/scipy scoring of the same
    renders, on the shipped example's true scene."""
    model = load_model(root / "models" / "shapes.scn")
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
