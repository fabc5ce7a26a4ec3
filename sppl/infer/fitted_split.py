"""The fitted split and its merge: an object that has grown over a smaller one beside it
gives that object back, fitted where the scene leaves pixels unexplained.

A chain that explained a large box and the small box beside it with one box grown over both
leaves the small box's pixels in the wrong colour. A fitted birth there is rejected: the
grown box still covers those pixels, so the newborn overlaps it. A split (``sppl.infer.merge``)
refits the grown box, but its newborns are births from the prior, seldom the small box. The
fitted split does both at once, from where the scene x = x- + y leaves pixels unexplained:

    fitted split (x- + y -> x- + i + j): y uniform among the m objects; a seed s uniform among
        the S seeds of x (``BirthProposal.seeds``, x rendered in full); the newborn i fitted
        at s into x- (``fitted_birth.class_choice``: every placed class fitted there, the
        class c with probability P(c | x-, s)) and drawn around its fit; then j, of y's
        class, from the refit proposal into x- + i starting from y (so it shrinks off the
        newborn's pixels); i at a uniform place of the m + 1, j at y's (the places carry
        no density: a scene is a set, as for a birth);
    fitted merge (x- + i + j -> x- + y): i uniform among the m + 1 objects (of a placed
        class), j its partner as a merge draws one (``merge.partner_log_weights``), y of j's
        class from the refit proposal into x- starting from j and i, in j's place; and the
        seed s the split would have used, chosen among the seeds of x- + y near i
        (``fitted_birth.seed_log_probs``, an auxiliary draw, as a fitted death's).

Every fit is a deterministic function of a state both directions build alike (x- and x- + i,
rendered in full with their objects in the same order) and of the objects it starts from, so

    log alpha_split = log pi(x- + i + j) - log pi(x- + y)
                      + log P(fitted merge) - log(m + 1) + log w(i, j) + log rho(s | x, i)
                      + log q_fit(y | x-, j, i)
                      - log P(fitted split) + log m + log S
                      - log P(c_i | x-, s) - log q_fit(i | fit(x-, c_i, s))
                      - log q_fit(j | x- + i, y),

the merge's the negative with the roles read back. Which object is born and which is fitted
are roles the move chooses: a split with its roles is undone by exactly one merge with the
same roles. A state without seeds has no fitted split, and a merge into such a state is
rejected (its reverse is impossible). docs/inference.md has the derivation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.trace import SceneObject, Trace, make_object
from . import fit as fitting
from .fitted_birth import class_choice, full_state, placed_classes, seed_log_probs
from .merge import partner_log_weights, screen_of
from .moves import Proposal, _log


@dataclass(frozen=True)
class FittedSplit:
    """What a fitted split or merge used, for its reverse: the scene x = x- + y and x-, both
    rendered in full, the seed, y's place in x, and j's and i's places in x- + i + j."""

    whole: Trace
    state: Trace
    seed: int
    single: int
    fitted_place: int
    born_place: int

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        if proposal.move == "fitted_split":
            return propose_fitted_merge(sampler, after, sampler.rng, i=self.born_place,
                                        j=self.fitted_place, seed=self.seed,
                                        target=before.objects[self.single], whole=self.whole,
                                        state=self.state)
        return propose_fitted_split(sampler, after, sampler.rng, k=self.single, seed=self.seed,
                                    place=self.born_place,
                                    born=before.objects[self.born_place],
                                    fitted=before.objects[self.fitted_place],
                                    whole=self.whole, state=self.state)


def newborn_log_density(classes, state: Trace, born: SceneObject, fits, log_p) -> float:
    """log P(c_i | x-, s) + log q_fit(i | fit(x-, c_i, s)) of the newborn, from the class
    choice at the seed (looked up when called, so that a test can put a wrong one in its
    place)."""
    c = fitting.class_index(classes, born.cls)
    return fitting.class_log_prob(log_p, c) + fitting.log_density(classes[c], born.values, fits[c])


def propose_fitted_split(sampler, trace: Trace, rng: np.random.Generator, k: int | None = None,
                         seed: int | None = None, place: int | None = None,
                         born: SceneObject | None = None, fitted: SceneObject | None = None,
                         whole: Trace | None = None, state: Trace | None = None
                         ) -> Proposal | None:
    """Split object k (uniform) into a newborn fitted at a seed of the scene (uniform) and the
    object refitted beside it; given ``born`` and ``fitted`` (with ``k``, ``seed`` and
    ``place``), the proposal of exactly those (a fitted merge's reverse)."""
    objects = trace.objects
    m = len(objects)
    model = sampler.model
    classes = placed_classes(model)
    if m < 1 or not classes:
        return None
    whole = whole if whole is not None else full_state(sampler, trace, objects)
    seeds = sampler.birth.seeds(whole)
    if not len(seeds):
        return None
    k = int(rng.integers(m)) if k is None else k
    s = int(rng.integers(len(seeds))) if seed is None else seed
    old = objects[k]
    rest = objects[:k] + objects[k + 1 :]
    state = state if state is not None else full_state(sampler, trace, rest)
    fits, log_p = class_choice(sampler, state, seeds[s])
    if born is None:
        c = fitting.draw_class(rng, log_p)
        born = make_object(model, classes[c], fitting.draw(classes[c], fits[c], rng))
    p = int(rng.integers(m + 1)) if place is None else place
    j = k if k < p else k + 1
    tag = FittedSplit(whole, state, s, k, j, p)
    label = old.cls.name
    if not math.isfinite(born.log_prior):
        return None  # rejected before j is fitted: nothing to render or to reverse
    beside = full_state(sampler, trace, rest + (born,))
    forward = fitting.fit(sampler, beside, old.cls, old)
    if fitted is None:
        fitted = make_object(model, old.cls, fitting.sample(sampler, beside, old.cls, forward, rng))
    replaced = objects[:k] + (fitted,) + objects[k + 1 :]
    split = replaced[:p] + (born,) + replaced[p:]
    if not math.isfinite(fitted.log_prior):
        return Proposal("fitted_split", label, split, trace.noise, (fitted, born), -math.inf,
                        tries=tag)
    log_q_forward = (_log(sampler.jump["fitted_split"]) - math.log(m) - math.log(len(seeds))
                     + newborn_log_density(classes, state, born, fits, log_p)
                     + fitting.log_mixture(sampler, beside, old.cls, fitted.values, forward))
    logw = partner_log_weights(split, p, screen_of(sampler))
    # log q(reverse), less the merged object's fitted density, which is deferred.
    log_q_back = (_log(sampler.jump["fitted_merge"]) - math.log(m + 1) + float(logw[j])
                  + float(seed_log_probs(seeds, born)[s]))
    back, bound = fitting.refitted_back(sampler, state, old, fitted, also=(born,))
    return Proposal("fitted_split", label, split, trace.noise, (fitted, born),
                    log_q_back - log_q_forward, tries=tag, deferred=back, deferred_bound=bound)


def propose_fitted_merge(sampler, trace: Trace, rng: np.random.Generator, i: int | None = None,
                         j: int | None = None, seed: int | None = None,
                         target: SceneObject | None = None, whole: Trace | None = None,
                         state: Trace | None = None) -> Proposal | None:
    """Merge object i (uniform; a fitted split's newborn) into its partner j, refitted over
    both; given ``target`` (with ``i``, ``j`` and ``seed``), the proposal of exactly that
    object (a fitted split's reverse)."""
    objects = trace.objects
    n = len(objects)
    model = sampler.model
    classes = placed_classes(model)
    if n < 2 or not classes:
        return None
    i = int(rng.integers(n)) if i is None else i
    born = objects[i]
    if not born.cls.position:
        return None  # no fitted split gives a newborn of this class
    logw = partner_log_weights(objects, i, screen_of(sampler))
    j = int(rng.choice(n, p=np.exp(logw))) if j is None else j
    piece = objects[j]
    rest = tuple(o for p, o in enumerate(objects) if p not in (i, j))
    state = state if state is not None else full_state(sampler, trace, rest)
    forward = fitting.fit(sampler, state, piece.cls, piece, also=(born,))
    new = target if target is not None else make_object(
        model, piece.cls, fitting.sample(sampler, state, piece.cls, forward, rng))
    merged = tuple(new if p == j else o for p, o in enumerate(objects) if p != i)
    k = j - (j > i)
    label = piece.cls.name
    if not math.isfinite(new.log_prior):
        return Proposal("fitted_merge", label, merged, trace.noise, (new,), -math.inf,
                        tries=FittedSplit(None, state, -1, k, j, i))
    whole = whole if whole is not None else full_state(sampler, trace, merged)
    seeds = sampler.birth.seeds(whole)
    if not len(seeds):
        return None  # no fitted split leaves x- + y: rejected, as it has no reverse
    log_rho = seed_log_probs(seeds, born)
    s = int(rng.choice(len(seeds), p=np.exp(log_rho - np.logaddexp.reduce(log_rho)))) \
        if seed is None else seed
    tag = FittedSplit(whole, state, s, k, j, i)
    log_q_forward = (_log(sampler.jump["fitted_merge"]) - math.log(n) + float(logw[j])
                     + float(log_rho[s])
                     + fitting.log_mixture(sampler, state, piece.cls, new.values, forward))
    # log q(reverse), less the newborn's class choice and fitted density and the refit's
    # density of j, which are deferred (every placed class fitted at the seed, and one fit).
    log_q_back = _log(sampler.jump["fitted_split"]) - math.log(n - 1) - math.log(len(seeds))
    beside = full_state(sampler, trace, rest + (born,))

    def back() -> float:
        fits, log_p = class_choice(sampler, state, seeds[s])
        shrunk = fitting.fit(sampler, beside, new.cls, new)
        return (newborn_log_density(classes, state, born, fits, log_p)
                + fitting.log_mixture(sampler, beside, piece.cls, piece.values, shrunk))

    bound = (fitting.log_density_bound(born.cls, born.values)
             + fitting.log_mixture_bound(sampler, beside, piece.cls, piece.values))
    return Proposal("fitted_merge", label, merged, trace.noise, (new,),
                    log_q_back - log_q_forward, tries=tag, deferred=back, deferred_bound=bound)
