"""Running a chain to disk: ``sppl sample``'s work, usable from Python too."""

from __future__ import annotations

import json
import math
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from . import __version__
from .checkpoint import (
    CHECKPOINT,
    capture,
    model_fingerprint,
    observations_fingerprint,
    read_checkpoint,
    restore,
    write_checkpoint,
)
from .errors import RunError, SpplError
from .lock import hold
from .model import Model
from .observations import Observations
from .samples import SampleWriter, format_summary, read_samples, summarise, truncate_samples
from .scoring import Scorer
from .seen import SeenCache
from .tempering import make_sampler
from .warmup import warmup_sweeps


CHECKPOINT_SECONDS = 30.0  # how often a chain saves its full state (``--checkpoint-every``)


class Stop(Exception):
    """Raised by a second SIGINT or SIGTERM: stop now, mid-sweep, without a last checkpoint."""


class _StopRequest:
    """SIGINT and SIGTERM ask the chain to stop at the end of the sweep it is drawing, so that
    the samples, the last checkpoint and the summary all describe one state of the chain; a
    second signal stops it at once (the previous checkpoint then stands). A signal that is
    ignored (SIGINT in a chain's worker process, which the parent stops) stays ignored."""

    def __init__(self) -> None:
        self.requested = False
        self.previous: dict[int, Any] = {}

    def __enter__(self) -> _StopRequest:
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
    summary: dict[str, Any]
    map_trace: Any
    last_trace: Any


def run_chain(
    model: Model,
    observations: Observations,
    out: Path,
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
    ``SeedSequence`` spawned from the run's seed (``run_chains``)."""
    out.mkdir(parents=True, exist_ok=True)
    with hold(out):  # one writer per run folder (sppl.lock)
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
        with _StopRequest() as stop:
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
    ``sppl.lockstep`` advances together: the set-up (a new chain, or one resumed from its
    checkpoint), the bookkeeping after each sweep, checkpoints, and the summary at the end.

    ``scorer``, if given, is shared with other chains; otherwise the chain makes its own
    (with ``renderer``, or a new one) once the resumed run's inputs have been checked."""

    def __init__(self, model: Model, observations: Observations, out: Path, *, steps: int,
                 seed: int | np.random.SeedSequence, scorer=None, renderer=None, thin: int = 1,
                 burn: int | None = None, extra: dict[str, Any] | None = None, callback=None,
                 resume: bool = False, checkpoint_seconds: float = CHECKPOINT_SECONDS) -> None:
        from .render import Renderer, renderer_string

        self.model, self.out, self.steps, self.thin = model, out, steps, thin
        self.callback, self.checkpoint_seconds = callback, checkpoint_seconds
        out.mkdir(parents=True, exist_ok=True)
        fingerprints = {"model_sha256": model_fingerprint(model),
                        "observations_sha256": observations_fingerprint(observations)}
        if resume and (out / "run.json").exists():
            _check_same_inputs(out, fingerprints)  # before anything is rendered
        if scorer is None:
            scorer = Scorer(model, observations, renderer or Renderer(model.render))
        if not isinstance(seed, np.random.SeedSequence):
            seed_sequence = np.random.SeedSequence(seed)
        else:
            seed_sequence = seed
        rng = np.random.default_rng(seed_sequence)
        self.seed = _seed_record(seed)
        self.sampler = sampler = make_sampler(model, scorer, rng)
        # Which objects some camera sees, worked out for the samples written (sppl.seen).
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
        return RunResult(summary, best, self.trace)


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


def _check_same_inputs(out: Path, fingerprints: dict[str, str]) -> None:
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


def write_chains_record(model: Model, observations: Observations, out: Path, *, chains: int,
                        steps: int, seed: int, thin: int, burn: int | None, resume: bool = False,
                        lockstep: bool = False) -> dict[str, Any]:
    """``out/run.json`` of a run of several chains, each in ``out/chain_<i>/``: what
    ``combine_chains`` pools and ``sppl sample --resume`` reads. A resumed run's record must
    name the same model and observations (checked before any chain starts)."""
    out.mkdir(parents=True, exist_ok=True)
    fingerprints = {"model_sha256": model_fingerprint(model),
                    "observations_sha256": observations_fingerprint(observations)}
    if resume and (out / "run.json").exists():
        _check_same_inputs(out, fingerprints)
    meta = {
        "sppl_version": __version__,
        "seed": seed,
        "chains": chains,
        "steps": steps,
        "thin": thin,
        "burn": burn,
        "model": str(model.path) if model.path else None,
        "observations": str(observations.root),
        "chain_folders": [chain_folder(out, i).name for i in range(chains)],
        **fingerprints,
        **({"lockstep": True} if lockstep else {}),
    }
    (out / "run.json").write_text(json.dumps(meta, indent=2))
    return meta


def _chain_worker(source, path, observations, out, steps, seed, thin, burn, index, extra, done,
                  errors, resume=False, checkpoint_seconds=CHECKPOINT_SECONDS) -> None:
    """One chain in its own process (and so with its own GL context). SIGINT is left to the
    parent, which stops the chains with SIGTERM: run_chain then ends as if interrupted."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from .lang import compile_model

        model = compile_model(source, path) if path else compile_model(source)

        def tick(step, trace, best, sampler):
            done[index] = step
            return False

        run_chain(model, observations, Path(out), steps=steps, seed=seed, thin=thin, burn=burn,
                  progress=False, extra=extra, callback=tick, resume=resume,
                  checkpoint_seconds=checkpoint_seconds)
    except SpplError as e:
        errors.put((index, str(e), _traceback(), True))
        raise SystemExit(1) from None
    except BaseException as e:  # noqa: BLE001 - reported by the parent as one line
        errors.put((index, _one_line(e), _traceback(), False))
        raise SystemExit(1) from None


def _traceback() -> str:
    import traceback

    return traceback.format_exc()


def _one_line(e: BaseException) -> str:
    """An exception that is not sppl's, as one line: the file and the system's reason for an
    OSError, else the exception's type and the first line of its message."""
    if isinstance(e, OSError) and e.strerror:
        where = f"{e.filename}: " if e.filename is not None else ""
        return f"{where}{e.strerror}"
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


class ChainTraceback(Exception):
    """A chain worker's traceback, as the cause of the error the parent raises: shown with
    ``--debug``, left out of the one-line message otherwise."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f"\n\nthe chain's own traceback:\n{self.text.rstrip()}"


def run_chains(
    model: Model,
    observations: Observations,
    out: Path,
    *,
    chains: int,
    steps: int,
    seed: int,
    thin: int = 1,
    burn: int | None = None,
    progress: bool | None = None,
    resume: bool = False,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
    lockstep: bool = False,
) -> RunResult:
    """Run ``chains`` chains in parallel processes, chain i into ``out/chain_<i>/`` with the
    i-th stream of ``SeedSequence(seed).spawn(chains)``, then combine them into ``out/``'s
    ``run.json``, ``summary.json`` and ``summary.txt`` (the MAP over all chains, the
    posterior over the pooled samples, R-hat and ESS of the label-invariant quantities).
    One chain is exactly ``run_chain`` into ``out/``. Ctrl-C or SIGTERM stop every chain
    with what it has drawn on disk, and the combined summary is still written. With
    ``resume=True`` each chain continues from its own checkpoint (see ``run_chain``). With
    ``lockstep=True`` the chains run in this process instead, advanced together
    (``sppl.lockstep``), and draw the same samples."""
    if chains == 1:
        return run_chain(model, observations, out, steps=steps, seed=seed, thin=thin, burn=burn,
                         progress=progress, resume=resume, checkpoint_seconds=checkpoint_seconds,
                         extra={"lockstep": True} if lockstep else None)
    out.mkdir(parents=True, exist_ok=True)
    with hold(out):  # one writer per run folder (sppl.lock), for the run's life
        return _run_chains(model, observations, out, chains=chains, steps=steps, seed=seed,
                           thin=thin, burn=burn, progress=progress, resume=resume,
                           checkpoint_seconds=checkpoint_seconds, lockstep=lockstep)


def _run_chains(model, observations, out, *, chains, steps, seed, thin, burn, progress, resume,
                checkpoint_seconds, lockstep) -> RunResult:
    import multiprocessing as mp

    write_chains_record(model, observations, out, chains=chains, steps=steps, seed=seed,
                        thin=thin, burn=burn, resume=resume, lockstep=lockstep)
    seeds = chain_seeds(seed, chains)
    if lockstep:
        from .lockstep import run_lockstep

        t0 = time.monotonic()
        interrupted = run_lockstep(model, observations, out, chains=chains, steps=steps,
                                   seed=seed, thin=thin, burn=burn, progress=progress,
                                   resume=resume, checkpoint_seconds=checkpoint_seconds)
        summary = combine_chains(out, seconds=time.monotonic() - t0, interrupted=interrupted)
        return RunResult(summary, None, None)
    ctx = mp.get_context("spawn")
    done = ctx.Array("q", chains)
    errors = ctx.Queue()
    procs = [
        ctx.Process(
            target=_chain_worker, name=f"sppl-chain-{i}",
            args=(model.source, str(model.path) if model.path else None, observations,
                  str(chain_folder(out, i)), steps, seeds[i], thin, burn, i,
                  chain_extra(i, chains, seed), done, errors, resume,
                  checkpoint_seconds),
        )
        for i in range(chains)
    ]

    def on_term(signum, frame):
        raise Stop()

    previous = signal.signal(signal.SIGTERM, on_term)
    interrupted = False
    stopped: set[int] = set()  # the chains this process stopped because another one failed
    t0 = time.monotonic()
    bar = tqdm(total=steps * chains, disable=None if progress is None else not progress,
               unit="step", dynamic_ncols=True, leave=False)
    try:
        for p in procs:
            p.start()
        while any(p.is_alive() for p in procs):
            time.sleep(0.25)
            bar.update(sum(done[:]) - bar.n)
            if any(p.exitcode not in (0, None) for p in procs):  # a chain failed: stop the rest
                for i, p in enumerate(procs):
                    if p.is_alive():
                        stopped.add(i)
                        p.terminate()
                break
    except (KeyboardInterrupt, Stop):
        interrupted = True
        for p in procs:
            if p.pid is not None and p.is_alive():
                p.terminate()  # SIGTERM: the chain stops and summarises what it has
    finally:
        signal.signal(signal.SIGTERM, previous)
        for p in procs:
            if p.pid is not None:
                p.join()
        bar.close()
    seconds = time.monotonic() - t0
    failures = []
    while True:
        try:
            failures.append(errors.get(timeout=0.1))
        except Exception:
            break
    reported = {f[0] for f in failures}
    for i, p in enumerate(procs):  # a chain that died without a word (a signal, a crash)
        if p.exitcode not in (0, None) and i not in reported | stopped and not interrupted:
            how = (f"was killed by signal {-p.exitcode}" if p.exitcode < 0
                   else f"exited with status {p.exitcode}")
            failures.append((i, f"its process {how} before it could report why", "", True))
    if failures and not interrupted:
        index, message, trace, ours = sorted(failures)[0]
        hint = None if ours else "`sppl --debug sample ...` shows where it failed"
        error = SpplError(f"chain {index} failed: {message.strip()}", hint=hint)
        raise error from (ChainTraceback(trace) if trace else None)
    summary = combine_chains(out, seconds=seconds, interrupted=interrupted)
    return RunResult(summary, None, None)


def combine_chains(out: Path, *, seconds: float | None = None,
                   interrupted: bool | None = None) -> dict[str, Any]:
    """Pool the chains of a run folder into its top-level ``summary.json`` and
    ``summary.txt``: the posterior over every chain's samples after its burn-in, the best MAP
    of any chain, move counts summed, and R-hat and ESS of the label-invariant quantities."""
    meta = json.loads((out / "run.json").read_text())
    folders = [out / name for name in meta["chain_folders"]]
    summaries, samples, used = [], [], []
    for i, folder in enumerate(folders):
        if not (folder / "summary.json").exists():
            continue  # stopped before it started
        s = json.loads((folder / "summary.json").read_text())
        summaries.append(s)
        used.append(i)
        samples += read_samples(folder / "samples.jsonl")
    if not summaries:
        raise SpplError(f"{out}: no chain wrote a summary")
    best = max(range(len(summaries)), key=lambda k: summaries[k]["map"]["score"])
    map_sample = {"chain": used[best], **summaries[best]["map"]}
    moves: dict[str, dict[str, int]] = {}
    for s in summaries:
        for key, c in s["acceptance_by_class"].items():
            m = moves.setdefault(key, {"proposed": 0, "accepted": 0})
            m["proposed"] += c["proposed"]
            m["accepted"] += c["accepted"]
            if c.get("nan"):
                m["nan"] = m.get("nan", 0) + c["nan"]
    summary = summarise(
        samples,
        list(summaries[0]["class_counts"]),
        map_sample,
        moves,
        burn=min(s["burn"] for s in summaries),
        extra={
            "chains": len(folders),
            "chains_used": used,
            "steps_done": min(s["steps_done"] for s in summaries),
            "chain_steps_done": [s["steps_done"] for s in summaries],
            "seconds": seconds if seconds is not None else max(s["seconds"] for s in summaries),
            "interrupted": (any(s["interrupted"] for s in summaries) if interrupted is None
                            else interrupted or any(s["interrupted"] for s in summaries)),
            "seed": meta["seed"],
        },
    )
    try:
        from .posterior import diagnostics, load_run, posterior_arrays

        summary["diagnostics"] = diagnostics(posterior_arrays(load_run(out, summary=summary)))
    except SpplError as e:  # too few samples for the diagnostics: the summary stands without
        summary["diagnostics_error"] = str(e)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "summary.txt").write_text(format_summary(summary) + "\n")
    return summary
