"""The chain's warm-up: adapted proposal scales and an annealed likelihood, both only before
the samples that count.

Both make the chain reach the posterior's mass sooner, and both break the Markov property or
the target while they act, so they act only during the first sweeps, which are always burned
(``warmup_sweeps``); from the first sweep after the warm-up the kernel is the fixed Metropolis
-Hastings kernel of the posterior, and every check of ``sppl verify`` applies to it.

- **Adaptation** (``adapt = N`` in the model's inference settings): during the first N sweeps,
  each random-walk move site (a class's block of continuous parameters, a face parameter's
  face moves, a noise parameter) scales its declared step by a factor that a Robbins-Monro
  recursion drives towards the acceptance rate ``TARGET`` (log factor += (accepted - TARGET) /
  sqrt(n)). The factors freeze at sweep N.
- **Annealing** (``anneal = N``): during the first N sweeps the acceptance ratios use the
  likelihood raised to a power beta that rises geometrically from ``anneal_from`` to 1, so the
  early chain moves between hypotheses that the data will later separate sharply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# The acceptance rate a random-walk site is adapted towards: near the optimum for moves of a
# few parameters at once (Roberts, Gelman and Gilks 1997 give 0.44 for one, 0.234 for many).
TARGET = 0.3
# Bounds on a factor: an adapted step stays within these multiples of the declared one.
FACTOR_RANGE = (1e-2, 1e2)


def warmup_sweeps(settings) -> int:
    """How many sweeps the warm-up takes: none unless the model asks for it."""
    return max(int(settings.adapt), int(settings.anneal))


@dataclass
class Warmup:
    """Per-chain warm-up state. ``sweep`` counts the sweeps done, so a resumed chain picks the
    schedule up where it stopped; ``log_factors`` holds the adapted scales."""

    adapt: int = 0
    anneal: int = 0
    anneal_from: float = 0.01
    sweep: int = 0
    log_factors: dict[str, float] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)

    @classmethod
    def of(cls, settings) -> Warmup:
        return cls(int(settings.adapt), int(settings.anneal), float(settings.anneal_from))

    @property
    def beta(self) -> float:
        """The power of the likelihood in this sweep's acceptance ratios."""
        if self.sweep >= self.anneal:
            return 1.0
        return self.anneal_from ** (1.0 - self.sweep / self.anneal)

    @property
    def adapting(self) -> bool:
        return self.sweep < self.adapt

    def factor(self, site: str) -> float:
        return math.exp(self.log_factors.get(site, 0.0))

    def record(self, site: str, accepted: bool) -> None:
        """One move at ``site`` was decided: nudge its factor while adapting."""
        if not self.adapting:
            return
        n = self.counts.get(site, 0) + 1
        self.counts[site] = n
        lo, hi = (math.log(b) for b in FACTOR_RANGE)
        value = self.log_factors.get(site, 0.0) + (float(accepted) - TARGET) / math.sqrt(n)
        self.log_factors[site] = min(max(value, lo), hi)

    def state_dict(self) -> dict:
        return {"sweep": self.sweep, "log_factors": dict(self.log_factors),
                "counts": dict(self.counts)}

    def load_state_dict(self, state: dict) -> None:
        self.sweep = int(state["sweep"])
        self.log_factors = {k: float(v) for k, v in state["log_factors"].items()}
        self.counts = {k: int(v) for k, v in state["counts"].items()}
