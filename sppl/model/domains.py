"""Parameter domains, and the symmetric random-walk step that stays inside each.

A parameter move must propose inside the parameter's domain and keep the proposal symmetric,
so that its density cancels in the Metropolis-Hastings ratio. Reflecting at a boundary and
wrapping around a period both keep a Gaussian step symmetric (the kernel becomes a sum over
mirror images, which is symmetric in its two arguments), so no domain needs a Hastings term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Real:
    def contains(self, x: float) -> bool:
        return math.isfinite(x)

    def step(self, x: float, scale: float, rng: np.random.Generator) -> float:
        return x + scale * float(rng.standard_normal())

    def describe(self) -> str:
        return "real"


@dataclass(frozen=True)
class Positive:
    def contains(self, x: float) -> bool:
        return 0.0 < x < math.inf

    def step(self, x: float, scale: float, rng: np.random.Generator) -> float:
        return abs(x + scale * float(rng.standard_normal()))

    def describe(self) -> str:
        return "positive"


@dataclass(frozen=True)
class Interval:
    """A closed interval ``[low, high]``; steps reflect off both ends."""

    low: float
    high: float

    def contains(self, x: float) -> bool:
        return self.low <= x <= self.high

    def step(self, x: float, scale: float, rng: np.random.Generator) -> float:
        width = self.high - self.low
        y = (x + scale * float(rng.standard_normal()) - self.low) % (2.0 * width)
        return self.low + (y if y <= width else 2.0 * width - y)

    def describe(self) -> str:
        return f"interval({self.low:g}, {self.high:g})"


@dataclass(frozen=True)
class Periodic:
    """An angle living on ``[low, high)``, where ``high`` and ``low`` are the same pose.

    A cube's rotation about z is periodic with period pi/2: turning it by 90 degrees gives the
    same cube, so its rotation lives on [-pi/4, pi/4).
    """

    low: float
    high: float

    def contains(self, x: float) -> bool:
        return self.low <= x < self.high

    def wrap(self, x: float) -> float:
        y = self.low + (x - self.low) % (self.high - self.low)
        return self.low if y >= self.high else y

    def step(self, x: float, scale: float, rng: np.random.Generator) -> float:
        return self.wrap(x + scale * float(rng.standard_normal()))

    def describe(self) -> str:
        return f"periodic({self.low:g}, {self.high:g})"


@dataclass(frozen=True)
class Integer:
    """Whole numbers in ``[low, high]`` (either end may be infinite).

    A step moves by a nonzero amount whose size and sign are drawn symmetrically, so it is
    never a wasted no-op; at a bound it folds back as a mirror placed half a unit outside the
    bound, which keeps the proposal symmetric (the same argument as ``Interval``'s reflection).
    """

    low: float = -math.inf
    high: float = math.inf

    def contains(self, x) -> bool:
        try:
            whole = float(x) == int(x)
        except (TypeError, ValueError, OverflowError):
            return False
        return whole and self.low <= x <= self.high

    def step(self, x: int, scale: float, rng: np.random.Generator) -> int:
        size = 1 + int(abs(scale * float(rng.standard_normal())))
        y = int(x) + (size if rng.random() < 0.5 else -size)
        if math.isinf(self.low) and math.isinf(self.high):
            return y
        if math.isinf(self.high):
            return y if y >= self.low else int(2 * self.low - 1 - y)
        if math.isinf(self.low):
            return y if y <= self.high else int(2 * self.high + 1 - y)
        n = int(self.high - self.low) + 1
        z = (y - int(self.low)) % (2 * n)
        return int(self.low) + (z if z < n else 2 * n - 1 - z)

    def describe(self) -> str:
        if math.isinf(self.low) and math.isinf(self.high):
            return "integer"
        return f"integer({self.low:g}, {self.high:g})"


@dataclass(frozen=True)
class Finite:
    """A categorical parameter: one of a fixed tuple of names (colours, say)."""

    values: tuple[str, ...]

    def contains(self, x: str) -> bool:
        return x in self.values

    def step(self, x: str, scale: float, rng: np.random.Generator) -> str:
        # A uniform draw among the *other* values: symmetric, and never a wasted no-op.
        others = [v for v in self.values if v != x]
        if not others:
            return x
        return others[int(rng.integers(len(others)))]

    def describe(self) -> str:
        return "categorical(" + ", ".join(self.values) + ")"


Domain = Real | Positive | Interval | Periodic | Integer | Finite


def is_continuous(domain: Domain) -> bool:
    return not isinstance(domain, Finite | Integer)
