"""The robust likelihoods (sppl/model/robust.py): their numpy densities against scipy, their samplers
against their densities, their GL-side terms against the numpy twin (absolute nats), and the
sampler's checks with them in the loop.

Statistical tests run at fixed seeds; each states its false-alarm rate over seeds.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from false_alarms import EACH, SLOW_EACH
from scipy import stats
from test_fast_scoring import setting_of

from sppl import cli, verify
from sppl.data.observations import load_observations
from sppl.errors import SpplError
from sppl.infer.chain import Sampler
from sppl.lang import load_model
from sppl.model.likelihoods import get_likelihood, gpu_statistics
from sppl.model.robust import Mixture, StudentT
from sppl.model.simulate import sample_noise, sample_objects
from sppl.model.types import RENDER_GROUP
from sppl.runs.lockstep import sweep_together
from sppl.scoring.scorer import ReferenceScorer, Scorer

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "robust"
# Absolute tolerance of the GL-side log density against the numpy twin, per term: float32
# rounding of per-pixel terms of a few nats, over a few thousand pixels (measured: < 1e-3).
NATS = 1e-2


def _pixels(rng, shape, high=8.0):
    rendered = rng.uniform(0.5, high - 0.5, size=shape)
    observed = rendered + rng.normal(0, 0.05, size=shape)
    outliers = rng.random(shape[:2]) < 0.2
    observed[outliers] = rng.uniform(0, high, size=observed[outliers].shape)
    return observed, rendered


# -- the numpy densities -------------------------------------------------------------------------


def test_depth_mixture_matches_scipy_and_masks_missing_pixels():
    rng = np.random.default_rng(0)
    observed, rendered = _pixels(rng, (9, 11))
    observed[0, :3] = [-0.2, 8.5, 9.0]  # outside the range: the inlier alone scores them
    valid = rng.random(observed.shape) > 0.2
    w, sigma = 0.15, 0.07
    inlier = np.log1p(-w) + stats.norm.logpdf(observed, rendered, sigma)
    in_range = (observed >= 0) & (observed <= 8.0)
    outlier = np.where(in_range, math.log(w / 8.0), -np.inf)
    expected = np.logaddexp(inlier, outlier)[valid].sum()
    lik = Mixture()
    got = lik.log_density(observed, rendered, valid, {"sigma": sigma, "outlier": w}, 8.0)
    assert got == pytest.approx(expected, abs=1e-9)


def test_image_mixture_with_a_laplace_inlier_matches_scipy():
    rng = np.random.default_rng(1)
    rendered = rng.random((5, 6, 3))
    observed = np.clip(rendered + rng.laplace(0, 0.04, rendered.shape), -0.1, 1.1)
    w, sigma = 0.3, 0.04
    inlier = np.log1p(-w) + stats.laplace.logpdf(observed, rendered, sigma).sum(-1)
    in_range = ((observed >= 0) & (observed <= 1)).all(-1)
    expected = np.logaddexp(inlier, np.where(in_range, math.log(w), -np.inf)).sum()
    lik = Mixture(inlier="laplace")
    got = lik.log_density(observed, rendered, None, {"sigma": sigma, "outlier": w})
    assert got == pytest.approx(expected, abs=1e-9)


def test_student_t_matches_scipy_per_value_and_per_pixel():
    rng = np.random.default_rng(2)
    observed, rendered = _pixels(rng, (7, 8))
    lik = StudentT()
    noise = {"sigma": 0.05, "nu": 3.5}
    expected = stats.t.logpdf(observed, 3.5, rendered, 0.05).sum()
    assert lik.log_density(observed, rendered, None, noise, 8.0) == pytest.approx(expected,
                                                                                  abs=1e-9)
    rgb_r, rgb_o = rng.random((3, 4, 3)), rng.random((3, 4, 3))
    expected = sum(stats.multivariate_t.logpdf(rgb_o[i, j], rgb_r[i, j], 0.05**2 * np.eye(3),
                                               df=3.5)
                   for i in range(3) for j in range(4))
    assert lik.log_density(rgb_o, rgb_r, None, noise) == pytest.approx(expected, abs=1e-9)


def test_the_missing_return_term_scores_every_pixel_by_what_the_render_shows():
    """Missing where a surface is in range: log missing; missing where none is: log
    missing_far; a return: log(1 - that) plus the value's density."""
    observed = np.array([[2.0, 0.0, 7.9, 0.0]])
    valid = np.array([[True, False, True, False]])
    rendered = np.array([[2.1, 2.1, 8.0, 8.0]], dtype=np.float32)  # 8.0: nothing in range
    noise = {"sigma": 0.1, "nu": 5.0, "missing": 0.2, "missing_far": 0.7}
    lik = StudentT(returns="modelled")
    near = float(rendered[0, 0])

    def t(o, r):
        return stats.t.logpdf(o, 5.0, r, 0.1)

    expected = (math.log(0.8) + t(2.0, near) + math.log(0.2)
                + math.log(0.3) + t(7.9, 8.0) + math.log(0.7))
    assert lik.log_density(observed, rendered, valid, noise, 8.0) == pytest.approx(expected,
                                                                                   abs=1e-9)
    # Without the term the missing pixels are masked, as the Gaussian masks them.
    masked = StudentT().log_density(observed, rendered, valid, noise, 8.0)
    assert masked == pytest.approx(t(2.0, near) + t(7.9, 8.0), abs=1e-9)


@pytest.mark.parametrize("sigma", [1e-300, 5e-324, 0.0, -1.0, math.nan, math.inf])
def test_extreme_noise_gives_a_number_or_minus_infinity_never_an_error(sigma):
    rng = np.random.default_rng(3)
    observed, rendered = _pixels(rng, (4, 5))
    for lik, noise in ((Mixture(), {"outlier": 0.1}), (StudentT(), {"nu": 2.0}),
                       (Mixture(returns="modelled"), {"outlier": 0.0, "missing": 1.0,
                                                      "missing_far": 0.0})):
        got = lik.log_density(observed, rendered, None, {"sigma": sigma, **noise}, 8.0)
        assert not math.isnan(got)
        assert got < math.inf
    # An outlier share keeps the density finite however small the inlier's scale.
    assert math.isfinite(Mixture().log_density(observed, rendered, None,
                                               {"sigma": 1e-300, "outlier": 0.1}, 8.0))
    assert Mixture().log_density(observed, rendered, None, {"sigma": 0.1, "outlier": 1.2},
                                 8.0) == -math.inf


def test_statistics_are_bound_to_their_noise_values():
    rng = np.random.default_rng(4)
    observed, rendered = _pixels(rng, (4, 5))
    lik = Mixture(outlier=0.1)  # a fixed outlier share is no noise parameter
    assert lik.noise_parameters == ("sigma",)
    s = lik.statistics(observed, rendered, None, {"sigma": 0.2}, depth_max=8.0)
    assert lik.log_prob(s, {"sigma": 0.2}) == s[-1]
    with pytest.raises(SpplError, match="scored at noise"):
        lik.log_prob(s, {"sigma": 0.3})
    with pytest.raises(SpplError, match="at given noise values"):
        lik.statistics(observed, rendered, None)


@pytest.mark.parametrize("options, message", [
    ({"outliers": 0.1}, "did you mean `outlier`"),
    ({"outlier": 1.5}, r"must lie in \[0, 1\]"),
    ({"outlier": -0.1}, r"must lie in \[0, 1\]"),
    ({"inlier": "cauchy"}, "one of gaussian, laplace"),
    ({"missing": 0.1}, "returns = modelled"),
    ({"sigma": 0.0}, "must be positive"),
])
def test_bad_options_are_one_line_errors(options, message):
    with pytest.raises(SpplError, match=message):
        get_likelihood("mixture", options)


# -- the samplers ----------------------------------------------------------------------------------


def test_mixture_samples_outliers_at_their_rate_and_over_the_range():
    """Of 200x200 pixels rendered at 2 m with sigma 1 cm and outlier share 0.3, those more
    than 10 cm off are the outliers outside 2 +- 0.1: 0.3 (1 - 0.2 / 8) of them. Five
    standard errors: a false alarm once in 1.7 million seeds."""
    rendered = np.full((200, 200), 2.0, np.float32)
    noise = {"sigma": 0.01, "outlier": 0.3}
    out = Mixture().sample(rendered, noise, np.random.default_rng(5), depth_max=8.0)
    far = np.abs(out - 2.0) > 0.1
    p = 0.3 * (1 - 0.2 / 8.0)
    assert far.mean() == pytest.approx(p, abs=5 * math.sqrt(p * (1 - p) / far.size))
    assert 0.0 <= out[far].min() and out[far].max() <= 8.0
    # RGB: a pixel is an outlier as a whole, uniform on the unit cube. Its channels are all
    # more than 0.01 off but where one lands within 0.01 by chance (2% each): all or none
    # off in 1 - 0.5 (1 - 0.98^3 - 0.02^3) = 97.1% of pixels, 12 standard errors above 95%
    # (outliers per channel would make it 1 - 0.5 * 3/4 = 62.5%).
    rgb = Mixture().sample(np.full((100, 100, 3), 0.5), {"sigma": 1e-3, "outlier": 0.5},
                           np.random.default_rng(6))
    off = np.abs(rgb - 0.5) > 0.01
    assert (off.any(-1) == off.all(-1)).mean() > 0.95


@pytest.mark.false_alarm(EACH)
def test_student_t_samples_have_its_distribution(false_alarm):
    """Kolmogorov-Smirnov of 4000 depth draws against the Student-t, and of 4000 pixels'
    squared norms against F; each at half the test's false-alarm rate."""
    rendered = np.full((40, 100), 3.0)
    out = StudentT().sample(rendered, {"sigma": 0.05, "nu": 2.5}, np.random.default_rng(7),
                            depth_max=8.0)
    assert stats.kstest(out.ravel(), stats.t(2.5, 3.0, 0.05).cdf).pvalue > false_alarm / 2
    # Per pixel the three channels share one scale: a multivariate t, whose squared norm
    # over 3 sigma^2 is F(3, nu) distributed.
    rgb = StudentT().sample(np.zeros((40, 100, 3)), {"sigma": 0.05, "nu": 2.5},
                            np.random.default_rng(8))
    f = (rgb**2).sum(-1).ravel() / (3 * 0.05**2)
    assert stats.kstest(f, stats.f(3, 2.5).cdf).pvalue > false_alarm / 2


def test_missing_returns_are_sampled_by_what_the_render_shows():
    """Rates 0.1 on the surface half and 0.6 on the far half, 20,000 pixels each; five
    standard errors (false alarm about one in a million seeds)."""
    rendered = np.concatenate([np.full((100, 200), 2.0), np.full((100, 200), 8.0)]).astype("f4")
    noise = {"sigma": 0.05, "outlier": 0.1, "missing": 0.1, "missing_far": 0.6}
    out = Mixture(returns="modelled").sample(rendered, noise, np.random.default_rng(9),
                                              depth_max=8.0)
    for half, p in ((out[:100], 0.1), (out[100:], 0.6)):
        assert np.isnan(half).mean() == pytest.approx(p, abs=5 * math.sqrt(p * (1 - p) / 2e4))


# -- the GL side against the numpy twin ------------------------------------------------------------


def _setting(root, name):
    """tests/test_fast_scoring.py's three cameras and missing depth, for a fixture model."""
    return setting_of(root, load_model(FIXTURES / name))


def _agree(fast_stats, ref_stats, scorer, noise):
    """Per-pixel terms to NATS; a Gaussian's statistics as tests/test_fast_scoring.py
    holds them (1e-4 relative)."""
    assert fast_stats.keys() == ref_stats.keys()
    for key, ref in ref_stats.items():
        if key[1] in scorer.per_pixel:
            assert fast_stats[key][:-1].tolist() == ref[:-1].tolist()  # the same noise values
            assert fast_stats[key][-1] == pytest.approx(ref[-1], abs=NATS), key
        else:
            assert fast_stats[key][0] == ref[0]
            assert fast_stats[key][1] == pytest.approx(ref[1], rel=1e-4, abs=1e-6)
    assert scorer.log_likelihood(fast_stats, noise) == pytest.approx(
        scorer.log_likelihood(ref_stats, noise), rel=1e-4, abs=NATS * len(ref_stats))


MODELS = ["mixture.scn", "student_t.scn", "mixed.scn"]


@pytest.mark.parametrize("name", MODELS)
def test_gl_terms_equal_the_numpy_twin(require_gl, root, name):
    model, renderer, obs, truth, noise = _setting(root, name)
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    assert fast.pixels is not None and fast.per_pixel
    for seed in range(3):
        objects = truth if seed == 0 else sample_objects(model, np.random.default_rng(seed))
        for n in (noise, sample_noise(model, np.random.default_rng(10 + seed))):
            _agree(fast.statistics(objects, n), ref.statistics(objects, n), ref, n)


@pytest.mark.parametrize("name", MODELS)
def test_a_chain_on_the_fast_path_scores_every_state_as_the_reference(require_gl, root, name,
                                                                       monkeypatch):
    """Moves scored incrementally, noise moves re-scored on the GL side: every state the
    chain keeps is the reference's at its noise values."""
    model, renderer, obs, truth, _ = _setting(root, name)
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    used = {"incremental": 0, "rescore": 0}
    incremental, rescore = Scorer._incremental, Scorer.rescore

    def counted_incremental(self, *args):
        found = incremental(self, *args)
        used["incremental"] += found is not None
        return found

    def counted_rescore(self, trace, noise):
        used["rescore"] += 1
        return rescore(self, trace, noise)

    monkeypatch.setattr(Scorer, "_incremental", counted_incremental)
    monkeypatch.setattr(Scorer, "rescore", counted_rescore)
    sampler = Sampler(model, fast, np.random.default_rng(11))
    trace = sampler.initial_trace(truth)
    for _ in range(6):
        trace = sampler.sweep(trace)
        _agree(trace.stats, ref.statistics(trace.objects, trace.noise), ref, trace.noise)
        assert trace.log_likelihood == fast.log_likelihood(trace.stats, trace.noise)
    assert used["incremental"] > 0 and used["rescore"] > 0


def test_chains_in_lockstep_each_score_at_their_own_noise(require_gl, root):
    """Three chains sharing one fast scorer, their hypotheses drawn together at each chain's
    noise values, draw what each draws alone with a scorer of its own."""
    model, renderer, obs, _, _ = _setting(root, "mixture.scn")
    shared = Scorer(model, obs, renderer)
    together = [Sampler(model, shared, np.random.default_rng(s)) for s in range(3)]
    alone = [Sampler(model, Scorer(model, obs, renderer), np.random.default_rng(s))
             for s in range(3)]
    a = [s.initial_trace() for s in together]
    b = [s.initial_trace() for s in alone]
    for _ in range(3):
        a = sweep_together(together, a)
        b = [s.sweep(t) for s, t in zip(alone, b)]
        assert [t.as_dict() for t in a] == [t.as_dict() for t in b]
        assert [t.score for t in a] == pytest.approx([t.score for t in b], rel=1e-12)


def _lit(noise, rng):
    """Noise values with the lighting drawn afresh and the robust ones kept."""
    out = {k: dict(v) for k, v in noise.items()}
    out[RENDER_GROUP].update(ambient=rng.uniform(0.2, 0.6), intensity=rng.uniform(0.6, 1.4),
                             azimuth=rng.uniform(-3, 3), elevation=rng.uniform(0.6, 1.3),
                             gain=rng.uniform(0.8, 1.2), red=rng.uniform(0.8, 1.2),
                             blue=rng.uniform(0.8, 1.2))
    return out


def test_robust_terms_under_latent_lighting_and_shadows_equal_the_reference(require_gl, root):
    """The terms pass with both the likelihood prelude and the lighting block: whole scenes
    under random lighting, a lighting change scored from a parent (a render move, at the
    parent's robust noise values) and a robust noise change re-scored under a lighting that
    is not the model's default (a noise move) are the reference's."""
    model, renderer, obs, truth, noise = _setting(root, "lit_mixture.scn")
    assert model.render.shadows and model.render.latent
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    assert fast.pixels is not None and fast.per_pixel == ["depth", "image"]
    rng = np.random.default_rng(4)
    for seed in range(3):
        objects = truth if seed == 0 else sample_objects(model, rng)
        n = _lit(sample_noise(model, rng), rng)
        _agree(fast.statistics(objects, n), ref.statistics(objects, n), ref, n)
    sampler = Sampler(model, fast, np.random.default_rng(5))
    trace = sampler.make_trace(truth, _lit(noise, rng))
    lit = _lit(trace.noise, rng)  # a render move's proposal
    _agree(fast.evaluate(truth, trace, lit)[0], ref.evaluate(truth, noise=lit)[0], ref, lit)
    rescored = {k: dict(v) for k, v in trace.noise.items()}  # a noise move's proposal
    rescored["image"]["outlier"] *= 0.5
    rescored["depth"]["sigma"] *= 1.5
    stats, _ = fast.rescore(trace, rescored)
    _agree(stats, ref.statistics(truth, rescored), ref, rescored)
    stats, _ = ref.rescore(trace, rescored)
    _agree(stats, ref.statistics(truth, rescored), ref, rescored)


def test_a_chain_with_robust_likelihoods_and_latent_lighting_agrees_on_both_paths(
        require_gl, root, monkeypatch):
    """A few sweeps on each scorer: every proposal scored (object moves from their parent,
    render moves re-rendered at the current robust noise values, noise moves re-scored under
    the current lighting) and every state kept is the reference's, and the same on the fast
    path, at its noise values and lighting."""
    model, renderer, obs, truth, noise = _setting(root, "lit_mixture.scn")
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    scored = {"parameters": 0, "noise": 0, "render": 0}
    evaluate = Sampler.evaluate

    def checked(self, trace, proposal):
        new = evaluate(self, trace, proposal)
        if new is not None:
            scored[proposal.move] = scored.get(proposal.move, 0) + 1
            _agree(new.stats, ref.statistics(new.objects, new.noise), ref, new.noise)
            _agree(fast.statistics(new.objects, new.noise), new.stats, ref, new.noise)
        return new

    monkeypatch.setattr(Sampler, "evaluate", checked)
    for scorer in (fast, ref):
        sampler = Sampler(model, scorer, np.random.default_rng(12))
        trace = sampler.make_trace(truth, _lit(noise, np.random.default_rng(13)))
        for _ in range(2):
            trace = sampler.sweep(trace)
            _agree(trace.stats, ref.statistics(trace.objects, trace.noise), ref, trace.noise)
            assert math.isfinite(trace.score)
    assert scored["parameters"] > 0 and scored["noise"] > 0 and scored["render"] > 0


def test_noise_values_the_gl_side_cannot_hold_go_to_the_reference(require_gl, root):
    """An outlier share of exactly 0 has log 0 in its terms: scored in float64 instead."""
    model, renderer, obs, truth, noise = _setting(root, "mixture.scn")
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    noise = {k: dict(v) for k, v in noise.items()}
    noise["image"]["outlier"] = 0.0
    assert not fast._fast(noise, fast._key(noise))
    _agree(fast.statistics(truth, noise), ref.statistics(truth, noise), ref, noise)


def test_a_subclass_with_another_density_leaves_the_gl_side():
    class Other(Mixture):
        def _value(self, *args):
            return super()._value(*args)

    assert gpu_statistics(Mixture()) == "pixel_log_density"
    assert gpu_statistics(Other()) is None


# -- sppl simulate and sppl verify -----------------------------------------------------------------


def test_sppl_simulate_draws_from_the_robust_likelihoods(require_gl, tmp_path):
    cameras = tmp_path / "cameras.json"
    cameras.write_text(json.dumps({
        "w": 32, "h": 32, "fl_x": 36.0, "fl_y": 36.0, "cx": 16.0, "cy": 16.0, "depth_max": 8.0,
        "frames": [{"name": "both", "modalities": ["rgb", "depth"],
                    "look_at": {"eye": [3.0, -2.5, 2.4], "target": [0, 0, 0.3], "up": [0, 0, 1]}}],
    }))
    for name in ("mixture.scn", "student_t.scn"):
        out = tmp_path / name
        code = cli.main(["simulate", str(FIXTURES / name), "--cameras", str(cameras),
                         "--out", str(out), "--seed", "2"])
        assert code == 0
        frame = load_observations(out).frames[0]
        assert frame.rgb is not None and (~frame.depth_valid).any()  # missing returns


@pytest.mark.parametrize("name", ["balls_mixture.scn", "balls_student_t.scn"])
def test_every_move_and_its_reverse_with_the_robust_likelihood_in_the_loop(require_gl, name):
    """States scored against observations by the fast scorer: noise moves re-score every
    pixel, and their reverses give back the very state (an exact check)."""
    report = verify.move_checks(load_model(FIXTURES / name), states=8, seed=2, size=16)
    assert report.passed, report.table()
    assert any(r.quantity.startswith("noise") for r in report.rows)


def _sbc(name, replicates, alpha):
    return verify.sbc(load_model(FIXTURES / name), replicates=replicates, draws=7, thin=2,
                      seed=8, p_jump=0.5, alpha=alpha)


@pytest.mark.false_alarm(EACH)
def test_sbc_ranks_are_uniform_with_the_mixture(require_gl, false_alarm):
    """Ranks of the count, the balls' values and every noise parameter (the outlier shares
    and missing-return probabilities too): chi-square against uniform, the whole table at
    the test's false-alarm rate (Holm)."""
    report = _sbc("balls_mixture.scn", 60, false_alarm)
    assert report.passed, report.table()


class MisnormalisedMixture(Mixture):
    """A mixture whose outlier term is ten times a uniform density (so it integrates to
    more than one), with the right simulator: a wrong density the language cannot see."""

    def _value(self, dist, in_range, values, k, high):
        return super()._value(dist, in_range, values, k, high / 10.0)


@pytest.mark.false_alarm(EACH)
def test_sppl_verify_passes_with_the_mixture(require_gl, capsys, false_alarm):
    """Every check of `sppl verify`, short runs (the long ones are slow tests below); all of
    the table at the test's family-wise false-alarm rate."""
    code = cli.main(["verify", str(FIXTURES / "balls_mixture.scn"), "--steps", "500",
                     "--geweke-chains", "40", "--geweke-length", "10", "--seed", "0",
                     "--alpha", str(false_alarm)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert re.search(r"^geweke +depth\.missing_far ", out, re.M)
    assert "noise: reverse undoes it" in out


def test_sppl_verify_catches_a_misnormalised_mixture(require_gl, capsys, registered):
    """The deliberately wrong density: Geweke's test names the outlier share (p about 1e-9
    at this seed, where the table's threshold is 1% over all its rows)."""
    registered("misnormalised_mixture", MisnormalisedMixture)
    code = cli.main(["verify", str(FIXTURES / "broken_mixture.scn"), "--steps", "500",
                     "--geweke-chains", "40", "--geweke-length", "8", "--seed", "0"])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "FAIL: " in out and "geweke: depth.outlier" in out.splitlines()[-1]


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH / 2)  # the two cases share one of the slow tests' shares
@pytest.mark.parametrize("name", ["balls_mixture.scn", "balls_student_t.scn"])
def test_sppl_verify_passes_with_each_robust_likelihood_long(require_gl, capsys, name,
                                                             false_alarm):
    code = cli.main(["verify", str(FIXTURES / name), "--steps", "20000",
                     "--geweke-chains", "300", "--geweke-length", "20", "--seed", "1",
                     "--alpha", str(false_alarm)])
    out = capsys.readouterr().out
    assert code == 0, out


@pytest.mark.slow
@pytest.mark.false_alarm(SLOW_EACH)
def test_sbc_ranks_are_uniform_with_student_t(require_gl, false_alarm):
    report = _sbc("balls_student_t.scn", 200, false_alarm)
    assert report.passed, report.table()
