"""Robust sensor likelihoods: an inlier/outlier mixture and Student-t, per pixel.

A rendering is never exactly the observation: cast shadows, glossy highlights, anti-aliased
edges and depth pixels mixed across an edge are off by far more than the sensor's noise. Under
the Gaussian a handful of such pixels inflate the noise scale until the sensor tells nothing;
these likelihoods give each pixel a heavy tail instead, so a few bad pixels cost a bounded
amount each.

Per pixel (for images the three channels of a pixel together, k = 3; for depth, k = 1), with
d = observed - rendered:

- ``mixture``: (1 - outlier) g(d) + outlier u(observed), where the inlier g is a Normal(0,
  sigma) (or, with ``inlier = laplace``, a Laplace with scale sigma) on each of the k values,
  and the outlier u is uniform over the sensor's range: [0, 1] per channel for images,
  [0, depth_max] for depth (3DP3 and Bayes3D model depth so).
- ``student_t``: a k-variate Student-t with scale sigma and ``nu`` degrees of freedom, a
  scale mixture of Normals: a pixel's values are off together, as a shadow makes them.

For depth, ``returns = modelled`` scores missing pixels instead of masking them: where the
rendering has a surface in range (nearer than depth_max) the sensor gives no return with
probability ``missing``, and where it has none with probability ``missing_far``; a pixel with
a return then has the value density above times (1 - that probability).

Unlike the Gaussian's (n, sum of squares), no few numbers are sufficient for these noise
parameters: the per-pixel terms depend on them non-linearly. So a likelihood here is scored
*at* given noise values, and its statistics record them: ``statistics`` gives
``[value of each noise parameter..., log density]``, and ``log_prob`` returns that log density
for those values only (anything else is a scorer's bug, and raises). A noise move therefore
re-scores the hypothesis's pixels (``Scorer.rescore``), which is exact.

This module is the slow, obviously right numpy twin (float64); ``sppl/render/shaders/
likelihood.glsl`` computes the same per-pixel terms on the GL side.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping

import numpy as np
from scipy.special import gammaln

from ..errors import SpplError
from .gl_statistics import register_gl_statistics

_LOG_2PI = math.log(2.0 * math.pi)
# The probabilities a model may fix or give a prior, and the range each must stay in.
_PROBABILITIES = ("outlier", "missing", "missing_far")
_WORDS = {"inlier": ("gaussian", "laplace"), "returns": ("masked", "modelled")}
# The GL-side term each likelihood's shader computes (likelihood.glsl's IMAGE_TERM/DEPTH_TERM).
TERM_MIXTURE_GAUSSIAN, TERM_MIXTURE_LAPLACE, TERM_STUDENT_T = 1, 2, 3


def _depth_max(observed: np.ndarray, depth_max: float | None) -> float:
    if observed.ndim == 3:
        return 1.0
    if depth_max is None:
        raise SpplError("a robust depth likelihood needs the sensor's depth_max")
    return float(depth_max)


class _PerPixel:
    """What the mixture and Student-t share: options, noise bookkeeping, the missing-return
    term and the bound statistics."""

    name = ""
    #: Statistics are scored at given noise values (see the module's docstring).
    per_pixel = True
    _parameters: tuple[str, ...] = ()
    _words: tuple[str, ...] = ("returns",)  # options whose values are words

    def __init__(self, **options) -> None:
        known = (*self._parameters, *self._words, "missing", "missing_far")
        for key, value in options.items():
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1)
                hint = f" (did you mean `{close[0]}`?)" if close else ""
                raise SpplError(f"no option `{key}`{hint}; the options are {', '.join(known)}")
            words = _WORDS.get(key)
            if words is not None:
                if value not in words:
                    raise SpplError(f"the option `{key}` is one of {', '.join(words)}, got "
                                    f"`{value}`")
            elif isinstance(value, str) or not math.isfinite(float(value)):
                raise SpplError(f"the option `{key}` is a number, got `{value}`")
            elif key in _PROBABILITIES and not 0.0 <= float(value) <= 1.0:
                raise SpplError(f"`{key}` is a probability and must lie in [0, 1], got {value:g}")
            elif key in ("sigma", "nu") and not float(value) > 0.0:
                raise SpplError(f"`{key}` must be positive, got {value:g}")
        self.inlier = options.get("inlier", "gaussian")
        self.returns = options.get("returns", "masked") == "modelled"
        if not self.returns and ("missing" in options or "missing_far" in options):
            raise SpplError("`missing` and `missing_far` belong to the missing-return term: "
                            "add the option `returns = modelled`")
        wanted = self._parameters + (("missing", "missing_far") if self.returns else ())
        self.fixed = {k: float(v) for k, v in options.items() if k in wanted}
        #: The noise parameters the model file gives priors for: those no option fixes.
        self.noise_parameters = tuple(p for p in wanted if p not in self.fixed)
        #: The range each noise parameter's domain must stay inside.
        self.noise_supports = {p: ((0.0, 1.0) if p in _PROBABILITIES else (0.0, math.inf))
                               for p in self.noise_parameters}

    # -- noise values ------------------------------------------------------------------------

    def values(self, noise: Mapping[str, float]) -> dict[str, float]:
        """Every parameter's value: the latent ones from ``noise``, the rest fixed."""
        return {**self.fixed, **{p: float(noise[p]) for p in self.noise_parameters}}

    def key(self, noise: Mapping[str, float]) -> tuple[float, ...]:
        return tuple(float(noise[p]) for p in self.noise_parameters)

    def in_support(self, values: Mapping[str, float]) -> bool:
        return all(
            (0.0 <= values[p] <= 1.0) if p in _PROBABILITIES else values[p] > 0.0
            for p in values if p in (*self._parameters, *_PROBABILITIES)
        ) and all(math.isfinite(v) for v in values.values())

    # -- the likelihood protocol -------------------------------------------------------------

    def statistics(self, observed, rendered, valid=None, noise=None, depth_max=None):
        """[noise values..., log density at them]."""
        if noise is None:
            raise SpplError(f"the {self.name} likelihood is scored at given noise values")
        total = self.log_density(observed, rendered, valid, noise, depth_max)
        return np.array([*self.key(noise), total])

    def log_prob(self, stats, noise) -> float:
        stats = np.asarray(stats, dtype=float)
        if tuple(stats[:-1].tolist()) != self.key(noise):
            raise SpplError(f"internal error: {self.name} statistics scored at noise "
                            f"{stats[:-1].tolist()} were asked for {dict(noise)}")
        return float(stats[-1])

    def log_density(self, observed, rendered, valid, noise, depth_max=None) -> float:
        """log p(observed | rendered, noise), summed in float64 (-inf outside the support)."""
        values = self.values(noise)
        if not self.in_support(values):
            return -math.inf
        total = float(np.sum(self.pixel_log_density(observed, rendered, valid, values,
                                                    depth_max)))
        return total if not math.isnan(total) else -math.inf

    def pixel_log_density(self, observed, rendered, valid, values, depth_max=None) -> np.ndarray:
        """Each pixel's log density, (rows, cols) float64: 0 for a missing depth pixel unless
        the missing-return term scores it."""
        high = _depth_max(observed, depth_max)
        o = np.asarray(observed, dtype=np.float64)
        r = np.asarray(rendered, dtype=np.float64)
        image = o.ndim == 3
        d = o - r
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if image:
                dist = np.sum(np.abs(d), axis=-1) if self._l1() else np.sum(d * d, axis=-1)
                in_range = np.all((o >= 0.0) & (o <= 1.0), axis=-1)
                return self._value(dist, in_range, values, 3, high)
            dist = np.abs(d) if self._l1() else d * d
            in_range = (o >= 0.0) & (o <= high)
            value = self._value(dist, in_range, values, 1, high)
            present = np.ones(o.shape, bool) if valid is None else np.asarray(valid, bool)
            if not self.returns:
                return np.where(present, value, 0.0)
            # A surface in range: the rendering is nearer than depth_max (the far value).
            surface = np.asarray(rendered) < np.float32(high)
            m = np.where(surface, values["missing"], values["missing_far"])
            return np.where(present, np.log1p(-m) + value, np.log(m))

    def sample(self, rendered, noise, rng, depth_max=None) -> np.ndarray:
        """An observation around a rendering; with the missing-return term, NaN marks the
        pixels that gave no return."""
        values = self.values(noise)
        r = np.asarray(rendered)
        high = _depth_max(r, depth_max)
        image = r.ndim == 3
        pixels = r.shape[:2]
        k = 3 if image else 1
        out = (r.reshape(*pixels, k) + self._noise(values, (*pixels, k), rng)).astype(r.dtype)
        out = self._outliers(out, values, pixels, high, rng)
        out = out if image else out[..., 0]
        if not image and self.returns:
            surface = r < np.float32(high)
            m = np.where(surface, values["missing"], values["missing_far"])
            out = np.where(rng.random(pixels) < m, np.nan, out).astype(r.dtype)
        return out

    def _outliers(self, out, values, pixels, high, rng):
        return out

    def _l1(self) -> bool:
        return False


register_gl_statistics(
    "pixel_log_density", _PerPixel.statistics, shader="likelihood.glsl", per_pixel=True,
    # Everything the shader's density copies, with the likelihood's own shader_term and
    # uniforms; log_density too, since the GL terms are relative to the empty scene's, which
    # is scored by it.
    methods=("statistics", "log_density", "pixel_log_density", "_value", "_l1", "_constant",
             "uniforms", "shader_term"),
    description="[noise values..., sum of the per-pixel log densities at them], each pixel's "
                "term computed by likelihood.glsl",
)


class Mixture(_PerPixel):
    """Each pixel an inlier around the rendering (probability 1 - outlier) or an outlier
    uniform over the sensor's range (see the module's docstring)."""

    name = "mixture"
    gl_statistics = "pixel_log_density"
    _parameters = ("sigma", "outlier")
    _words = ("inlier", "returns")

    def _l1(self) -> bool:
        return self.inlier == "laplace"

    def _value(self, dist, in_range, values, k, high):
        sigma, w = values["sigma"], values["outlier"]
        log_sigma = math.log(sigma)
        # dist / sigma^2 through logs, so that a sigma whose square underflows gives -inf
        # (or 0 for an exact match) instead of nan.
        power = 1.0 if self._l1() else 2.0
        scaled = np.where(dist > 0.0, np.exp(np.log(dist) - power * log_sigma), 0.0)
        if self._l1():
            inlier = -k * (math.log(2.0) + log_sigma) - scaled
        else:
            inlier = -0.5 * k * _LOG_2PI - k * log_sigma - 0.5 * scaled
        a = np.log1p(-w) + inlier if w < 1.0 else np.full(np.shape(dist), -np.inf)
        b = np.where(in_range, math.log(w) - k * math.log(high), -np.inf) if w > 0.0 else -np.inf
        return np.logaddexp(a, b)

    def _noise(self, values, shape, rng):
        sigma = values["sigma"]
        if self._l1():
            return rng.laplace(0.0, sigma, shape)
        return sigma * rng.standard_normal(shape)

    def _outliers(self, out, values, pixels, high, rng):
        outlier = rng.random(pixels) < values["outlier"]
        uniform = rng.uniform(0.0, high, out.shape).astype(out.dtype)
        return np.where(outlier[..., None], uniform, out)

    def uniforms(self, values, k: int, high: float) -> tuple[float, float, float, float]:
        """likelihood.glsl's parameters (its header says what each is)."""
        sigma, w = values["sigma"], values["outlier"]
        log_w = math.log(w) if w > 0.0 else -math.inf
        log_in = math.log1p(-w) if w < 1.0 else -math.inf
        if self._l1():
            return (1.0 / sigma, log_in - k * math.log(2.0 * sigma), log_w - k * math.log(high),
                    0.0)
        return (0.5 / (sigma * sigma), log_in - 0.5 * k * _LOG_2PI - k * math.log(sigma),
                log_w - k * math.log(high), 0.0)

    @property
    def shader_term(self) -> int:
        return TERM_MIXTURE_LAPLACE if self._l1() else TERM_MIXTURE_GAUSSIAN


class StudentT(_PerPixel):
    """A k-variate Student-t on each pixel's values around the rendering, scale sigma and
    nu degrees of freedom (fixed with the option ``nu = 4``, or latent with a prior)."""

    name = "student_t"
    gl_statistics = "pixel_log_density"
    _parameters = ("sigma", "nu")

    def _value(self, dist, in_range, values, k, high):
        sigma, nu = values["sigma"], values["nu"]
        log_sigma = math.log(sigma)
        scaled = np.where(dist > 0.0, np.exp(np.log(dist) - 2.0 * log_sigma - math.log(nu)), 0.0)
        return self._constant(nu, k) - k * log_sigma - 0.5 * (nu + k) * np.log1p(scaled)

    @staticmethod
    def _constant(nu: float, k: int) -> float:
        return float(gammaln(0.5 * (nu + k)) - gammaln(0.5 * nu) - 0.5 * k * math.log(nu * math.pi))

    def _noise(self, values, shape, rng):
        # A Normal scaled by one chi-square draw per pixel: the multivariate t.
        sigma, nu = values["sigma"], values["nu"]
        scale = np.sqrt(nu / rng.chisquare(nu, shape[:2]))[..., None]
        return sigma * scale * rng.standard_normal(shape)

    def uniforms(self, values, k: int, high: float) -> tuple[float, float, float, float]:
        sigma, nu = values["sigma"], values["nu"]
        return (1.0 / (nu * sigma * sigma), -0.5 * (nu + k),
                self._constant(nu, k) - k * math.log(sigma), 0.0)

    shader_term = TERM_STUDENT_T
