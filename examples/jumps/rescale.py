"""A jump added from outside sppl: "rescale" grows or shrinks one object by a random factor.

docs/walkthroughs/adding-a-jump.md walks through this file; tests/test_jumps.py registers the
jump, runs sppl's move checks and prior recovery with it, and shows that the same jump without
its Jacobian is caught by both.

A parameter move steps a size by a fixed amount, which is a large step for a small object and
a small one for a large object. Rescaling multiplies the size instead: object k (uniform among
the n objects) and one of its positive parameters p (uniform among its m) are chosen, and

    p' = p * exp(e),   e ~ Normal(0, STEP).

The reverse is the same jump choosing the same object and parameter (probability 1/(n m) both
ways) and the factor exp(-e) (the same normal density). In p the factor's density carries
the Jacobian of p -> log p, so q(p' | p) = N(e; 0, STEP) / p' and q(p | p') = N(-e; 0, STEP) / p:

    log q(reverse) - log q(forward) = log p' - log p.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sppl import Jump, Positive, Proposal, make_object

NAME = "rescale"
STEP = 1.0  # standard deviation of the log of the factor


def sizes(cls) -> list[str]:
    """The parameters a rescale may change: those of the positive reals."""
    return [p.name for p in cls.parameters if isinstance(p.domain, Positive)]


def rescaled(sampler, trace, k: int, name: str, value: float, ratio: float) -> Proposal:
    """``trace`` with parameter ``name`` of object ``k`` set to ``value``."""
    old = trace.objects[k]
    obj = make_object(sampler.model, old.cls, {**old.values, name: value})
    objects = trace.objects[:k] + (obj,) + trace.objects[k + 1 :]
    return Proposal(NAME, old.cls.name, objects, trace.noise, (obj,), ratio)


def propose(sampler, trace, rng: np.random.Generator) -> Proposal | None:
    if not trace.objects:
        return None
    k = int(rng.integers(len(trace.objects)))
    names = sizes(trace.objects[k].cls)
    if not names:
        return None
    name = names[int(rng.integers(len(names)))]
    old = trace.objects[k].values[name]
    new = old * math.exp(rng.normal(0.0, STEP))
    return rescaled(sampler, trace, k, name, new, math.log(new) - math.log(old))


def undo(sampler, before, proposal: Proposal, after) -> Proposal:
    """The rescale back: the same object and parameter, to the value it had before."""
    k = next(i for i, o in enumerate(after.objects) if o is proposal.changed[0])
    old, new = before.objects[k].values, after.objects[k].values
    name = next(p for p in sizes(after.objects[k].cls) if old[p] != new[p])
    return rescaled(sampler, after, k, name, old[name],
                    math.log(old[name]) - math.log(new[name]))


RESCALE = Jump(NAME, propose, reverse=NAME, undo=undo)


def propose_without_jacobian(sampler, trace, rng: np.random.Generator) -> Proposal | None:
    """The mistake the checks must catch: the factor taken as symmetric in p, its Jacobian
    left out (the reverse still has it)."""
    proposal = propose(sampler, trace, rng)
    return None if proposal is None else dataclasses.replace(proposal, log_q_ratio=0.0)


WITHOUT_JACOBIAN = Jump(NAME, propose_without_jacobian, reverse=NAME, undo=undo)
