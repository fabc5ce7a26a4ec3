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
class TruncatedNormal:
    """Normal(mu, sigma) restricted to ``[low, high]`` (either may be infinite) and renormalised."""

    mu: float
    sigma: float
    low: float
    high: float

    def __post_init__(self) -> None:
        a, b = self._standard(self.low), self._standard(self.high)
        # log of the mass the normal puts on [low, high], computed on the side of the mean
        # where it is not a difference of two numbers close to 1.
        if a > 0:
            mass = special.ndtr(-a) - special.ndtr(-b)
        else:
            mass = special.ndtr(b) - special.ndtr(a)
        object.__setattr__(self, "_log_mass", math.log(mass) if mass > 0 else -math.inf)

    def _standard(self, x: float) -> float:
        return (x - self.mu) / self.sigma

    def sample(self, rng: np.random.Generator) -> float:
        a, b = self._standard(self.low), self._standard(self.high)
        # Inverse-CDF sampling, on the upper tail's side where that is more accurate.
        u = rng.random()
        if a > 0:
            lo, hi = special.ndtr(-b), special.ndtr(-a)
            z = -special.ndtri(lo + u * (hi - lo))
        else:
            lo, hi = special.ndtr(a), special.ndtr(b)
            z = special.ndtri(lo + u * (hi - lo))
        return float(min(max(self.mu + self.sigma * z, self.low), self.high))

    def log_prob(self, x: float) -> float:
        if not self.low <= x <= self.high:
            return -math.inf
        z = (x - self.mu) / self.sigma
        return -0.5 * z * z - math.log(self.sigma) - 0.5 * _LOG_2PI - self._log_mass

    def cdf(self, x):
        a, b = self._standard(self.low), self._standard(self.high)
        return stats.truncnorm.cdf(x, a, b, loc=self.mu, scale=self.sigma)

    def support(self) -> tuple[float, float]:
        return (self.low, self.high)

    def __str__(self) -> str:
        return f"truncated_normal({self.mu:g}, {self.sigma:g}, {self.low:g}, {self.high:g})"


@dataclass(frozen=True)
class LogNormal:
    """exp(Normal(mu, sigma)): ``mu`` and ``sigma`` are the mean and sd of the logarithm."""

    mu: float
    sigma: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.lognormal(self.mu, self.sigma))

    def log_prob(self, x: float) -> float:
        if x <= 0.0:
            return -math.inf
        log_x = math.log(x)
        z = (log_x - self.mu) / self.sigma
        return -0.5 * z * z - math.log(self.sigma) - 0.5 * _LOG_2PI - log_x

    def cdf(self, x):
        return stats.lognorm.cdf(x, self.sigma, scale=math.exp(self.mu))

    def support(self) -> tuple[float, float]:
        return (0.0, math.inf)

    def __str__(self) -> str:
        return f"lognormal({self.mu:g}, {self.sigma:g})"


@dataclass(frozen=True)
class Beta:
    a: float
    b: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.beta(self.a, self.b))

    def log_prob(self, x: float) -> float:
        if not 0.0 <= x <= 1.0:
            return -math.inf
        if (x == 0.0 and self.a != 1.0) or (x == 1.0 and self.b != 1.0):
            # The density is 0 or infinite at an end; either way the value is not usable.
            return -math.inf
        log_x = math.log(x) if self.a != 1.0 else 0.0
        log_1mx = math.log1p(-x) if self.b != 1.0 else 0.0
        return (self.a - 1.0) * log_x + (self.b - 1.0) * log_1mx - special.betaln(self.a, self.b)

    def cdf(self, x):
        return stats.beta.cdf(x, self.a, self.b)

    def support(self) -> tuple[float, float]:
        return (0.0, 1.0)

    def __str__(self) -> str:
        return f"beta({self.a:g}, {self.b:g})"


@dataclass(frozen=True)
class Exponential:
    """Exponential with *rate* ``rate`` (mean ``1 / rate``)."""

    rate: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.exponential(1.0 / self.rate))

    def log_prob(self, x: float) -> float:
        if x < 0.0:
            return -math.inf
        return math.log(self.rate) - self.rate * x

    def cdf(self, x):
        return stats.expon.cdf(x, scale=1.0 / self.rate)

    def support(self) -> tuple[float, float]:
        return (0.0, math.inf)

    def __str__(self) -> str:
        return f"exponential({self.rate:g})"


@dataclass(frozen=True)
class DiscreteUniform:
    """Each integer of ``low, low + 1, ..., high`` equally likely."""

    low: int
    high: int

    def sample(self, rng: np.random.Generator) -> int:
        return int(rng.integers(self.low, self.high + 1))

    def log_prob(self, x) -> float:
        if x != int(x) or not self.low <= x <= self.high:
            return -math.inf
        return -math.log(self.high - self.low + 1)

    def cdf(self, x):
        return stats.randint.cdf(x, self.low, self.high + 1)

    def support(self) -> tuple[float, float]:
        return (self.low, self.high)

    def __str__(self) -> str:
        return f"discrete_uniform({self.low}, {self.high})"


@dataclass(frozen=True)
class Dependent:
    """Stands in a ``Parameter``'s ``prior`` when its distribution depends on other values of
    the object (``h : positive ~ uniform(r, 2 * r)``): the real distribution is made, from
    those values, by ``Parameter.distribution``. Only its text is kept here."""

    text: str

    def sample(self, rng: np.random.Generator):
        raise TypeError(f"the prior {self.text} depends on other parameters; use Parameter.sample")

    def log_prob(self, x) -> float:
        raise TypeError(
            f"the prior {self.text} depends on other parameters; use Parameter.log_prob"
        )

    def __str__(self) -> str:
        return self.text


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

    def cdf(self, x):
        return stats.poisson.cdf(x, self.rate)

    def support(self) -> tuple[float, float]:
        return (0, math.inf)


Distribution = (
    Normal
    | Uniform
    | Gamma
    | TruncatedNormal
    | LogNormal
    | Beta
    | Exponential
    | DiscreteUniform
    | Poisson
    | Categorical
    | Dependent
)
