"""Which objects a state could do without: the merge's choice of the object it takes away.

A chain that explained a cone with a shorter cone and a second, thin cone behind it that
paints the first one's tip, or a mug with a mug turned a little wrong and a small one where
its handle shows, holds an object whose death costs a few hundred nats where every other
object's costs thousands: it explains a sliver that its neighbour, refitted, would explain.
A merge of it into that neighbour leaves the state, but with the first object drawn
uniformly it comes once in n merges, each of which also has to draw the right partner.
The merge instead draws its first object k with probability

    q(k | x) = (1 - F) / n + F exp(D_k(x) / T) / sum_j exp(D_j(x) / T)

with D_k(x) = log p(x without k) - log p(x), the log joint its death would change, and T
(``NATS``) the scale at which one object counts as more dispensable than another. It is a
deterministic function of the state, computed the same way in a merge and in a split's
reverse (in the state the split proposes). F is the model's ``merge_focus`` setting; at 0
(the default) the choice is uniform and draws what it always drew. The uniform share keeps
every object's chance at least (1 - F) / n: the first object of a merge that builds one
large object out of many pieces is no more dispensable than the others.
"""

from __future__ import annotations

import math

import numpy as np

# Deaths a few hundred nats apart weigh e^(difference / NATS) against each other: a sliver
# that costs 100 to 300 nats to lose stands against real objects that cost thousands, and
# against each other two slivers weigh within a few times.
NATS = 100.0


def death_costs(sampler, trace) -> np.ndarray:
    """D_k of each object of ``trace``: the log joint of the state without it, less the
    state's. Cached on the trace: a merge that is refused leaves the chain where it was."""
    cached = trace.cache.get("death_costs")
    if cached is not None:
        return cached
    objects = trace.objects
    costs = np.array([
        sampler.make_trace(objects[:k] + objects[k + 1 :], trace.noise).score - trace.score
        for k in range(len(objects))
    ])
    trace.cache["death_costs"] = costs
    return costs


def log_probs(sampler, trace, focus: float | None = None) -> np.ndarray:
    """log q(k | trace) of the merge's first object, with the model's focus or ``focus``."""
    n = len(trace.objects)
    focus = sampler.model.inference.merge_focus if focus is None else focus
    if n == 0:
        return np.empty(0)
    if focus == 0.0:
        return np.full(n, -math.log(n))
    d = death_costs(sampler, trace) / NATS
    if not np.isfinite(d).any():
        # No object's death has a prior (a class of fixed count): the choice stays uniform.
        return np.full(n, -math.log(n))
    soft = np.exp(d - np.max(d[np.isfinite(d)]))
    return np.log((1.0 - focus) / n + focus * soft / soft.sum())


def log_prob_bound(sampler, n: int) -> float:
    """An upper bound of any object's log q(k | x) in a state of ``n`` objects, with no
    death scored."""
    focus = sampler.model.inference.merge_focus
    return math.log((1.0 - focus) / n + focus)


def choose(sampler, trace, rng: np.random.Generator) -> int:
    """The merge's first object, drawn from ``log_probs``; without a focus, one integer from
    ``rng``, as the merge always drew it, so that a model without a focus keeps its chains."""
    n = len(trace.objects)
    if sampler.model.inference.merge_focus == 0.0:
        return int(rng.integers(n))
    p = np.exp(log_probs(sampler, trace))
    return int(rng.choice(n, p=p / p.sum()))
