"""Running one chain to disk: ``sppl sample``'s work for a chain, usable from Python too."""

from __future__ import annotations

import json
import math
import signal
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from .._version import __version__
from ..data.observations import Observations
from ..errors import RunError
from ..infer.tempering import make_sampler
from ..infer.warmup import warmup_sweeps
from ..model.types import Model
from ..output.samples import SampleWriter, format_summary, read_samples, summarise, truncate_samples
from ..render.seen import SeenCache
from ..scoring.scorer import Scorer
from .checkpoint import (
    CHECKPOINT,
    capture,
    model_fingerprint,
    observations_fingerprint,
    read_checkpoint,
    restore,
    write_checkpoint,
)
from .lock import hold

CHECKPOINT_SECONDS = 30.0  # how often a chain saves its full state (``--checkpoint-every``)


class Stop(Exception):
    """Raised by a second SIGINT or SIGTERM: stop now, mid-sweep, without a last checkpoint."""


class StopRequest:
    """SIGINT and SIGTERM ask the chain to stop at the end of the sweep it is drawing, so that
    the samples, the last checkpoint and the summary all describe one state of the chain; a
    second signal stops it at once (the previous checkpoint then stands). A signal that is
    ignored (SIGINT in a chain's worker process, which the parent stops) stays ignored."""

    def __init__(self) -> None:
        self.requested = False
        self.previous: dict[int, Any] = {}

    def __enter__(self) -> StopRequest:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self.previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise Stop()
        self.requested = True

    def __exit__(self, *exc) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


@dataclass
class RunResult:
    """What a run returns: its summary (as in ``summary.json``), the MAP and last traces of a
    single chain (None for several chains: their MAP is the summary's ``map``), and the
    samples. ``chain_samples`` holds each chain's samples in order, ``samples`` all of them
    pooled; a run into a folder reads them from its ``samples.jsonl`` files when first asked,
    a run without one (``out=None``) holds them already."""

    summary: dict[str, Any]
    map_trace: Any
    last_trace: Any
    sample_files: tuple[Path, ...] = ()
    _chain_samples: list[list[dict[str, Any]]] | None = field(default=None, repr=False)

    @property
    def chain_samples(self) -> list[list[dict[str, Any]]]:
        if self._chain_samples is None:
            self._chain_samples = [read_samples(f) for f in self.sample_files]
        return self._chain_samples

    @property
    def samples(self) -> list[dict[str, Any]]:
        return [s for chain in self.chain_samples for s in chain]


def in_memory(run, *args, **kwargs) -> RunResult:
    """``run(model, observations, out, ...)`` into a temporary folder that is gone when it
    returns, the samples read into the result first: a run that needs no folder."""
    with tempfile.TemporaryDirectory(prefix="sppl-run-") as tmp:
        result = run(*args[:2], Path(tmp), *args[2:], **kwargs)
        result.chain_samples  # read before the folder goes
        result.sample_files = ()
        return result


def run_chain(
    model: Model,
    observations: Observations,
    out: Path | None,
    *,
    steps: int,
    seed: int | np.random.SeedSequence,
    renderer=None,
    thin: int = 1,
    burn: int | None = None,
    progress: bool | None = None,
    extra: dict[str, Any] | None = None,
    callback=None,
    resume: bool = False,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
) -> RunResult:
    """Run one chain for ``steps`` sweeps from an empty scene, streaming samples to
    ``out/samples.jsonl`` and writing ``out/summary.json``. Ctrl-C or SIGTERM stop it at the
    end of the current sweep with everything drawn so far on disk and summarised. Every
    ``checkpoint_seconds`` (and when it stops) the chain's full state goes to
    ``out/checkpoint.json``; with ``resume=True`` the chain continues from there up to
    ``steps`` sweeps in all, drawing exactly the samples an uninterrupted run draws.
    ``callback(step, trace, best, sampler)``, if given, is called after every sweep; returning
    True stops the run. ``seed`` is an integer or, for one of several chains, a
    ``SeedSequence`` spawned from the run's seed (``run_chains``). With ``out=None`` the run
    keeps nothing on disk and its result holds the samples (``RunResult.samples``); it cannot
    be resumed."""
    if out is None:
        if resume:
            raise RunError("a run without an output folder cannot be resumed",
                           hint="give the run a folder (out=...) to resume it later")
        return in_memory(run_chain, model, observations, steps=steps, seed=seed,
                         renderer=renderer, thin=thin, burn=burn, progress=progress, extra=extra,
                         callback=callback, checkpoint_seconds=checkpoint_seconds)
    out.mkdir(parents=True, exist_ok=True)
    with hold(out):  # one writer per run folder (sppl.runs.lock)
        return _run_chain(model, observations, out, steps=steps, seed=seed, renderer=renderer,
                          thin=thin, burn=burn, progress=progress, extra=extra,
                          callback=callback, resume=resume,
                          checkpoint_seconds=checkpoint_seconds)


def _run_chain(model, observations, out, *, steps, seed, renderer, thin, burn, progress, extra,
               callback, resume, checkpoint_seconds) -> RunResult:
    chain = ChainRun(model, observations, out, steps=steps, seed=seed, renderer=renderer,
                     thin=thin, burn=burn, extra=extra, callback=callback, resume=resume,
                     checkpoint_seconds=checkpoint_seconds)
    interrupted = False
    bar = tqdm(total=steps, initial=chain.start,
               disable=None if progress is None else not progress,
               unit="step", dynamic_ncols=True, leave=False)
    try:
        with StopRequest() as stop:
            for step in range(chain.start + 1, steps + 1):
                stopping = chain.after_sweep(step, chain.sampler.sweep(chain.trace))
                bar.update(1)
                if stopping or stop.requested:
                    break
                chain.checkpoint_if_due()
                if step % 50 == 0:
                    bar.set_postfix(objects=chain.trace.n_objects,
                                    log_joint=f"{chain.trace.score:.0f}", refresh=False)
            interrupted = stop.requested and chain.done < steps
            chain.save()
    except Stop:
        interrupted = True  # stopped mid-sweep: the last checkpoint stands
    finally:
        bar.close()
        chain.close()
    return chain.finish(interrupted)


class ChainRun:
    """One chain writing its run folder, for ``run_chain`` and for the chains that
    ``sppl.runs.lockstep`` advances together: the set-up (a new chain, or one resumed from its
    checkpoint), the bookkeeping after each sweep, checkpoints, and the summary at the end.

    ``scorer``, if given, is shared with other chains; otherwise the chain makes its own
    (with ``renderer``, or a new one) once the resumed run's inputs have been checked."""

    def __init__(self, model: Model, observations: Observations, out: Path, *, steps: int,
                 seed: int | np.random.SeedSequence, scorer=None, renderer=None, thin: int = 1,
                 burn: int | None = None, extra: dict[str, Any] | None = None, callback=None,
                 resume: bool = False, checkpoint_seconds: float = CHECKPOINT_SECONDS) -> None:
        from ..render import Renderer, renderer_string

        self.model, self.out, self.steps, self.thin = model, out, steps, thin
        self.callback, self.checkpoint_seconds = callback, checkpoint_seconds
        out.mkdir(parents=True, exist_ok=True)
        fingerprints = {"model_sha256": model_fingerprint(model),
                        "observations_sha256": observations_fingerprint(observations)}
        if resume and (out / "run.json").exists():
            check_same_inputs(out, fingerprints)  # before anything is rendered
        if scorer is None:
            scorer = Scorer(model, observations, renderer or Renderer(model.render))
        if not isinstance(seed, np.random.SeedSequence):
            seed_sequence = np.random.SeedSequence(seed)
        else:
            seed_sequence = seed
        rng = np.random.default_rng(seed_sequence)
        self.seed = _seed_record(seed)
        self.sampler = sampler = make_sampler(model, scorer, rng)
        # Which objects some camera sees, worked out for the samples written (sppl.render.seen).
        self.seen = SeenCache(model, observations.cameras)
        burn_option, self.burn = burn, effective_burn(model, steps, burn)
        self.state = state = read_checkpoint(out) if resume else None
        meta = {
            "sppl_version": __version__,
            "seed": self.seed,
            "steps": steps,
            "thin": thin,
            "burn": burn_option,
            "model": str(model.path) if model.path else None,
            "observations": str(observations.root),
            "gl_renderer": renderer_string(),
            **fingerprints,
            **(extra or {}),
        }
        (out / "run.json").write_text(json.dumps(meta, indent=2))

        if state is not None:
            restored = restore(sampler, state, out / CHECKPOINT)
            self.trace, self.best, self.best_step = restored.trace, restored.best, restored.best_step
            self.start, self.seconds_before = restored.step, restored.seconds
        else:
            self.trace = sampler.initial_trace()
            if math.isnan(self.trace.score):
                # Every ratio from this state would be NaN, and so rejected: the chain could not
                # move.
                raise RunError("the starting scene's log joint is NaN: a sensor likelihood gave "
                               "NaN for the observations", path=observations.root,
                               hint="check the observations and the likelihoods the model names")
            self.best, self.best_step, self.start, self.seconds_before = self.trace, 0, 0, 0.0
        # A resumed chain draws the samples after its checkpoint again; a new one starts empty.
        truncate_samples(out / "samples.jsonl", self.start)
        self.writer = SampleWriter(out / "samples.jsonl")
        self.done = self.start
        self.t0 = time.monotonic()
        if state is None:
            self.save()  # resumable from the start, and no stale checkpoint of an earlier run left
        self.last_save = time.monotonic()

    def after_sweep(self, step: int, trace) -> bool:
        """Take the state after sweep ``step``: the best so far, the sample. True when the
        callback asks to stop."""
        self.trace, self.done = trace, step
        if trace.score > self.best.score:
            self.best, self.best_step = trace, step
        if step % self.thin == 0:
            self.writer.write(step, trace, self.seen(trace.objects))
        return self.callback is not None and bool(
            self.callback(step, trace, self.best, self.sampler))

    def checkpoint_if_due(self) -> None:
        if time.monotonic() - self.last_save >= self.checkpoint_seconds:
            self.save()
            self.last_save = time.monotonic()

    def save(self) -> None:
        """A checkpoint of the state after the last sweep taken."""
        self.writer.sync()  # every sample up to the checkpoint's step is on disk before it
        write_checkpoint(self.out, capture(self.sampler, self.trace, self.done, self.best,
                                           self.best_step, self.seconds()))

    def seconds(self) -> float:
        return self.seconds_before + time.monotonic() - self.t0

    def close(self) -> None:
        self.writer.close()
        self.seen.release()

    def finish(self, interrupted: bool) -> RunResult:
        """The chain's summary (``summary.json``, ``summary.txt``) of what it wrote."""
        model, done, seconds = self.model, self.done, self.seconds()
        best = self.sampler.prune(self.best)
        map_sample = {"step": self.best_step, "score": best.score,
                      "log_likelihood": best.log_likelihood,
                      **best.as_dict(self.seen(best.objects, keep=False))}
        burn = self.burn
        summary = summarise(
            read_samples(self.out / "samples.jsonl"),
            model.class_names,
            map_sample,
            self.sampler.stats.as_dict(),
            burn=max(min(burn, done // 2), warmup_sweeps(model.inference)) if interrupted else burn,
            extra={"steps_done": done, "seconds": seconds, "interrupted": interrupted,
                   "seed": self.seed,
                   "resumed_from": self.start if self.state is not None else None},
        )
        (self.out / "summary.json").write_text(json.dumps(summary, indent=2))
        (self.out / "summary.txt").write_text(format_summary(summary) + "\n")
        return RunResult(summary, best, self.trace, (self.out / "samples.jsonl",))


def effective_burn(model: Model, steps: int, burn: int | None) -> int:
    """The sweeps a chain of ``steps`` leaves out of its posterior: ``burn`` (default half the
    steps), and never fewer than the warm-up's (adaptation, annealing), whose sweeps do not
    target the posterior."""
    return max(steps // 2 if burn is None else burn, warmup_sweeps(model.inference))


def read_run(out: Path) -> tuple[dict[str, Any], int]:
    """A run folder's record (``run.json``) and the steps every one of its chains has
    checkpointed, for ``sppl sample --resume``."""
    try:
        meta = json.loads((out / "run.json").read_text())
    except FileNotFoundError:
        raise RunError("not a run folder (it has no run.json)", path=out,
                       hint="--resume takes the --out folder of an earlier `sppl sample`") from None
    except (OSError, json.JSONDecodeError) as e:
        raise RunError(f"cannot read the run's record ({e})", path=out / "run.json") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("steps"), int):
        raise RunError("run.json is not the record of an `sppl sample` run", path=out)
    folders = [out / name for name in meta.get("chain_folders", [])] or [out]
    done = []
    for folder in folders:
        state = read_checkpoint(folder) if folder.is_dir() else None
        done.append(0 if state is None else int(state["step"]))
    return meta, min(done)


def check_same_inputs(out: Path, fingerprints: dict[str, str]) -> None:
    """A run resumes only on the model and observations it started with."""
    try:
        meta = json.loads((out / "run.json").read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise RunError(f"cannot read the run's record ({e})", path=out / "run.json") from None
    for key, what in (("model_sha256", "model has"), ("observations_sha256", "observations have")):
        if meta.get(key) not in (None, fingerprints[key]):
            raise RunError(
                f"the {what} changed since this run started, so resuming would mix two "
                "posteriors", path=out,
                hint=f"resume with the run's original {what.split()[0]}, or start a new run",
            )


def _seed_record(seed: int | np.random.SeedSequence) -> Any:
    """A seed as run.json records it: the integer, or a spawned sequence's entropy and key."""
    if isinstance(seed, np.random.SeedSequence):
        return {"entropy": int(seed.entropy), "spawn_key": [int(k) for k in seed.spawn_key]}
    return seed


# ----------------------------------------------------------------------------------------------
# Several chains


def chain_folder(out: Path, index: int) -> Path:
    return out / f"chain_{index}"


def chain_seeds(seed: int, chains: int) -> list[np.random.SeedSequence]:
    """Chain i's stream: the i-th of ``SeedSequence(seed).spawn(chains)``."""
    return np.random.SeedSequence(seed).spawn(chains)


def chain_extra(index: int, chains: int, seed: int) -> dict[str, Any]:
    """What a chain of several records in its own run.json about the run it belongs to."""
    return {"chain": index, "chains": chains, "master_seed": seed}
