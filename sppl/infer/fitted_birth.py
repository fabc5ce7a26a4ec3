"""The fitted birth and its death: a whole object fitted to a blob of unexplained pixels.

A data-driven birth (``sppl.infer.birth``) puts its object near unexplained pixels but draws its
class, size and colour from the prior, so a small purple sphere where the scene has none is
born only when all of them happen to be right: a handful of times in thousands of sweeps.
A fitted birth fits the whole object first. From the state x it takes the seeds, ground
points where blobs of pixels are unexplained (``BirthProposal.seeds``, a deterministic
function of x's renders), picks a seed s, fits an object of each of the K classes with a
declared ground position starting at s (the refit's deterministic search, ``sppl.infer.fit``),
chooses a class c by those fits and draws the new object y around its fit:

    fitted birth (x -> x + y): s uniform among the S seeds of x, c with probability
        P(c | x, s) (``class_choice``: 0.95 times the softmax of the fits' log joints, plus
        0.05 / K), y ~ q_fit(y | fit(x, c, s)) (the refit's spreads and categorical draw),
        inserted at a uniform place;
    fitted death (x + y -> x): y uniform among the n objects of x + y, and the seed s that
        would have been its start chosen with probability rho(s | x, y): near y's position,
        (1 - FLOOR) exp(-d_s^2 / (2 RADIUS^2)) / sum + FLOOR / S, with d_s the distance from
        y to seed s of x.

The death's choice of s is an auxiliary draw: each (birth through s, death choosing s) pair is
a pair of mutual reverses, and detailed balance for each pair gives it for the sum over s.
So neither direction sums over the seeds, and each costs K fits:

    log alpha_birth = log pi(x + y) - log pi(x)
                      + log P(fitted death) - log n + log rho(s | x, y)
                      - log P(fitted birth) - log P(c | x, s) + log S
                      - log q_fit(y | fit(x, c, s)).

Both directions fit in x rendered in full (not incrementally), so that the fit, and the
seeds, are the same whichever way x is reached. The death's fits are deferred: computed only
where the ratio's upper bound cannot decide (``Sampler.decide``). A state without seeds
has no fitted birth, and the death of an object into such a state, or of an object of a class
without a position, is never proposed (its reverse is impossible). docs/inference.md has the
derivation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.trace import SceneObject, Trace, make_object
from ..model.types import ObjectClass
from . import fit as fitting
from .moves import Proposal, _log

# How a fitted death chooses the seed its object would have started from: a seed RADIUS metres
# away is e^(-1/2) times as likely as one at the object's place, and FLOOR of the choice is
# uniform, so that every seed keeps a chance (a fit can wander from its seed).
RADIUS = 0.5
FLOOR = 0.1


def placed_classes(model) -> tuple[ObjectClass, ...]:
    """The classes a fitted birth can make: those with a declared ground position."""
    return tuple(c for c in model.classes if c.position)


def seed_log_probs(seeds: np.ndarray, obj: SceneObject) -> np.ndarray:
    """log rho(s | x, y) over the seeds of x for the object y."""
    x, y = (obj.values[n] for n in obj.cls.position)
    d2 = ((seeds - (x, y)) ** 2).sum(axis=1)
    near = np.exp(-0.5 * (d2 - d2.min()) / RADIUS**2)
    return np.log((1.0 - FLOOR) * near / near.sum() + FLOOR / len(seeds))


def fit_at(sampler, state: Trace, cls: ObjectClass, seed, speck: bool = False
           ) -> tuple[dict, float]:
    """The deterministic fit of a ``cls`` object into ``state`` from the seed (the search of
    ``sppl.infer.fit`` from the seed, its other parameters from the best of fixed draws of
    the class's prior; and the same search with the place first held at the seed, the better
    winning), and the log joint of the state with it."""
    start = cls.sample_prior(np.random.default_rng(0))
    start[cls.position[0]], start[cls.position[1]] = float(seed[0]), float(seed[1])
    return fitting.scored_fit(sampler, state, cls, make_object(sampler.model, cls, start),
                              keep=cls.position, settle=cls.position, shrink=speck)


def class_choice(sampler, state: Trace, seed, speck: bool = False
                 ) -> tuple[list[dict], np.ndarray]:
    """Every placed class fitted at the seed, and log P(c | x, s) of choosing each
    (``fit.class_log_probs`` of their fits' log joints)."""
    fits, scores = zip(*(fit_at(sampler, state, cls, seed, speck)
                         for cls in placed_classes(sampler.model)))
    return list(fits), fitting.class_log_probs(scores)


@dataclass(frozen=True)
class FittedJump:
    """What a fitted birth or death used, for its reverse: the state x rendered in full, the
    seed, and the object's place in x + y."""

    state: Trace
    seed: int
    place: int

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        if proposal.move == "fitted_birth":
            return propose_fitted_death(sampler, after, sampler.rng, k=self.place,
                                        seed=self.seed, state=self.state)
        gone = before.objects[self.place]
        return propose_fitted_birth(sampler, after, sampler.rng, seed=self.seed,
                                    target=gone, place=self.place, state=self.state)


def full_state(sampler, trace: Trace, objects) -> Trace:
    """The scene of these objects under the trace's noise, rendered in full: the state a fit
    starts from, built alike by a move and its reverse."""
    return sampler.make_trace(tuple(objects), trace.noise)


def propose_fitted_birth(sampler, trace: Trace, rng: np.random.Generator,
                         seed: int | None = None, target: SceneObject | None = None,
                         place: int | None = None, state: Trace | None = None
                         ) -> Proposal | None:
    """A fitted birth into ``trace``; given ``target`` (with ``seed`` and ``place``), the
    proposal of exactly that object (a fitted death's reverse, through the same ``state``)."""
    model = sampler.model
    classes = placed_classes(model)
    if not classes:
        return None
    state = state if state is not None else full_state(sampler, trace, trace.objects)
    seeds = sampler.birth.seeds(state)
    if not len(seeds):
        return None
    s = int(rng.integers(len(seeds))) if seed is None else seed
    fits, log_p = class_choice(sampler, state, seeds[s], sampler.birth.speck_seeds(state)[s])
    c = fitting.draw_class(rng, log_p) if target is None else \
        fitting.class_index(classes, target.cls)
    cls, fitted = classes[c], fits[c]
    obj = target if target is not None else make_object(model, cls,
                                                        fitting.draw(cls, fitted, rng))
    n = len(trace.objects) + 1
    k = int(rng.integers(n)) if place is None else place
    objects = trace.objects[:k] + (obj,) + trace.objects[k:]
    tag = FittedJump(state, s, k)
    if not math.isfinite(obj.log_prior):
        return Proposal("fitted_birth", cls.name, objects, trace.noise, (obj,), -math.inf,
                        tries=tag)
    log_q_forward = (_log(sampler.jump["fitted_birth"]) + fitting.class_log_prob(log_p, c)
                     - math.log(len(seeds)) + fitting.log_density(cls, obj.values, fitted))
    log_q_back = (_log(sampler.jump["fitted_death"]) - math.log(n)
                  + float(seed_log_probs(seeds, obj)[s]))
    return Proposal("fitted_birth", cls.name, objects, trace.noise, (obj,),
                    log_q_back - log_q_forward, tries=tag)


def propose_fitted_death(sampler, trace: Trace, rng: np.random.Generator, k: int | None = None,
                         seed: int | None = None, state: Trace | None = None
                         ) -> Proposal | None:
    """The death of object k (uniform) of ``trace``, as the reverse of a fitted birth."""
    n = len(trace.objects)
    if n == 0:
        return None
    k = int(rng.integers(n)) if k is None else k
    gone = trace.objects[k]
    if not gone.cls.position:
        return None
    classes = placed_classes(sampler.model)
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    state = state if state is not None else full_state(sampler, trace, rest)
    seeds = sampler.birth.seeds(state)
    if not len(seeds):
        return None
    log_rho = seed_log_probs(seeds, gone)
    s = int(rng.choice(len(seeds), p=np.exp(log_rho - np.logaddexp.reduce(log_rho)))) \
        if seed is None else seed
    log_q_forward = _log(sampler.jump["fitted_death"]) - math.log(n) + float(log_rho[s])
    # log q(reverse), less the class choice and the fitted density of the object, which
    # are deferred (each class's fit); the choice's log probability is at most 0.
    log_q_back = _log(sampler.jump["fitted_birth"]) - math.log(len(seeds))

    def back() -> float:
        fits, log_p = class_choice(sampler, state, seeds[s],
                                   sampler.birth.speck_seeds(state)[s])
        c = fitting.class_index(classes, gone.cls)
        return fitting.class_log_prob(log_p, c) + fitting.log_density(classes[c], gone.values,
                                                                      fits[c])

    return Proposal(
        "fitted_death", gone.cls.name, rest, trace.noise, (), log_q_back - log_q_forward,
        tries=FittedJump(state, s, k), deferred=back,
        deferred_bound=fitting.log_density_bound(gone.cls, gone.values),
    )
