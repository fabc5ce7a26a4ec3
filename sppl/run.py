"""Running a chain to disk: ``sppl sample``'s work, usable from Python too."""

from __future__ import annotations

import json
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from . import __version__
from .chain import Sampler
from .model import Model
from .observations import Observations
from .samples import SampleWriter, format_summary, read_samples, summarise
from .scoring import Scorer


class Stop(Exception):
    """Raised by the SIGTERM handler so a terminated run ends like an interrupted one."""


@dataclass
class RunResult:
    summary: dict[str, Any]
    map_trace: Any
    last_trace: Any


def run_chain(
    model: Model,
    observations: Observations,
    out: Path,
    *,
    steps: int,
    seed: int,
    renderer=None,
    thin: int = 1,
    burn: int | None = None,
    progress: bool | None = None,
    extra: dict[str, Any] | None = None,
    callback=None,
) -> RunResult:
    """Run one chain for ``steps`` sweeps from an empty scene, streaming samples to
    ``out/samples.jsonl`` and writing ``out/summary.json``. Ctrl-C or SIGTERM stop it early
    with everything drawn so far on disk and summarised. ``callback(step, trace, best,
    sampler)``, if given, is called after every sweep; returning True stops the run."""
    from .render import Renderer, renderer_string

    out.mkdir(parents=True, exist_ok=True)
    renderer = renderer or Renderer(model.render)
    scorer = Scorer(model, observations, renderer)
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    sampler = Sampler(model, scorer, rng)
    burn = steps // 2 if burn is None else burn
    meta = {
        "sppl_version": __version__,
        "seed": seed,
        "steps": steps,
        "thin": thin,
        "model": str(model.path) if model.path else None,
        "observations": str(observations.root),
        "gl_renderer": renderer_string(),
        **(extra or {}),
    }
    (out / "run.json").write_text(json.dumps(meta, indent=2))
    writer = SampleWriter(out / "samples.jsonl")

    def on_term(signum, frame):
        raise Stop()

    previous = signal.signal(signal.SIGTERM, on_term)
    trace = sampler.initial_trace()
    best, best_step = trace, 0
    done, interrupted = 0, False
    t0 = time.monotonic()
    bar = tqdm(total=steps, disable=None if progress is None else not progress, unit="step",
               dynamic_ncols=True, leave=False)
    try:
        for step in range(1, steps + 1):
            trace = sampler.sweep(trace)
            done = step
            if trace.score > best.score:
                best, best_step = trace, step
            if step % thin == 0:
                writer.write(step, trace)
            bar.update(1)
            if callback is not None and callback(step, trace, best, sampler):
                break
            if step % 50 == 0:
                bar.set_postfix(objects=trace.n_objects, log_joint=f"{trace.score:.0f}", refresh=False)
    except (KeyboardInterrupt, Stop):
        interrupted = True
    finally:
        bar.close()
        writer.close()
        signal.signal(signal.SIGTERM, previous)
    seconds = time.monotonic() - t0
    best = sampler.prune(best)
    map_sample = {"step": best_step, "score": best.score, "log_likelihood": best.log_likelihood,
                  **best.as_dict()}
    summary = summarise(
        read_samples(out / "samples.jsonl"),
        model.class_names,
        map_sample,
        sampler.stats.as_dict(),
        burn=min(burn, done // 2) if interrupted else burn,
        extra={"steps_done": done, "seconds": seconds, "interrupted": interrupted, "seed": seed},
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "summary.txt").write_text(format_summary(summary) + "\n")
    return RunResult(summary, best, trace)
