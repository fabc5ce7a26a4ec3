"""``step`` settings: the proposal scale of a numeric parameter, for the sampler's moves.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. Steps are
given in the inference block but applied after every statement is compiled, once the
parameters of every class and sensor (and the render block's lighting) are known.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from ..model.domains import Finite
from ..model.types import Parameter
from . import ast
from .context import CompileContext, Owner
from .expressions import did_you_mean


def apply_steps(context: CompileContext, steps: list[ast.Step], pending: list[Owner]) -> None:
    """Give each parameter of the classes and sensors in ``pending`` its proposal scale:
    `step owner.name` wins over `step name`."""
    owners: dict[str, list[Owner]] = {}
    for owner in pending:
        owners.setdefault(owner.name, []).append(owner)
    scales: dict[tuple[str | None, str], float] = {}  # (owner or None, parameter): step
    for step in steps:
        owner = None if step.owner is None else step.owner.text
        if not _step_target_exists(context, step, owners):
            continue
        if not context.first(("step", owner or "", step.name.text), step):
            continue
        value = context.expr.constant(step.value, context.global_scope())
        if value is not None and value <= 0:
            context.error(f"a step must be positive, got {value:g}", step.value.span)
        elif value is not None:
            scales[owner, step.name.text] = value
    for owner in pending:
        owner.parameters = [
            replace(p, proposal_scale=_scale(scales, owner.name, p.name))
            if _steppable(p) and _scale(scales, owner.name, p.name) is not None
            else p
            for p in owner.parameters
        ]


def _step_target_exists(
    context: CompileContext, step: ast.Step, owners: dict[str, list[Owner]]
) -> bool:
    name = step.name.text
    if step.owner is None:
        candidates = [o for group in owners.values() for o in group]
    elif step.owner.text in owners:
        candidates = owners[step.owner.text]
    else:
        context.error(
            f"no class or sensor is called `{step.owner.text}`",
            step.owner.span,
            did_you_mean(step.owner.text, owners),
        )
        return False
    declared = {n for o in candidates for n in o.declared}
    if name not in declared:
        where = "" if step.owner is None else f" in `{step.owner.text}`"
        context.error(
            f"no parameter `{name}`{where} to step",
            step.name.span,
            did_you_mean(name, declared),
        )
        return False
    matches = [p for o in candidates for p in o.parameters if p.name == name]
    if not matches:
        return False  # it failed to compile, which was reported there
    if not any(_steppable(p) for p in matches):
        context.error(
            f"`{name}` is categorical; steps are for numeric parameters", step.name.span
        )
        return False
    return True


def _steppable(p: Parameter) -> bool:
    return not isinstance(p.domain, Finite)


def _scale(scales: Mapping[tuple[str | None, str], float], owner: str, name: str) -> float | None:
    if (owner, name) in scales:
        return scales[owner, name]
    return scales.get((None, name))
