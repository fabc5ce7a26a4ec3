"""Parallel tempering: a ladder of chains whose hotter rungs see the likelihood flattened.

A chain that explained a large sphere with three small objects sits thousands of nats below
the right scene, and no single move gets it there: every path goes through states the
likelihood rules out. With ``tempered = K`` in the model's inference block the chain is the
coldest of K chains, run in lockstep in one process on one scorer: rung i targets

    pi_i(x) proportional to p(x) L(x)^beta_i,   beta_i = b^(i / (K - 1)),  b = tempered_from,

so beta_0 = 1 (the posterior, the chain that is sampled and written) and the hottest rung
sees the likelihood raised to b, where wrong explanations are cheap to leave. Every rung runs
the model's own sweep (its acceptance ratios with the likelihood to its power). After each
sweep, neighbouring rungs (i, i + 1) propose to swap their states, the pairs starting at rung
0 on even sweeps and at rung 1 on odd ones, each accepted with probability

    min(1, exp((beta_i - beta_{i+1}) (log L(x_{i+1}) - log L(x_i)))),

the Metropolis-Hastings ratio of the swap under the product of the rungs' targets (the priors
cancel). Each swap leaves that product invariant, and so does every rung's sweep, so the
ladder does too, and the coldest rung's marginal is the posterior. During an annealed warm-up
each rung's power is also multiplied by the warm-up's.

The hotter rungs start where the chain starts, and their states, generators and warm-ups are
part of the checkpoint, so a resumed ladder continues exactly. The swaps are counted as
"swap" moves in the chain's acceptance table, per pair of rungs.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.trace import Trace
from ..scoring.protocol import ScorerProtocol
from .chain import Sampler, accept
from .records import trace_from_record, trace_record


def ladder(rungs: int, hottest: float) -> list[float]:
    """The rungs' powers of the likelihood, from 1 down to ``hottest``, geometric."""
    if rungs == 1:
        return [1.0]
    return [hottest ** (i / (rungs - 1)) for i in range(rungs)]


def make_sampler(model, scorer: ScorerProtocol, rng: np.random.Generator) -> Sampler:
    """The sampler a run uses: the tempered ladder where the model asks for one."""
    if model.inference.tempered > 1:
        return TemperedSampler(model, scorer, rng)
    return Sampler(model, scorer, rng)


class TemperedSampler(Sampler):
    """The coldest rung of a tempered ladder, driving the others: its ``sweep`` sweeps every
    rung and then swaps neighbours, and returns the coldest rung's state."""

    def __init__(self, model, scorer: ScorerProtocol, rng: np.random.Generator) -> None:
        super().__init__(model, scorer, rng)
        self.powers = ladder(model.inference.tempered, model.inference.tempered_from)
        # The hotter rungs' generators are spawned from a draw of this chain's, so a seed
        # fixes the whole ladder.
        seeds = np.random.SeedSequence(int(rng.integers(2**63))).spawn(len(self.powers) - 1)
        # The rungs share this chain's model (its region bound to the cameras), so that their
        # states, which swaps pass between them, hold objects of the same classes.
        self.hot = [Sampler(self.model, scorer, np.random.default_rng(s)) for s in seeds]
        for sampler, power in zip(self.hot, self.powers[1:]):
            sampler.power = power
        self.hot_traces: list[Trace] | None = None

    def sweep_steps(self, trace: Trace):
        if self.hot_traces is None:
            self.hot_traces = [trace] * len(self.hot)
        first = self.warmup.sweep % 2
        trace = yield from super().sweep_steps(trace)
        for i, sampler in enumerate(self.hot):
            self.hot_traces[i] = yield from sampler.sweep_steps(self.hot_traces[i])
        return self.swap(trace, first)

    def adjoint_sweep_steps(self, trace: Trace):
        raise NotImplementedError("a tempered ladder has no adjoint sweep: simulation-based "
                                  "calibration checks the rungs' own kernel")

    def swap(self, cold: Trace, first: int) -> Trace:
        """The swaps of neighbouring rungs (first, first + 1), (first + 2, first + 3), ...;
        the coldest rung's state after them."""
        states = [cold, *self.hot_traces]
        warm = self.warmup.beta
        for i in range(first, len(states) - 1, 2):
            a, b = states[i], states[i + 1]
            with np.errstate(invalid="ignore"):
                log_alpha = (warm * (self.powers[i] - self.powers[i + 1])
                             * (b.log_likelihood - a.log_likelihood))
            label = f"{i}<->{i + 1}"
            if math.isnan(log_alpha):
                self.stats.record_nan("swap", label)
                continue
            swapped = accept(log_alpha, self.rng)
            self.stats.record("swap", label, swapped)
            if swapped:
                states[i], states[i + 1] = b, a
        self.hot_traces = states[1:]
        return states[0]

    # -- checkpoints -----------------------------------------------------------------------

    def state_dict(self) -> dict:
        hot = []
        for i, sampler in enumerate(self.hot):
            hot.append({
                "rng": sampler.rng.bit_generator.state,
                "warmup": sampler.warmup.state_dict(),
                "trace": (None if self.hot_traces is None
                          else trace_record(self.hot_traces[i])),
            })
        return {**super().state_dict(), "hot": hot}

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        records = state["hot"]
        if len(records) != len(self.hot):
            raise ValueError(f"the checkpoint has {len(records) + 1} tempered chains, the "
                             f"model {len(self.hot) + 1}")
        traces = []
        for sampler, record in zip(self.hot, records):
            sampler.rng.bit_generator.state = record["rng"]
            sampler.warmup.load_state_dict(record["warmup"])
            if record["trace"] is not None:
                traces.append(trace_from_record(sampler, record["trace"], None))
        self.hot_traces = traces if len(traces) == len(self.hot) else None
