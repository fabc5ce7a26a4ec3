"""Every move and its reverse: applying a proposal and then its reverse gives back the same
trace, and the two log acceptance ratios are negatives of each other."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..infer import faces, jumps, moves
from ..infer.chain import Sampler
from ..model.simulate import sample_noise, sample_objects
from ..model.trace import Trace
from ..model.types import Model
from ..scoring.scorer import PriorScorer
from .report import ALPHA, Report, Row
from .simulated import Simulator, for_checks, verify_cameras
from .statistics import seed_sequence

# Exact checks: how far apart log alpha(forward) and -log alpha(reverse) may be.
RATIO_TOLERANCE = 1e-6


def same_trace(a: Trace, b: Trace) -> bool:
    """The same objects in the same places with the same values, the same noise, the same
    score."""
    if len(a.objects) != len(b.objects):
        return False
    for x, y in zip(a.objects, b.objects):
        if x.cls is not y.cls or dict(x.values) != dict(y.values):
            return False
    if {k: dict(v) for k, v in a.noise.items()} != {k: dict(v) for k, v in b.noise.items()}:
        return False
    return math.isclose(a.score, b.score, rel_tol=1e-9, abs_tol=1e-9)


def check_reverse(sampler: Sampler, trace: Trace, proposal) -> tuple[float, float, bool] | None:
    """Apply a proposal and then its reverse. Returns (log alpha forward, log alpha of the
    reverse, whether the reverse gave back ``trace``), or None when the proposal has zero prior
    (it would be rejected before rendering, and has no reverse). Raises ``ValueError`` for a
    move type without a reverse, or a jump whose reverse is not the jump it declares
    (``sppl.infer.jumps.reverse``)."""
    if proposal is None:
        return None
    new = sampler.evaluate(trace, proposal)
    if new is None:
        return None
    forward = sampler.log_alpha(trace, proposal, new)
    rev = jumps.reverse(sampler, trace, proposal, new)
    back = sampler.evaluate(new, rev)
    if back is None:
        return forward, -math.inf, False
    return forward, sampler.log_alpha(new, rev, back), same_trace(trace, back)


def _ratio_gap(forward: float, backward: float) -> float:
    if math.isfinite(forward) and math.isfinite(backward):
        return abs(forward + backward)
    return 0.0 if forward == -backward else math.inf


# Per state, the move checks draw jumps from the sampler's own ``propose_jump`` until every jump
# type it can make has been seen, or this many have been drawn.
JUMP_TRIES = 60


def move_checks(
    model: Model,
    *,
    states: int = 30,
    seed=0,
    size: int = 8,
    renderer=None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    observe: bool = True,
) -> Report:
    """Every move type from ``states`` prior draws, each applied and then reversed.

    The model jumps are the sampler's own: ``Sampler.propose_jump`` is called until each jump
    type with a positive probability (``Sampler.jump``) has been proposed once from the state,
    so a new kind of jump is checked without naming it here (and fails where it is not
    registered with a reverse, ``sppl.model.jumps``). Then a parameter move of each block of one
    object (and, where the model asks for face moves, a face move of each of its face
    parameters), and a move of each noise parameter. With sensors (and ``observe``), the states are
    scored against observations of another prior scene, so that data-driven births (which
    look at what a state leaves unexplained) are among those checked; without, against no
    observations. The change-of-class pairings are checked too (``change_declarations``).
    """
    model = for_checks(model)
    seq = seed_sequence(seed)
    rng = np.random.default_rng(seq)
    if model.sensors and observe:
        if renderer is None:
            from ..render import Renderer

            renderer = Renderer(model.render)
        sim = Simulator(model, verify_cameras(model, size), renderer)
        objs, noise = sample_objects(model, rng), sample_noise(model, rng)
        sampler = sim.sampler(sim.observe(sim.render(objs, noise), noise, rng), rng, sampler_factory)
    else:
        sampler = sampler_factory(model, PriorScorer(), rng)
    jumps = {j for j, p in sampler.jump.items() if p > 0}
    results: dict[str, list[tuple[float, float, bool]]] = {}
    no_reverse: dict[str, str] = {}
    for _ in range(states):
        trace = sampler.initial_trace(sample_objects(model, rng))
        proposals, seen = [], set()
        for _ in range(JUMP_TRIES):
            p = sampler.propose_jump(trace)
            if p is not None and p.move not in seen:
                seen.add(p.move)
                proposals.append(p)
            if seen >= jumps:
                break
        if trace.objects:
            k = int(rng.integers(len(trace.objects)))
            for block in moves.parameter_blocks(trace.objects[k].cls):
                proposals.append(moves.propose_parameters(model, trace, k, block, rng))
            if model.inference.face_steps:
                for name in faces.face_parameters(trace.objects[k].cls):
                    face = faces.propose_face(model, trace, k, name, rng)
                    if face is not None:  # a parameter with no reach has no face move
                        proposals.append(face)
        for kind, parameters in model.noise_groups:
            for p in parameters:
                proposals.append(moves.propose_noise(model, trace, kind, p.name, rng))
        for p in proposals:
            if p.move in no_reverse:
                continue
            try:
                result = check_reverse(sampler, trace, p)
            except ValueError as error:
                no_reverse[p.move] = str(error)
                continue
            results.setdefault(p.move, [])
            if result is not None:
                results[p.move].append(result)
    rows = []
    for move in sorted(set(results) | set(no_reverse)):
        name, expected = f"{move}: reverse undoes it", "same trace, log a + log a_rev = 0"
        if move in no_reverse:
            rows.append(Row("moves", name, expected, f"no reverse: {no_reverse[move]}", None, False))
            continue
        res = results[move]
        if not res:
            continue  # proposed, but never to a state of positive prior
        same = sum(r[2] for r in res)
        gap = max(_ratio_gap(f, b) for f, b, _ in res)
        rows.append(Row(
            "moves", name, expected, f"{same}/{len(res)} same, max |sum| {gap:.1e}", None,
            same == len(res) and gap < RATIO_TOLERANCE,
        ))
    notes = [
        f"moves: {move} jumps were never proposed to a state of positive prior in {states} "
        "states; prior recovery still checks them."
        for move in sorted(jumps) if not results.get(move) and move not in no_reverse
    ]
    return Report(change_declarations(model) + rows, ALPHA, notes)


def change_declarations(model: Model) -> list[Row]:
    """Exact rows, one per pair of classes: a change of class carries values as they are, so
    its reverse can carry them back only if the pairing is the same both ways, reversed, and
    each carried pair has the same domain (a value of a wider domain may not fit the narrower
    one; a whole number carried into a real parameter would land on a set of measure zero, and
    the ratio would be wrong). The language rejects such a declaration when it compiles a
    model; a class built in Python (or a future pairing rule) is checked here."""
    rows = []
    for i, a in enumerate(model.classes):
        for b in model.classes[i + 1 :]:
            forward = moves.carried_parameters(a, b)  # {parameter of b: parameter of a}
            back = moves.carried_parameters(b, a)  # {parameter of a: parameter of b}
            problems = []
            if back != {q: p for p, q in forward.items()}:
                problems.append(f"{a.name} -> {b.name} carries {_pairs(forward, a, b)} but "
                                f"{b.name} -> {a.name} carries {_pairs(back, b, a)} back")
            for p, q in forward.items():
                da, db = a.parameter(q).domain, b.parameter(p).domain
                if da != db:
                    problems.append(f"{a.name}.{q} ({da.describe()}) -> {b.name}.{p} ({db.describe()})")
            # A scaled pairing carries back only with the reciprocal factor.
            there, back_scales = moves.carried_scales(a, b), moves.carried_scales(b, a)
            for p, q in forward.items():
                if q in back_scales and not math.isclose(there[p] * back_scales[q], 1.0):
                    problems.append(f"{a.name}.{q} -> {b.name}.{p} is scaled by {there[p]:g} "
                                    f"but back by {back_scales[q]:g}")
            observed = "; ".join(problems) or f"carries {_pairs(forward, a, b) or 'nothing'}"
            rows.append(Row("moves", f"change {a.name} <-> {b.name}: carries back",
                            "the same pairs both ways, equal domains", observed, None,
                            not problems))
    return rows


def _pairs(carried: dict[str, str], old, new) -> str:
    return ", ".join(q if p == q else f"{old.name}.{q} -> {new.name}.{p}"
                     for p, q in carried.items())
