"""What the sampler asks of a scorer.

``ScorerProtocol`` is all a ``Sampler`` (``sppl.infer.chain``) needs: a scorer that renders a
hypothesis and gives its statistics, and turns those into a log likelihood. ``PriorScorer``
(no observations) is one, and so is a test's stand-in. A scorer of observations
(``ObservationScorer``: the fast ``Scorer`` and the numpy ``ReferenceScorer``) has more, which
the sampler and the checks use where a scorer has it: its terms (data-driven births look at the
pixels a state leaves unexplained), a batch of hypotheses drawn together, re-scoring at other
noise values for the per-pixel likelihoods, and a term's statistics from given renders (``sppl
verify``). The fast scorer's pixel rectangles (``draws``, for merges) are optional beyond these.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from ..data.camera import Camera
    from .scorer import Term

#: A hypothesis's statistics: per (frame, sensor kind), its likelihood's ``statistics``.
Stats = Mapping[tuple[int, str], "np.ndarray"]
#: Noise values by sensor kind (and the render group, for latent lighting).
Noise = Mapping[str, Mapping[str, float]]


@runtime_checkable
class ScorerProtocol(Protocol):
    """Renders hypotheses and scores them against observations."""

    def evaluate(self, objects: Sequence, parent: Any = None,
                 noise: Noise | None = None) -> tuple[Stats, Mapping]:
        """(statistics, renders) of a hypothesis. ``parent``, the trace it was proposed from,
        lets a scorer work incrementally; ``noise`` lights it and gives the values per-pixel
        likelihoods are scored at (the sampler passes it only where either applies)."""

    def log_likelihood(self, stats: Stats, noise: Noise) -> float:
        """log p(observations | hypothesis, noise) from ``evaluate``'s statistics."""


@runtime_checkable
class ObservationScorer(ScorerProtocol, Protocol):
    """A scorer of observations: the terms it scores and what the sampler, the births and the
    checks use of them."""

    #: The (frame, sensor kind) pairs that contribute to the likelihood.
    terms: list[Term]
    #: Each frame's camera.
    cameras: Mapping[int, Camera]
    #: The sensor kinds scored at given noise values (``sppl.model.robust``): a noise move
    #: of one re-scores the pixels (``rescore``).
    per_pixel: list[str]

    def evaluate_batch(self, requests: Sequence[tuple]) -> list[tuple[Stats, Mapping]]:
        """``evaluate`` of several (objects, parent) or (objects, parent, noise) requests, in
        order, with the same answers."""

    def rescore(self, trace: Any, noise: Noise) -> tuple[Stats, Mapping]:
        """(statistics, renders) of the trace's objects at other noise values."""

    def rendered(self, renders: Mapping, term: Term) -> np.ndarray:
        """The rendered array a term compares with its observation."""

    def term_statistics(self, term: Term, rendered: np.ndarray, noise: Noise | None
                        ) -> np.ndarray:
        """A term's statistics from a rendering, in numpy."""
