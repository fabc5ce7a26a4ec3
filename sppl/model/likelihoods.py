"""Sensor likelihoods: how an observation is distributed around its rendered pseudo-observation.

A likelihood is split in two so that noise moves cost no rendering: ``statistics`` reduces an
(observation, rendering) pair to a few numbers, and ``log_prob`` turns those numbers and the
noise parameters into a log density. For the Gaussian, the statistics are the count of valid
values and the sum of squared residuals, which is all the noise scale ever needs.

Likelihoods are looked up by the name a model file gives (``likelihood gaussian``). The robust
ones, ``mixture`` and ``student_t`` (``sppl.model.robust``), have no sufficient statistics: theirs
are scored at given noise values. Third-party
packages add their own through the ``sppl.likelihoods`` entry-point group: the entry point's
name is the name used in model files, and it points at a class implementing ``Likelihood``.
A likelihood whose statistics the GL side can compute says which (``gl_statistics``, a name
``sppl.model.gl_statistics`` registers), and is then scored without reading renders back.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from importlib.metadata import entry_points
from typing import Protocol

import numpy as np

from ..errors import SpplError
from .gl_statistics import declared_gl_statistics, register_gl_statistics
from .robust import Mixture, StudentT

_LOG_2PI = math.log(2.0 * math.pi)


class Likelihood(Protocol):
    """The interface every sensor likelihood implements.

    A likelihood whose statistics cannot serve every noise value (``sppl.model.robust``'s) sets
    ``per_pixel = True``: its ``statistics`` then also takes the noise values to score at
    and the frame's ``depth_max``, and ``sample`` takes ``depth_max``."""

    #: Names of the noise parameters the model file must give this likelihood a prior for.
    noise_parameters: tuple[str, ...]
    #: Optional: the GL-side computation (``sppl.model.gl_statistics``) that gives the same
    #: statistics as ``statistics``, so that scoring need not read renders back; None or
    #: absent: it reads them back and calls ``statistics``.
    gl_statistics: str | None

    def statistics(
        self, observed: np.ndarray, rendered: np.ndarray, valid: np.ndarray | None
    ) -> np.ndarray:
        """Reduce an observation and its rendering to the numbers ``log_prob`` needs."""

    def log_prob(self, stats: np.ndarray, noise: Mapping[str, float]) -> float:
        """log p(observation | rendering, noise), from ``statistics``' output."""

    def sample(
        self, rendered: np.ndarray, noise: Mapping[str, float], rng: np.random.Generator
    ) -> np.ndarray:
        """Draw an observation around a rendering (used by ``sppl simulate``)."""


# exp of more than this overflows a double.
_LOG_MAX = math.log(np.finfo(float).max)


def gaussian_log_prob(n: float, ssr: float, sigma: float) -> float:
    """log of n independent Normal(0, sigma) densities whose values' squares sum to ssr.

    Scored through log sigma: sigma * sigma underflows to 0 below about 1e-154 and overflows
    above 1e154, where ssr / sigma^2 would divide by zero or lose the value. Here a tiny or huge
    sigma gives a finite value or -inf, never an exception; sigma <= 0 has no density (-inf).
    """
    if n == 0:
        return 0.0  # nothing observed: the likelihood is 1 whatever sigma is
    if math.isnan(sigma):
        return math.nan  # the chain rejects a NaN ratio (sppl.infer.chain)
    if not 0.0 < sigma < math.inf:
        return -math.inf
    log_sigma = math.log(sigma)
    if ssr > 0.0:
        log_quad = math.log(ssr) - 2.0 * log_sigma
        if log_quad > _LOG_MAX:
            return -math.inf
        quad = math.exp(log_quad)
    else:
        quad = 0.0
    return -0.5 * n * (_LOG_2PI + 2.0 * log_sigma) - 0.5 * quad


class Gaussian:
    """Independent Normal(rendered, sigma) noise on every valid value (thesis 3.3.2, 3.3.3).

    For images each colour channel of each pixel is one value; for depth each pixel is one
    value in metres, and pixels whose depth is missing are masked out, never compared.
    """

    noise_parameters = ("sigma",)
    gl_statistics = "squared_residual"

    def __init__(self, **options: float) -> None:
        if options:
            raise SpplError(
                f"the gaussian likelihood takes no options, got {', '.join(sorted(options))}"
            )

    def statistics(self, observed, rendered, valid=None) -> np.ndarray:
        # In float64 throughout: the difference of two float32 values is exact there, and a
        # float32 sum of a 1080p image's 6 million squares is tens of nats off.
        r = np.subtract(observed, rendered, dtype=np.float64)
        if valid is not None:
            r = r[valid]
        r = r.ravel()
        return np.array([r.size, float(np.dot(r, r))])

    def log_prob(self, stats, noise) -> float:
        n, ssr = stats
        return gaussian_log_prob(n, ssr, noise["sigma"])

    def sample(self, rendered, noise, rng) -> np.ndarray:
        eps = rng.standard_normal(rendered.shape).astype(rendered.dtype)
        return rendered + noise["sigma"] * eps


def sample_observation(likelihood: Likelihood, rendered: np.ndarray, noise: Mapping[str, float],
                       rng: np.random.Generator, depth_max: float) -> np.ndarray:
    """``likelihood.sample``, given the sensor's range where the likelihood needs it (an
    outlier is uniform over it)."""
    if getattr(likelihood, "per_pixel", False):
        return likelihood.sample(rendered, noise, rng, depth_max=depth_max)
    return likelihood.sample(rendered, noise, rng)


register_gl_statistics(
    "squared_residual", Gaussian.statistics,
    description="(number of valid values, sum of their squared residuals), summed in float64 "
                "from terms.frag's per-pixel squares",
)


def gpu_statistics(likelihood: Likelihood) -> str | None:
    """The name of the GL-side computation that gives this likelihood's statistics, or None
    if none does (then scoring reads the renders back and calls ``statistics``): the one its
    class declares (``gl_statistics``), unless a subclass changed what that computation stands
    in for (``sppl.model.gl_statistics``)."""
    found = declared_gl_statistics(likelihood)
    return None if found is None else found.name


_BUILTIN: dict[str, Callable[..., Likelihood]] = {
    "gaussian": Gaussian, "mixture": Mixture, "student_t": StudentT,
}
_registry: dict[str, Callable[..., Likelihood]] = dict(_BUILTIN)
_plugins_loaded = False


def register_likelihood(name: str, factory: Callable[..., Likelihood]) -> None:
    """Make a likelihood usable by name in model files (for code that is not an installed
    package; installed packages use the ``sppl.likelihoods`` entry-point group instead)."""
    _registry[name] = factory


def _load_plugins() -> None:
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for ep in entry_points(group="sppl.likelihoods"):
        if ep.name in _registry:
            continue
        try:
            _registry[ep.name] = ep.load()
        except Exception as err:  # a broken plugin must not take sppl down with it
            raise SpplError(f"the likelihood plugin {ep.name!r} ({ep.value}) failed to load: {err}")


def available_likelihoods() -> tuple[str, ...]:
    _load_plugins()
    return tuple(sorted(_registry))


def get_likelihood(name: str, options: Mapping[str, float] | None = None) -> Likelihood:
    if name not in _registry:
        _load_plugins()
    if name not in _registry:
        known = ", ".join(available_likelihoods())
        raise SpplError(f"unknown likelihood {name!r}; known likelihoods: {known}")
    return _registry[name](**dict(options or {}))
