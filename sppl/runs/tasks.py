"""One task of a data set: one chain of one scene, as a worker runs it (a local worker process
or a Ray worker; ``sppl.runs.executors``)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..data.observations import load_observations
from .checkpoint import CHECKPOINT
from .run import chain_extra, chain_seeds, run_chain

TASK_RECORD = "task.json"  # in a task's chain folder: which worker ran it, and how many times


@dataclass(frozen=True)
class Task:
    """One chain of one scene: everything a worker needs besides the model."""

    scene: str
    obs: str  # the observation folder, as a path the worker can open
    out: str  # the chain's run folder
    chain: int
    chains: int
    steps: int
    seed: int
    thin: int
    burn: int | None
    checkpoint_seconds: float

    @property
    def label(self) -> str:
        return self.scene if self.chains == 1 else f"{self.scene}, chain {self.chain}"


def task_state(task: Task) -> str:
    """``"done"`` (its summary says it drew every step), ``"resume"`` (a checkpoint to go on
    from) or ``"new"``."""
    out = Path(task.out)
    try:
        summary = json.loads((out / "summary.json").read_text())
        if summary.get("steps_done", 0) >= task.steps and not summary.get("interrupted"):
            return "done"
    except (OSError, ValueError):
        pass
    return "resume" if (out / CHECKPOINT).exists() else "new"


# What a worker process keeps between its tasks: compiling a model and opening a GL context are
# paid once per process, not once per task.
_worker_cache: dict[Any, Any] = {}


def run_task(model_source: str, model_path: str | None, task: Task) -> dict[str, Any]:
    """Run one task in this process (a local worker or a Ray worker) and return what the
    driver reports of it. A task that finds its chain finished returns at once; one that finds
    a checkpoint (its earlier worker was lost, or the run was stopped) continues from it."""
    import os
    import socket

    from ..lang import compile_model
    from ..render import Renderer

    out = Path(task.out)
    state = task_state(task)
    if state != "done":
        key = ("model", model_source, model_path)
        if key not in _worker_cache:
            _worker_cache.clear()  # a new model: the old one's renderer goes with it
            model = (compile_model(model_source, model_path) if model_path
                     else compile_model(model_source))
            _worker_cache[key] = model, Renderer(model.render)
        model, renderer = _worker_cache[key]
        out.mkdir(parents=True, exist_ok=True)
        record = out / TASK_RECORD
        try:
            attempts = json.loads(record.read_text()).get("attempts", 0)
        except (OSError, ValueError):
            attempts = 0
        # Written before the chain starts, so that a lost worker is known by its pid.
        record.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                      "attempts": attempts + 1, "resumed": state == "resume"}))
        observations = load_observations(task.obs)
        seed = task.seed if task.chains == 1 else chain_seeds(task.seed, task.chains)[task.chain]
        extra = None if task.chains == 1 else chain_extra(task.chain, task.chains, task.seed)
        run_chain(model, observations, out, steps=task.steps, seed=seed, renderer=renderer,
                  thin=task.thin, burn=task.burn, progress=False, extra=extra,
                  resume=state == "resume", checkpoint_seconds=task.checkpoint_seconds)
    summary = json.loads((out / "summary.json").read_text())
    return {"state": state, "steps_done": summary["steps_done"],
            "interrupted": summary["interrupted"], "seconds": summary["seconds"]}
