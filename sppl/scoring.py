"""The likelihood of a hypothesis: render it for every camera and compare with the observations.

Analysis by synthesis (thesis 3.3): each frame is rendered once per hypothesis, giving RGB and
depth together, and each of the frame's modalities that the model has a sensor for is reduced to
its likelihood's sufficient statistics. The statistics are cached on the trace, so the noise
moves re-score without rendering.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .errors import ObservationError
from .likelihoods import Likelihood, get_likelihood
from .model import Model
from .observations import Observations

log = logging.getLogger(__name__)

# Which rendered output each sensor kind is compared with.
_OUTPUT = {"image": 0, "depth": 1}


@dataclass(frozen=True, eq=False)
class Term:
    """One (frame, sensor kind) pair that contributes to the likelihood."""

    frame: int
    kind: str
    camera: Camera
    observed: np.ndarray
    valid: np.ndarray | None
    likelihood: Likelihood


class Scorer:
    """Turns a set of objects into per-term likelihood statistics, and those into a log density."""

    def __init__(self, model: Model, observations: Observations, renderer) -> None:
        self.model = model
        self.renderer = renderer
        self.likelihoods = {k: get_likelihood(s.likelihood, s.options) for k, s in model.sensors.items()}
        terms: list[Term] = []
        for i, frame in enumerate(observations.frames):
            for kind, data, valid in (
                ("image", frame.rgb, None),
                ("depth", frame.depth, frame.depth_valid),
            ):
                if data is None:
                    continue
                if kind not in model.sensors:
                    log.warning("frame %d has %s data but the model has no %s sensor: ignored",
                                i, kind, kind)
                    continue
                if kind == "depth":
                    data = np.where(valid, data, 0.0).astype(np.float32)
                terms.append(Term(i, kind, frame.camera, data, valid, self.likelihoods[kind]))
        if not terms:
            raise ObservationError(
                "no observation matches a sensor of the model: the frames need RGB images for an"
                " 'image' sensor or depth maps for a 'depth' sensor",
                path=observations.root,
            )
        self.terms = terms
        self.cameras = {t.frame: t.camera for t in terms}

    def evaluate(self, objects):
        """Render the objects for every camera; return the likelihood statistics of every term
        and the renders, as (stats, {frame: (rgb, depth)})."""
        parts = [*self.model.static_parts, *(p for o in objects for p in o.parts)]
        rendered = {f: self.renderer.render(parts, cam) for f, cam in self.cameras.items()}
        stats = {
            (t.frame, t.kind): t.likelihood.statistics(
                t.observed, rendered[t.frame][_OUTPUT[t.kind]], t.valid
            )
            for t in self.terms
        }
        return stats, rendered

    def statistics(self, objects) -> dict[tuple[int, str], np.ndarray]:
        return self.evaluate(objects)[0]

    def rendered(self, renders, term: Term) -> np.ndarray:
        """The rendered array a term compares with its observation."""
        return renders[term.frame][_OUTPUT[term.kind]]

    def log_likelihood(
        self, stats: Mapping[tuple[int, str], np.ndarray], noise: Mapping[str, Mapping[str, float]]
    ) -> float:
        return sum(
            self.likelihoods[kind].log_prob(s, noise[kind]) for (_, kind), s in stats.items()
        )


class PriorScorer:
    """A scorer with no observations: the chain then targets the prior, which is how the
    sampler is verified (prior recovery) and how ``sppl verify`` checks a user's model."""

    terms: list[Term] = []
    cameras: dict = {}

    def evaluate(self, objects):
        return {}, {}

    def statistics(self, objects) -> dict[tuple[int, str], np.ndarray]:
        return {}

    def log_likelihood(self, stats, noise) -> float:
        return 0.0
