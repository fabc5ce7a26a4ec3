"""A trace as a record of plain data, and back: what a checkpoint keeps of the chain's state
(``sppl.runs.checkpoint``) and of a tempered sampler's hot rungs (``sppl.infer.tempering``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RunError
from ..model.trace import Trace, make_object


def encode(value: Any) -> Any:
    """JSON-ready data from a state that may hold numpy arrays and scalars."""
    if isinstance(value, np.ndarray):
        return {"__ndarray__": value.tolist(), "dtype": str(value.dtype)}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {str(k): encode(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode(v) for v in value]
    return value


def decode(value: Any) -> Any:
    if isinstance(value, dict):
        if "__ndarray__" in value:
            return np.array(value["__ndarray__"], dtype=value["dtype"])
        return {k: decode(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode(v) for v in value]
    return value


# -- traces --------------------------------------------------------------------------------------


def trace_record(trace: Trace) -> dict[str, Any]:
    """A trace as JSON-ready data that ``trace_from_record`` reads back."""
    # Floats go through repr, which reads back to the same double: the resumed chain continues
    # from bit-identical values. The likelihood's statistics are kept too, so that the resumed
    # trace scores exactly what the saved one did, whatever path of renders led to it.
    stats = [[frame, kind, encode(np.asarray(s))] for (frame, kind), s in trace.stats.items()]
    return {"score": trace.score, "stats": stats, **trace.as_dict()}


def trace_from_record(sampler, record: dict[str, Any], path: Path | None) -> Trace:
    """The trace ``record`` holds, rendered again by ``sampler`` and checked to score what it
    scored when it was recorded (a different model, observations or renderer would not)."""
    model = sampler.model
    objects = tuple(make_object(model, model.object_class(o["class"]), o["params"])
                    for o in record["objects"])
    fresh = sampler.make_trace(objects, record["noise"])  # renders it again
    stats = {(int(f), str(k)): decode(s) for f, k, s in record["stats"]}
    log_likelihood = sampler.scorer.log_likelihood(stats, fresh.noise)
    recorded = fresh.log_prior + log_likelihood
    if not (fresh.score == recorded or math.isclose(fresh.score, recorded, rel_tol=1e-4,
                                                   abs_tol=1e-3)):
        raise RunError(
            f"the checkpoint's scene scores {fresh.score!r} now but {recorded!r} when it was "
            "saved: the model, the observations or the renderer differ from the run's",
            path=path, hint="resume with the same model and observations, or start a new run",
        )
    return Trace(model, objects, fresh.noise, stats, fresh.log_prior, log_likelihood,
                 fresh.renders)
