"""Running several chains of one scene: each in its own process (or all in this one, in
lockstep), then their samples combined."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from .._version import __version__
from ..data.observations import Observations
from ..errors import RunError, SpplError
from ..model.types import Model
from ..output.samples import format_summary, read_samples, summarise
from .checkpoint import model_fingerprint, observations_fingerprint
from .lock import hold
from .lockstep import run_lockstep
from .run import (
    CHECKPOINT_SECONDS,
    RunResult,
    Stop,
    chain_extra,
    chain_folder,
    chain_seeds,
    check_same_inputs,
    in_memory,
    run_chain,
)


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
        check_same_inputs(out, fingerprints)
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
        from ..lang import compile_model

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
    out: Path | None,
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
    (``sppl.runs.lockstep``), and draw the same samples. The result holds every chain's
    samples (``RunResult.chain_samples``); with ``out=None`` the run keeps nothing on disk."""
    if out is None:
        if resume:
            raise RunError("a run without an output folder cannot be resumed",
                           hint="give the run a folder (out=...) to resume it later")
        return in_memory(run_chains, model, observations, chains=chains, steps=steps,
                         seed=seed, thin=thin, burn=burn, progress=progress,
                         checkpoint_seconds=checkpoint_seconds, lockstep=lockstep)
    if chains == 1:
        return run_chain(model, observations, out, steps=steps, seed=seed, thin=thin, burn=burn,
                         progress=progress, resume=resume, checkpoint_seconds=checkpoint_seconds,
                         extra={"lockstep": True} if lockstep else None)
    out.mkdir(parents=True, exist_ok=True)
    with hold(out):  # one writer per run folder (sppl.runs.lock), for the run's life
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

        t0 = time.monotonic()
        interrupted = run_lockstep(model, observations, out, chains=chains, steps=steps,
                                   seed=seed, thin=thin, burn=burn, progress=progress,
                                   resume=resume, checkpoint_seconds=checkpoint_seconds)
        summary = combine_chains(out, seconds=time.monotonic() - t0, interrupted=interrupted)
        return RunResult(summary, None, None, _sample_files(out, chains))
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
    return RunResult(summary, None, None, _sample_files(out, chains))


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
        from ..output.posterior import diagnostics, load_run, posterior_arrays

        summary["diagnostics"] = diagnostics(posterior_arrays(load_run(out, summary=summary)))
    except SpplError as e:  # too few samples for the diagnostics: the summary stands without
        summary["diagnostics_error"] = str(e)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "summary.txt").write_text(format_summary(summary) + "\n")
    return summary


def _sample_files(out: Path, chains: int) -> tuple[Path, ...]:
    return tuple(chain_folder(out, i) / "samples.jsonl" for i in range(chains))
