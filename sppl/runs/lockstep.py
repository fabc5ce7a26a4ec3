"""Several chains advanced in lockstep by one process (``sppl sample --chains N --lockstep``).

Each chain is its own ``Sampler`` with its own generator, seeded as ``run_chains`` seeds its
processes, so chain i here is chain i there, sample for sample. The chains share one scorer
(one GL context): a round of ``sweep_together`` runs every chain's sweep up to its next
proposal evaluation and answers all of them with one ``Scorer.evaluate_batch`` call, which
draws the full-scene hypotheses together. A chain's randomness never depends on another's, so
the order in which a round serves them changes nothing.
"""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from ..data.observations import Observations
from ..infer.chain import evaluate_batch
from ..model.types import Model
from ..scoring.scorer import Scorer


def sweep_together(samplers, traces) -> list:
    """One sweep of every chain, from its trace; the chains' next traces. The samplers
    share one scorer."""
    sweeps = [sampler.sweep_steps(trace) for sampler, trace in zip(samplers, traces)]
    out = list(traces)
    answers = {i: None for i in range(len(sweeps))}  # sending None starts a generator
    while answers:
        requests = {}
        for i, answer in answers.items():
            try:
                requests[i] = sweeps[i].send(answer)
            except StopIteration as end:
                out[i] = end.value
        evaluated = evaluate_batch([(samplers[i], *requests[i]) for i in requests])
        answers = dict(zip(requests, evaluated))
    return out


def run_lockstep(model: Model, observations: Observations, out: Path, *, chains: int,
                 steps: int, seed: int, thin: int = 1, burn: int | None = None,
                 progress: bool | None = None, resume: bool = False,
                 checkpoint_seconds: float | None = None, renderer=None) -> bool:
    """Run ``chains`` chains into ``out/chain_<i>/`` as ``run_chains`` lays them out, each
    written exactly as ``run_chain`` writes it; whether they were interrupted. A resumed chain
    continues from its own checkpoint, so the chains may start a few sweeps apart; each
    stops at ``steps``. Ctrl-C or SIGTERM stop every chain at the end of the round."""
    from ..render import Renderer
    from .run import (
        CHECKPOINT_SECONDS,
        ChainRun,
        Stop,
        StopRequest,
        chain_extra,
        chain_folder,
        chain_seeds,
    )

    scorer = Scorer(model, observations, renderer or Renderer(model.render))
    seeds = chain_seeds(seed, chains)
    runs: list[ChainRun] = []
    stopped = [False] * chains
    try:
        for i in range(chains):
            runs.append(ChainRun(
                model, observations, chain_folder(out, i), steps=steps, seed=seeds[i],
                scorer=scorer, thin=thin, burn=burn, resume=resume,
                checkpoint_seconds=(CHECKPOINT_SECONDS if checkpoint_seconds is None
                                    else checkpoint_seconds),
                extra={**chain_extra(i, chains, seed), "lockstep": True},
            ))
        bar = tqdm(total=steps * chains, initial=sum(r.start for r in runs),
                   disable=None if progress is None else not progress,
                   unit="step", dynamic_ncols=True, leave=False)
        try:
            with StopRequest() as stop:
                while not stop.requested:
                    live = [r for r in runs if r.done < steps]
                    if not live:
                        break
                    traces = sweep_together([r.sampler for r in live], [r.trace for r in live])
                    for r, trace in zip(live, traces):
                        r.after_sweep(r.done + 1, trace)
                    bar.update(len(live))
                    if stop.requested:
                        break
                    for r in live:
                        r.checkpoint_if_due()
                stopped = [stop.requested and r.done < steps for r in runs]
                for r in runs:
                    r.save()
        except Stop:
            stopped = [True] * chains  # stopped mid-round: the last checkpoints stand
        finally:
            bar.close()
    finally:
        for r in runs:
            r.close()
    for r, interrupted in zip(runs, stopped):
        r.finish(interrupted)
    return any(stopped)
