"""Multiple-try jumps: births, deaths and replaces that weigh several candidates at once.

A single birth proposes one object from the birth proposal Q(y | x) (a class uniformly, its
parameters from ``sppl.infer.birth``), and is accepted only if that one object fits. With
``tries = M`` in the model's inference settings, a birth draws M candidates y_1..y_M from
Q(. | x) at once, scores each (one incremental render apiece), and proposes y_J with
probability proportional to its importance weight w(y) = pi(x + y) / Q(y | x). Its reverse, the
death of y from x' = x + y, draws M - 1 reference candidates z_j from Q(. | x) and counts y
among them. Then

    alpha_birth = q_death(x') (1/M) sum_j w(y_j) / pi(x)
    alpha_death = pi(x) / (q_death(x') (1/M) (w(y) + sum_j w(z_j)))

which satisfy detailed balance for the set-valued posterior (docs/inference.md has the
derivation; M = 1 gives the single-try ratios exactly). A replace does the same in the scene
x- without the replaced object: M candidates against M - 1 fresh references and the old object,

    alpha_replace = sum_j w(y_j) / (w(old) + sum_j w(z_j)),   w(y) = pi(x- + y) / Q(y | x-),

which is multiple-try Metropolis with independent proposals (Liu, Liang and Wong 2000).

The candidates cost renders, not acceptance: where the data say "an object is here" but not
which, M candidates of random classes and sizes let the chain take the one that fits, instead
of committing to the first that fits a little and growing it into the wrong shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.trace import SceneObject, Trace, make_object
from .moves import Proposal, log_q_birth, log_q_death


@dataclass(frozen=True)
class Tries:
    """What a multiple-try jump drew besides the object it proposes: its other candidates,
    and for a replace the reference candidates of its reverse."""

    others: tuple[SceneObject, ...]
    references: tuple[SceneObject, ...] = ()

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        return reverse(sampler, before, proposal, after)


def _draw(sampler, state: Trace, n: int, rng: np.random.Generator) -> list[SceneObject]:
    """n candidates from the birth proposal of ``state``."""
    model, classes = sampler.model, sampler.model.classes
    out = []
    for _ in range(n):
        cls = classes[int(rng.integers(len(classes)))]
        out.append(make_object(model, cls, sampler.birth.sample(cls, state, rng)))
    return out


def _log_weights(sampler, state: Trace, candidates) -> np.ndarray:
    """log w(y) = log pi(state + y) - log Q(y | state) of each candidate; -inf for one of zero
    prior (out of its domain, overlapping), which is not rendered. The candidates are scored
    together, so that a scorer can draw them in one pass."""
    proposals = [Proposal("birth", obj.cls.name, state.objects + (obj,), state.noise, (obj,))
                 for obj in candidates]
    scored = sampler.evaluate_batch([(state, p) for p in proposals])
    out = np.full(len(candidates), -math.inf)
    for i, (obj, new) in enumerate(zip(candidates, scored)):
        if new is not None and math.isfinite(new.score):
            out[i] = new.score - log_q_birth(sampler.model, obj.cls, obj.values, sampler.birth,
                                             state)
    return out


def _log_mean(log_w: np.ndarray) -> float:
    if not np.any(np.isfinite(log_w)):
        return -math.inf
    return float(np.logaddexp.reduce(log_w) - math.log(len(log_w)))


def _pick(log_w: np.ndarray, rng: np.random.Generator) -> int | None:
    if not np.any(np.isfinite(log_w)):
        return None
    p = np.exp(log_w - np.max(log_w))
    return int(rng.choice(len(log_w), p=p / p.sum()))


def _state_without(sampler, trace: Trace, k: int) -> Trace | None:
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    gone = trace.objects[k]
    return sampler.evaluate(trace, Proposal("death", gone.cls.name, rest, trace.noise, ()))


# -- births and deaths --------------------------------------------------------------------------


def propose_birth(sampler, trace: Trace, rng: np.random.Generator, tries: int,
                  candidates=None, chosen: int | None = None, place: int | None = None
                  ) -> Proposal:
    """A birth weighing ``tries`` candidates, the one proposed inserted at a uniform place;
    given ``candidates``, the ``chosen`` one and its ``place``, those instead of fresh draws
    (the reverse of a death)."""
    model = sampler.model
    cands = list(candidates) if candidates is not None else _draw(sampler, trace, tries, rng)
    log_w = _log_weights(sampler, trace, cands)
    j = chosen if chosen is not None else _pick(log_w, rng)
    if j is None:  # no candidate has positive prior: a birth that is rejected
        j, log_mean = 0, -math.inf
    else:
        log_mean = _log_mean(log_w)
    obj = cands[j]
    k = int(rng.integers(len(trace.objects) + 1)) if place is None else place
    objects = trace.objects[:k] + (obj,) + trace.objects[k:]
    n_after = len(objects)
    return Proposal(
        "birth", obj.cls.name, objects, trace.noise, (obj,),
        ratio_fn=lambda new: log_q_death(model, n_after) + log_mean - new.score,
        tries=Tries(tuple(c for i, c in enumerate(cands) if i != j)),
    )


def propose_death(sampler, trace: Trace, rng: np.random.Generator, tries: int,
                  k: int | None = None, references=None) -> Proposal | None:
    """The death of a uniformly chosen object (or object ``k``), weighed against ``tries``-1
    reference candidates from the birth proposal of the scene without it (or the given
    ``references``)."""
    n = len(trace.objects)
    if n == 0:
        return None
    model = sampler.model
    k = int(rng.integers(n)) if k is None else k
    gone = trace.objects[k]
    state = _state_without(sampler, trace, k)
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    if state is None:
        return Proposal("death", gone.cls.name, rest, trace.noise, (), -math.inf)
    refs = list(references) if references is not None else _draw(sampler, state, tries - 1, rng)
    log_w = np.append(_log_weights(sampler, state, refs),
                      trace.score - log_q_birth(model, gone.cls, gone.values, sampler.birth,
                                                state))
    ratio = trace.score - log_q_death(model, n) - _log_mean(log_w)
    return Proposal("death", gone.cls.name, rest, trace.noise, (), ratio,
                    tries=Tries(tuple(refs)))


# -- replace ----------------------------------------------------------------------------------


def propose_replace(sampler, trace: Trace, rng: np.random.Generator, tries: int,
                    k: int | None = None, candidates=None, references=None,
                    chosen: int | None = None) -> Proposal | None:
    """Replace object k (uniform) by the best-weighted of ``tries`` candidates drawn into the
    scene without it, against ``tries``-1 references and the old object."""
    n = len(trace.objects)
    if n == 0:
        return None
    k = int(rng.integers(n)) if k is None else k
    old = trace.objects[k]
    state = _state_without(sampler, trace, k)
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    if state is None:
        return None
    cands = list(candidates) if candidates is not None else _draw(sampler, state, tries, rng)
    refs = list(references) if references is not None else _draw(sampler, state, tries - 1, rng)
    log_w = _log_weights(sampler, state, cands)
    j = chosen if chosen is not None else _pick(log_w, rng)
    if j is None:
        return Proposal("replace", old.cls.name, trace.objects, trace.noise, (), -math.inf)
    obj = cands[j]
    back = np.append(_log_weights(sampler, state, refs),
                     trace.score - log_q_birth(sampler.model, old.cls, old.values,
                                               sampler.birth, state))
    ratio = _log_mean(log_w) - _log_mean(back) + trace.score
    objects = rest[:k] + (obj,) + rest[k:]
    return Proposal("replace", old.cls.name, objects, trace.noise, (obj,),
                    ratio_fn=lambda new: ratio - new.score,
                    tries=Tries(tuple(c for i, c in enumerate(cands) if i != j), tuple(refs)))


# -- reverses, for the move checks ----------------------------------------------------------------


def reverse(sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
    """The multiple-try jump that undoes ``proposal`` with the same candidates: a birth's
    reverse is the death of the born object against the birth's other candidates, a death's
    the birth of the same object among its references, a replace's the replace back with the
    roles of candidates and references exchanged. Its log ratio is minus the forward's."""
    t: Tries = proposal.tries
    if proposal.move == "birth":
        k = next(i for i, o in enumerate(after.objects) if o is proposal.changed[0])
        return propose_death(sampler, after, sampler.rng, len(t.others) + 1, k, t.others)
    if proposal.move == "death":
        k = next((i for i, o in enumerate(after.objects) if o is not before.objects[i]),
                 len(after.objects))
        gone = before.objects[k]
        return propose_birth(sampler, after, sampler.rng, len(t.others) + 1,
                             candidates=[*t.others, gone], chosen=len(t.others), place=k)
    if proposal.move == "replace":
        new = proposal.changed[0]
        k = next(i for i, o in enumerate(after.objects) if o is new)
        old = before.objects[k]
        return propose_replace(sampler, after, sampler.rng, len(t.others) + 1, k,
                               candidates=[*t.references, old], references=t.others,
                               chosen=len(t.references))
    raise ValueError(f"no multiple-try reverse for a {proposal.move!r} proposal")
