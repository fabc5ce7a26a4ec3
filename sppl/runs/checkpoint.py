"""Checkpoints: the full state of one chain, written atomically, so that a stopped run resumes.

A checkpoint holds everything the next sweep depends on, so that a resumed chain draws exactly
the samples the uninterrupted one would have drawn:

- the current trace (objects and noise scales; its score is recomputed by rendering them),
- the random generator's state,
- the sampler's own state where it has any (warm-up adaptation, tempering), through
  ``Sampler.state_dict()`` / ``load_state_dict()``,
- the step, the move statistics, the best trace so far and its step, and the seconds spent.

It is written to ``checkpoint.json.tmp``, flushed to disk, then renamed over
``checkpoint.json`` (``os.replace`` is atomic): a kill at any moment leaves the previous
checkpoint or the new one, never a torn one. The samples file is flushed to disk first, so it
always holds every sample up to the checkpoint's step.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RunError
from ..infer.records import decode, encode, trace_from_record, trace_record
from ..model.trace import Trace

CHECKPOINT = "checkpoint.json"
FORMAT = 1


@dataclass
class ChainState:
    """What a chain resumes from: the step it reached and the traces it held then."""

    step: int
    trace: Trace
    best: Trace
    best_step: int
    seconds: float


def capture(sampler, trace: Trace, step: int, best: Trace, best_step: int,
            seconds: float) -> dict[str, Any]:
    """A chain's state after ``step`` sweeps, as plain JSON data."""
    return {
        "format": FORMAT,
        "step": step,
        "seconds": seconds,
        "trace": trace_record(trace),
        "best": {"step": best_step, **trace_record(best)},
        "rng": sampler.rng.bit_generator.state,
        "moves": [[m, label, n, a, sampler.stats.nan.get((m, label), 0)]
                  for (m, label), (n, a) in sampler.stats.counts.items()],
        "sampler": _sampler_state(sampler),
    }


def restore(sampler, state: dict[str, Any], path: Path) -> ChainState:
    """Put ``sampler`` back in the state ``capture`` recorded; return the chain's traces."""
    try:
        sampler.rng.bit_generator.state = state["rng"]
        for m, label, n, a, nan in state["moves"]:
            sampler.stats.counts[(m, label)] = [int(n), int(a)]
            if nan:
                sampler.stats.nan[(m, label)] = int(nan)
        _load_sampler_state(sampler, state.get("sampler"))
        trace = trace_from_record(sampler, state["trace"], path)
        best = trace_from_record(sampler, state["best"], path)
        return ChainState(int(state["step"]), trace, best, int(state["best"]["step"]),
                          float(state["seconds"]))
    except (KeyError, TypeError, ValueError) as e:
        raise RunError(f"the checkpoint is damaged ({type(e).__name__}: {e})", path=path,
                       hint="start the run again without --resume") from None


# -- the sampler's own state: the one place that knows about it ----------------------------------


def _sampler_state(sampler) -> Any:
    # Warm-up adaptation and tempering live in the sampler, which exports them where it has any.
    state_dict = getattr(sampler, "state_dict", None)
    return encode(state_dict()) if state_dict is not None else None


def _load_sampler_state(sampler, state: Any) -> None:
    load = getattr(sampler, "load_state_dict", None)
    if state is not None and load is not None:
        load(decode(state))


# -- files ---------------------------------------------------------------------------------------


def write_checkpoint(folder: Path, state: dict[str, Any]) -> Path:
    """Write ``folder/checkpoint.json`` atomically (temporary file, fsync, rename)."""
    path = folder / CHECKPOINT
    tmp = folder / (CHECKPOINT + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(state, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return path


def read_checkpoint(folder: Path) -> dict[str, Any] | None:
    """The chain's last checkpoint, or None if it never wrote one."""
    path = folder / CHECKPOINT
    if not path.exists():
        return None
    try:
        state = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RunError(f"cannot read the checkpoint ({e})", path=path,
                       hint="start the run again without --resume") from None
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise RunError("not a checkpoint this version of sppl can resume", path=path,
                       hint="start the run again without --resume")
    return state


# -- what a run was made from --------------------------------------------------------------------


def model_fingerprint(model) -> str:
    """A hash of the model's text: a resumed run must sample the same model."""
    return hashlib.sha256((model.source or "").encode("utf-8")).hexdigest()


def observations_fingerprint(observations) -> str:
    """A hash of every camera and every pixel: a resumed run must see the same data."""
    h = hashlib.sha256()
    for frame in observations.frames:
        cam = frame.camera
        h.update(repr((cam.name, cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy,
                       cam.depth_max, cam.depth_type, cam.near)).encode())
        h.update(np.ascontiguousarray(cam.c2w, dtype=np.float64).tobytes())
        for array in (frame.rgb, frame.depth_valid,
                      None if frame.depth is None else np.nan_to_num(frame.depth)):
            h.update(b"-" if array is None else np.ascontiguousarray(array).tobytes())
    return h.hexdigest()
