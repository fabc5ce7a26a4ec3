"""The pair refit jump: two neighbouring objects fitted again one after the other, both taken
out of the scene first.

A chain read a kraft box and the tall yellow box behind it as one kraft box grown over both
and a small yellow box beside it (tabletop.scn's prior scene 18, 6,776 nats below the truth).
No move of one object mends it: a refit of the kraft box alone uncovers yellow pixels that the
small yellow box does not cover, and a refit of the yellow box alone cannot grow it into the
kraft box, which the no-overlap constraint forbids. A merge fits one object where two were.
Taken out together, the yellow box fitted first in the scene without either, then the kraft
box fitted beside it, the pair stands 2,307 nats above the state. (On shapes.scn's scene 19,
a red cube read too small with a needle cone patching its rim, the pair gains 2,112 nats, but
a refit of the cube alone already gains 1,533.)

    pair refit (x- + a + b -> x- + a' + b'): i uniform among the n objects, j among the others
        with probability v(i, j) (the merge's partner weights without their colour term:
        the objects that share pixels here are of different colours), a' from the refit
        proposal of a's class into x- starting from a (``sppl.infer.fit``: around the fit of
        x- + a, or a birth into x-), then b' from the refit proposal of b's class into x- + a'
        starting from b;

and its reverse is the same jump from x- + a' + b', choosing the same places. Each fit is a
deterministic function of the scene it fits into (rendered in full, with the objects in the
same order both ways) and of the object it starts from, so

    log alpha = log pi(x- + a' + b') - log pi(x- + a + b) + log v'(i, j) - log v(i, j)
                + log q(a | x-, fit from a') + log q(b | x- + a, fit from b')
                - log q(a' | x-, fit from a) - log q(b' | x- + a', fit from b)

with v' the partner weights in the proposed state; the 1/n of choosing i cancels. The two
reverse fits are deferred (``Sampler.decide``), bounded without a fit as a refit's is. Classes
stay: a refit changes a class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.trace import SceneObject, Trace, make_object
from . import fit as fitting
from . import merge
from .moves import Proposal


@dataclass(frozen=True)
class PairRefit:
    """What a pair refit used: the scene without both objects, and their places."""

    state: Trace
    first: int
    second: int

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        olds = (before.objects[self.first], before.objects[self.second])
        return propose_pair_refit(sampler, after, sampler.rng, first=self.first,
                                  second=self.second, targets=olds, state=self.state)


def partner_log_weights(sampler, objects, i: int) -> np.ndarray:
    """log v(i, j) over the places j of ``objects``: the merge's nearness on the ground or in
    a camera's image, without its colour term."""
    return merge.partner_log_weights(objects, i, merge.screen_of(sampler), colour=False)


def _refitted(sampler, state: Trace, old: SceneObject, target: SceneObject | None,
              rng: np.random.Generator) -> tuple[SceneObject, dict]:
    """A draw of the refit proposal of ``old``'s class into ``state`` from ``old`` (or exactly
    ``target``), and the fit it is drawn around."""
    fitted = fitting.fit(sampler, state, old.cls, old)
    if target is None:
        target = make_object(sampler.model, old.cls,
                             fitting.sample(sampler, state, old.cls, fitted, rng))
    return target, fitted


def propose_pair_refit(sampler, trace: Trace, rng: np.random.Generator,
                       first: int | None = None, second: int | None = None,
                       targets: tuple[SceneObject, SceneObject] | None = None,
                       state: Trace | None = None) -> Proposal | None:
    """A pair refit of objects ``first`` (uniform) and ``second`` (near it); given
    ``targets``, the proposal of exactly those two (the reverse, through the same ``state``,
    the scene without both)."""
    objects = trace.objects
    n = len(objects)
    if n < 2:
        return None
    i = int(rng.integers(n)) if first is None else first
    logv = partner_log_weights(sampler, objects, i)
    j = int(rng.choice(n, p=np.exp(logv))) if second is None else second
    a, b = objects[i], objects[j]
    rest = tuple(o for p, o in enumerate(objects) if p not in (i, j))
    # The scene without both, and with the first refitted, rendered in full so that their
    # scores, and so the fits, are the same whichever state they are reached from.
    state = state if state is not None else sampler.make_trace(rest, trace.noise)
    new_a, fit_a = _refitted(sampler, state, a, targets and targets[0], rng)
    label = a.cls.name
    if not math.isfinite(new_a.log_prior):
        return Proposal("pair_refit", label, tuple(new_a if p == i else o for p, o
                                                   in enumerate(objects)),
                        trace.noise, (new_a,), -math.inf, tries=PairRefit(state, i, j))
    with_a = sampler.make_trace(rest + (new_a,), trace.noise)
    new_b, fit_b = _refitted(sampler, with_a, b, targets and targets[1], rng)
    proposed = tuple(new_a if p == i else new_b if p == j else o for p, o in enumerate(objects))
    if not math.isfinite(new_b.log_prior):
        return Proposal("pair_refit", label, proposed, trace.noise, (new_a, new_b), -math.inf,
                        tries=PairRefit(state, i, j))
    log_q_forward = (logv[j]
                     + fitting.log_mixture(sampler, state, a.cls, new_a.values, fit_a)
                     + fitting.log_mixture(sampler, with_a, b.cls, new_b.values, fit_b))
    log_q_choice_back = partner_log_weights(sampler, proposed, i)[j]
    # The reverse refits a from a' in x-, then b from b' in x- + a.
    back_a, bound_a = fitting.refitted_back(sampler, state, a, new_a)
    back_b, bound_b = fitting.refitted_back(
        sampler, sampler.make_trace(rest + (a,), trace.noise), b, new_b)
    return Proposal("pair_refit", label, proposed, trace.noise, (new_a, new_b),
                    log_q_choice_back - log_q_forward, tries=PairRefit(state, i, j),
                    deferred=lambda: back_a() + back_b(), deferred_bound=bound_a + bound_b)
