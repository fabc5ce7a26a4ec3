"""The probability distributions a model file can name.

Each distribution samples with an explicit ``numpy.random.Generator`` and returns log densities
(``-inf`` outside its support). Log densities are written out by hand rather than taken from
``scipy.stats`` because they sit on the sampler's hot path, where scipy's argument checking
costs tens of microseconds a call; ``cdf`` uses scipy, since it only serves the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Normal:
    mu: float
    sigma: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.normal(self.mu, self.sigma))

    def log_prob(self, x: float) -> float:
        z = (x - self.mu) / self.sigma
        return -0.5 * z * z - math.log(self.sigma) - 0.5 * _LOG_2PI

    def cdf(self, x):
        return stats.norm.cdf(x, self.mu, self.sigma)

    def support(self) -> tuple[float, float]:
        return (-math.inf, math.inf)

    def __str__(self) -> str:
        return f"normal({self.mu:g}, {self.sigma:g})"


@dataclass(frozen=True)
class Uniform:
    low: float
    high: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))

    def log_prob(self, x: float) -> float:
        if self.low <= x <= self.high:
            return -math.log(self.high - self.low)
        return -math.inf

    def cdf(self, x):
        return stats.uniform.cdf(x, self.low, self.high - self.low)

    def support(self) -> tuple[float, float]:
        return (self.low, self.high)

    def __str__(self) -> str:
        return f"uniform({self.low:g}, {self.high:g})"


@dataclass(frozen=True)
class Gamma:
    """Gamma with shape ``k`` and *scale* ``theta`` (mean ``k * theta``).

    The model language accepts ``gamma(k, theta)`` (scale) or ``gamma(k, rate=beta)``; the rate
    form is converted to a scale when the model is compiled, so this is the only form inside.
    """

    shape: float
    scale: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.gamma(self.shape, self.scale))

    def log_prob(self, x: float) -> float:
        if x <= 0.0:
            return -math.inf
        k, theta = self.shape, self.scale
        return (k - 1.0) * math.log(x) - x / theta - special.gammaln(k) - k * math.log(theta)

    def cdf(self, x):
        return stats.gamma.cdf(x, self.shape, scale=self.scale)

    def support(self) -> tuple[float, float]:
        return (0.0, math.inf)

    def __str__(self) -> str:
        return f"gamma({self.shape:g}, {self.scale:g})"


@dataclass(frozen=True)
class Categorical:
    """A distribution over named values (colours, materials), with weights summing to one."""

    values: tuple[str, ...]
    probs: tuple[float, ...]

    def __post_init__(self) -> None:
        total = sum(self.probs)
        if not math.isclose(total, 1.0):
            object.__setattr__(self, "probs", tuple(p / total for p in self.probs))

    def sample(self, rng: np.random.Generator) -> str:
        return self.values[int(rng.choice(len(self.values), p=self.probs))]

    def log_prob(self, x: str) -> float:
        try:
            p = self.probs[self.values.index(x)]
        except ValueError:
            return -math.inf
        return math.log(p) if p > 0 else -math.inf

    def support(self) -> tuple[str, ...]:
        return self.values

    def __str__(self) -> str:
        if len(set(self.probs)) == 1:
            return f"categorical({', '.join(self.values)})"
        return "categorical(" + ", ".join(f"{v}: {p:g}" for v, p in zip(self.values, self.probs)) + ")"


@dataclass(frozen=True)
class Poisson:
    """The prior on how many objects of one class a scene holds."""

    rate: float

    def sample(self, rng: np.random.Generator) -> int:
        return int(rng.poisson(self.rate))

    def log_prob(self, n: int) -> float:
        if n < 0:
            return -math.inf
        if self.rate == 0:
            return 0.0 if n == 0 else -math.inf
        return n * math.log(self.rate) - self.rate - special.gammaln(n + 1)

    def __str__(self) -> str:
        return f"poisson({self.rate:g})"

    def pmf(self, n):
        return stats.poisson.pmf(n, self.rate)


Distribution = Normal | Uniform | Gamma | Categorical
