"""The moves of the sampler, derived from the model's declared classes.

Nothing here names a concrete class: every move is built from what ``ObjectClass`` declares
(parameters, domains, priors, proposal scales, rate). Each proposal carries
``log_q_ratio = log q(reverse) - log q(forward)``, so that the acceptance ratio is

    log alpha = score(new) - score(old) + log_q_ratio (+ ratio_fn(new) + deferred())

with the scores of ``sppl.model.trace`` (densities with respect to the unit-rate marked Poisson
process, so the scene is a set). The forward and reverse densities of the model jumps are
written out as functions of their own (``log_q_birth`` and friends) so that a move and its
reverse can be checked against each other; docs/inference.md derives them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import SpplError
from ..model.domains import Finite
from ..model.jumps import jump, jump_names
from ..model.trace import SceneObject, Trace, make_object
from ..model.types import RENDER_GROUP, Model, ObjectClass
from .birth import BirthProposal


@dataclass(frozen=True, eq=False)
class Proposal:
    move: str  # "parameters", "face", "noise", "render", or a registered jump (sppl.model.jumps)
    label: str  # class name, or sensor kind for noise moves: acceptance is counted per label
    objects: tuple[SceneObject, ...]
    noise: Mapping[str, Mapping[str, float]]
    changed: tuple[SceneObject, ...]  # objects that are new in this proposal
    log_q_ratio: float = 0.0
    # The part of the ratio that depends on the proposed state's renders, if any.
    ratio_fn: Callable[[Trace], float] | None = None
    # A part of log q(reverse) that is dear to compute (a refit's reverse fit), if any, and
    # an upper bound of it: the sampler computes it only when the bound cannot decide
    # (``Sampler.decide``); the acceptance ratio includes it.
    deferred: Callable[[], float] | None = None
    deferred_bound: float = math.inf
    # A multiple-try jump's other candidates and reference points (``sppl.infer.tries``), which its
    # reverse reuses.
    tries: Any = None


def jump_probabilities(model: Model, observed: bool = True) -> dict[str, float]:
    """Probability of each model-jump type, given that a jump is made.

    It does not depend on the state: a death or change chosen in an empty scene does nothing,
    as in the thesis's Algorithm 7. A change needs a second class to change to. Without
    observations (``observed`` false: the prior's scorer) nothing is ever unexplained, so
    fitted births and deaths could never act, and the other jumps take their share.
    """
    names = jump_names()
    w = dict(model.inference.jump_weights)
    unknown = sorted(j for j, weight in w.items() if weight > 0 and j not in names)
    if unknown:
        # A model compiled where a jump was registered, run where it is not (another
        # process): its weight must not silently count for nothing.
        raise SpplError(f"the model weighs the jump{'s' if len(unknown) > 1 else ''} "
                        f"{', '.join(unknown)}, not registered in this process; import the "
                        "module that registers it before running the model here")
    if len(model.classes) < 2:
        w["change"] = 0.0
    from_observations = [j for j in names if jump(j).needs_observations]
    if not observed and any(w.get(j, 0.0) for j in names if j not in from_observations):
        w.update(dict.fromkeys(from_observations, 0.0))
    total = sum(w.get(j, 0.0) for j in names)
    return {j: w.get(j, 0.0) / total for j in names}


def _log(p: float) -> float:
    return math.log(p) if p > 0 else -math.inf


# -- proposal densities of the model jumps ---------------------------------------------------


def log_q_birth(
    model: Model, cls: ObjectClass, values: Mapping[str, Any], birth: BirthProposal, state: Trace
) -> float:
    """Density of proposing, from ``state``, a birth of exactly this object: the jump type,
    the class (uniform over classes), and its parameters (``sppl.infer.birth``: the class's prior,
    or for its position a mixture with a density near what ``state`` leaves unexplained)."""
    return (
        _log(jump_probabilities(model)["birth"])
        - math.log(len(model.classes))
        + birth.log_density(cls, values, state)
    )


def log_q_death(model: Model, n_objects: int) -> float:
    """Probability of proposing the death of one given object among ``n_objects``."""
    return _log(jump_probabilities(model)["death"]) - math.log(n_objects)


def carried_parameters(old: ObjectClass, new: ObjectClass) -> dict[str, str]:
    """Parameters a change of class keeps, as {parameter of new: parameter of old}: the pairs
    the model declares (``change a.p <-> b.q``), and the others with the same name and the
    same domain in both classes. The pairing is the same in both directions, reversed, so a
    change and its reverse carry the same values and drop the same ones (no Jacobian: the
    carried values are copied as they are)."""
    declared = dict(new.correspondences.get(old.name, {}))
    taken = set(declared.values())
    carried = {}
    for p in new.parameters:
        if p.name in declared:
            carried[p.name] = declared[p.name]
        elif p.name not in taken and (q := old.parameter(p.name)) is not None:
            if q.domain == p.domain and p.name not in old.correspondences.get(new.name, {}):
                carried[p.name] = p.name
    return carried


def carried_scales(old: ObjectClass, new: ObjectClass) -> dict[str, float]:
    """For each parameter of ``new`` that a change from ``old`` carries, the factor its value
    is the old one's times: 1 unless the model pairs the two with a factor
    (``change a.p <-> k * b.q``). The reverse change has the reciprocal factors."""
    scales = new.correspondence_scales.get(old.name, {})
    return {p: float(scales.get(p, 1.0)) for p in carried_parameters(old, new)}


def log_jacobian_change(old: ObjectClass, new: ObjectClass) -> float:
    """log |det| of the map a change makes of the carried values: scaling a value by k
    stretches the parameter space by k along it, which the acceptance ratio must count."""
    return sum(math.log(k) for k in carried_scales(old, new).values())


def _scaled(value, factor: float):
    """A carried value times its factor; a factor of 1 copies it exactly (a colour too)."""
    return value if factor == 1.0 else value * factor


def log_q_change(
    model: Model, n_objects: int, old: ObjectClass, new: ObjectClass, new_values: Mapping[str, Any]
) -> float:
    """Density of changing a given object from ``old`` to ``new`` with these new values: the
    object (uniform), the new class (uniform over the others), and the parameters that are not
    carried over drawn from ``new``'s prior, given the carried ones where it depends on them."""
    carried = set(carried_parameters(old, new))
    return (
        _log(jump_probabilities(model)["change"])
        - math.log(n_objects)
        - math.log(len(model.classes) - 1)
        + new.log_prior(new_values, only=[n for n in new.parameter_names if n not in carried])
    )


# -- proposals ---------------------------------------------------------------------------------


def propose_birth(
    model: Model, trace: Trace, rng: np.random.Generator, birth: BirthProposal
) -> Proposal:
    cls = model.classes[int(rng.integers(len(model.classes)))]
    values = birth.sample(cls, trace, rng)
    obj = make_object(model, cls, values)
    # The new object goes to a uniformly chosen place in the tuple, not to its end: then a
    # death at place k and a birth inserting at k are exact reverses of each other on the
    # stored tuples too, and the order carries no information (appending would make it the
    # order of birth, which the in-order parameter sweep would then see; docs/inference.md).
    k = int(rng.integers(len(trace.objects) + 1))
    objects = trace.objects[:k] + (obj,) + trace.objects[k:]
    ratio = log_q_death(model, len(objects)) - log_q_birth(model, cls, values, birth, trace)
    return Proposal("birth", cls.name, objects, trace.noise, (obj,), ratio)


def propose_death(
    model: Model, trace: Trace, rng: np.random.Generator, birth: BirthProposal
) -> Proposal | None:
    n = len(trace.objects)
    if n == 0:
        return None
    return death_of(model, trace, int(rng.integers(n)), birth)


def death_of(model: Model, trace: Trace, k: int, birth: BirthProposal) -> Proposal:
    """The death of object ``k`` of ``trace``."""
    n = len(trace.objects)
    gone = trace.objects[k]
    objects = trace.objects[:k] + trace.objects[k + 1 :]
    # The reverse birth starts from the state after the death, which is only known (rendered)
    # once the proposal is evaluated: that part of the ratio is computed then.
    return Proposal(
        "death", gone.cls.name, objects, trace.noise, (), -log_q_death(model, n),
        lambda after: log_q_birth(model, gone.cls, gone.values, birth, after),
    )


def propose_change(model: Model, trace: Trace, rng: np.random.Generator) -> Proposal | None:
    n = len(trace.objects)
    if n == 0 or len(model.classes) < 2:
        return None
    k = int(rng.integers(n))
    old = trace.objects[k]
    others = [c for c in model.classes if c is not old.cls]
    new_cls = others[int(rng.integers(len(others)))]
    carried = carried_parameters(old.cls, new_cls)
    scales = carried_scales(old.cls, new_cls)
    # The dropped parameters are drawn from the new class's prior, in its dependency order,
    # given the carried ones.
    values = new_cls.sample_prior(
        rng, given={n: _scaled(old.values[q], scales[n]) for n, q in carried.items()})
    obj = make_object(model, new_cls, values)
    objects = trace.objects[:k] + (obj,) + trace.objects[k + 1 :]
    ratio = (log_q_change(model, n, new_cls, old.cls, old.values)
             - log_q_change(model, n, old.cls, new_cls, values)
             + log_jacobian_change(old.cls, new_cls))
    return Proposal("change", old.cls.name, objects, trace.noise, (obj,), ratio)


def propose_parameters(
    model: Model, trace: Trace, k: int, names: tuple[str, ...], rng: np.random.Generator,
    factor: float = 1.0,
) -> Proposal:
    """A symmetric random-walk step of some parameters of object ``k`` (Algorithm 3), each of
    its declared step times ``factor`` (the warm-up's adapted scale, ``sppl.infer.warmup``);
    a block of several categorical parameters moves to one of its *other* combinations,
    uniformly (``joint_step``)."""
    old = trace.objects[k]
    values = dict(old.values)
    params = [old.cls.parameter(name) for name in names]
    if len(params) > 1 and all(isinstance(p.domain, Finite) for p in params):
        values.update(joint_step(params, values, rng))
    else:
        for p in params:
            values[p.name] = p.domain.step(values[p.name], p.proposal_scale * factor, rng)
    obj = make_object(model, old.cls, values)
    objects = trace.objects[:k] + (obj,) + trace.objects[k + 1 :]
    return Proposal("parameters", old.cls.name, objects, trace.noise, (obj,))


def propose_noise(
    model: Model, trace: Trace, kind: str, name: str, rng: np.random.Generator,
    factor: float = 1.0,
) -> Proposal:
    """A symmetric random-walk step of one noise parameter (thesis section 4.2), or of one of
    the render block's lighting parameters (``kind`` RENDER_GROUP): the same step, but a
    "render" move, which changes the renders and so is scored by rendering again."""
    p = next(q for k, group in model.noise_groups if k == kind for q in group if q.name == name)
    noise = {k: dict(v) for k, v in trace.noise.items()}
    noise[kind][name] = p.domain.step(noise[kind][name], p.proposal_scale * factor, rng)
    move = "render" if kind == RENDER_GROUP else "noise"
    return Proposal(move, kind, trace.objects, noise, ())


def reverse(
    model: Model,
    before: Trace,
    proposal: Proposal,
    after: Trace,
    birth: BirthProposal,
    without: Callable[[tuple[SceneObject, ...]], Trace] | None = None,
) -> Proposal:
    """The proposal that undoes ``proposal``, made from ``after``, the state it led to.

    Built independently of the forward move from the same proposal densities: a birth's
    reverse is the death of the born object, a death's the birth of the same object at its
    old place, a change's the change back (carrying the same parameters and proposing exactly
    the dropped ones), a replace's the replacement of the new object by the old one through
    the same scene without either (which ``without`` renders, as in ``propose_replace``), a
    parameter or noise move's the step back, a face move's the same reach stepped back. The log acceptance ratio of the reverse is minus
    that of the move, and applying both gives back ``before``: the debug check
    ``sppl.verify.check_reverse`` does exactly that. A move type this does not know raises
    ``ValueError``, which the check reports as a failure.
    """
    if proposal.move == "replace":
        if without is None:
            raise ValueError("the reverse of a replace needs `without` to render the scene x-")
        k = _place(after.objects, proposal.changed[0])
        new, old = after.objects[k], before.objects[k]
        rest = after.objects[:k] + after.objects[k + 1 :]
        state = without(rest)
        objects = rest[:k] + (old,) + rest[k:]
        # The object (1/K) and the class (1/|C|) are chosen alike both ways and cancel.
        ratio = birth.log_density(new.cls, new.values, state) - birth.log_density(
            old.cls, old.values, state
        )
        return Proposal("replace", new.cls.name, objects, after.noise, (old,), ratio)
    if proposal.move == "birth":
        return death_of(model, after, _place(after.objects, proposal.changed[0]), birth)
    if proposal.move == "death":
        k = next(
            (i for i, o in enumerate(after.objects) if o is not before.objects[i]),
            len(after.objects),
        )
        gone = before.objects[k]
        objects = after.objects[:k] + (gone,) + after.objects[k:]
        ratio = log_q_death(model, len(objects)) - log_q_birth(
            model, gone.cls, gone.values, birth, after
        )
        return Proposal("birth", gone.cls.name, objects, after.noise, (gone,), ratio)
    if proposal.move in ("change", "parameters"):
        k = _place(after.objects, proposal.changed[0])
        old, new = before.objects[k], after.objects[k]
        objects = after.objects[:k] + (old,) + after.objects[k + 1 :]
        ratio = 0.0  # parameter steps are symmetric
        if proposal.move == "change":
            n = len(objects)
            ratio = (log_q_change(model, n, old.cls, new.cls, new.values)
                     - log_q_change(model, n, new.cls, old.cls, old.values)
                     + log_jacobian_change(new.cls, old.cls))
        return Proposal(proposal.move, new.cls.name, objects, after.noise, (old,), ratio)
    if proposal.move in ("noise", "render"):
        return Proposal(proposal.move, proposal.label, after.objects, before.noise, ())
    if proposal.move == "face":  # the same reach, the step back (sppl.infer.faces)
        return proposal.tries.undo(model, after, before)
    raise ValueError(f"no reverse for a {proposal.move!r} proposal")


def _place(objects, obj) -> int:
    return next(i for i, o in enumerate(objects) if o is obj)


def propose_replace(
    model: Model,
    trace: Trace,
    rng: np.random.Generator,
    birth: BirthProposal,
    without: Callable[[tuple[SceneObject, ...]], Trace],
) -> Proposal | None:
    """Replace one object by a fresh one of any class, placed like a birth into the scene
    without it.

    Object k (uniform) and a class (uniform over all, its own included) are chosen; the new
    object is drawn from the birth proposal of the state x- without object k, which
    ``without`` renders. The reverse chooses the new object and the old class, and goes
    through the same x-, so

        log q(reverse) - log q(forward) = log q_birth(old | x-) - log q_birth(new | x-).

    Where a sphere explains a cube's pixels, or an object sits in the wrong place, this jumps
    straight to a data-driven fresh guess instead of a death and a birth that each alone would
    be rejected.
    """
    n = len(trace.objects)
    if n == 0:
        return None
    k = int(rng.integers(n))
    old = trace.objects[k]
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    state = without(rest)
    cls = model.classes[int(rng.integers(len(model.classes)))]
    values = birth.sample(cls, state, rng)
    obj = make_object(model, cls, values)
    objects = rest[:k] + (obj,) + rest[k:]
    ratio = birth.log_density(old.cls, old.values, state) - birth.log_density(cls, values, state)
    return Proposal("replace", old.cls.name, objects, trace.noise, (obj,), ratio)


def parameter_blocks(cls: ObjectClass) -> tuple[tuple[str, ...], ...]:
    """How an object's parameters are moved: the continuous ones jointly (the thesis's
    Algorithm 3 moves them together), each categorical one on its own, since a colour
    redrawn together with a position is almost always rejected once the position fits; and
    where a class has several categorical parameters, all of them together as well. A large
    metal yellow cylinder read as a rubber brown one is worse as a metal brown one and as a
    rubber yellow one (its sheen and its colour meet in every pixel), so no move of one value
    at a time reaches it; the joint move does, 4,298 nats up (scene 14 of blocks.scn's prior
    scenes, benchmarks/README.md)."""
    cont = tuple(p.name for p in cls.parameters if p.continuous)
    cat = tuple((p.name,) for p in cls.parameters if not p.continuous)
    finite = tuple(p.name for p in cls.parameters if isinstance(p.domain, Finite))
    joint = (finite,) if len(finite) > 1 else ()
    return ((cont,) if cont else ()) + cat + joint


def joint_step(params, values, rng: np.random.Generator) -> dict[str, str]:
    """A uniform draw among the combinations of the categorical ``params`` other than their
    ``values``: symmetric (1 / (N - 1) both ways, N combinations), and never a no-op. Drawn
    by index, so no list of the N combinations is made."""
    sizes = [len(p.domain.values) for p in params]
    here = 0
    for p, n in zip(params, sizes):
        here = here * n + p.domain.values.index(values[p.name])
    total = math.prod(sizes)
    if total < 2:
        return {}
    index = int(rng.integers(total - 1))
    index += index >= here
    drawn = {}
    for p, n in zip(reversed(params), reversed(sizes)):
        index, r = divmod(index, n)
        drawn[p.name] = p.domain.values[r]
    return drawn
