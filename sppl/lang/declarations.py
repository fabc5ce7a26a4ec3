"""A class's or sensor's own names: its parameters and derived quantities.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``, used by
classes, sensors and the render block's lighting: within one of them the names may come in any
order, so they are all declared first, then compiled in an order where each comes after what it
uses (``order.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from ..model.domains import Finite
from . import ast
from .context import CompileContext, Owner
from .expressions import COLOUR_PARAMETER, DERIVED, Scope, Symbol, names_in
from .order import cycle_path, parameters_read, strongly_connected, topological
from .priors import parameter_kind


def declare_locals(
    context: CompileContext, body, pending: Owner, owner: str
) -> tuple[dict[str, Symbol], dict[str, ast.Choice | ast.Let]]:
    """The symbols visible inside a class or sensor (the globals, its parameters and
    derived quantities), and the declarations of its own names."""
    local = dict(context.symbols)
    own: dict[str, ast.Choice | ast.Let] = {}
    for item in body:
        # `count` is a class's number of objects, not a parameter; a choice with no
        # domain is reported where it is compiled.
        if isinstance(item, ast.Choice):
            if item.domain is None or item.name.text == "count":
                continue
            kind = parameter_kind(item.domain)
            what = "parameter"
        elif isinstance(item, ast.Let):
            kind, what = DERIVED, "derived quantity"
        else:
            continue
        name = item.name
        if what == "parameter":
            pending.declared.add(name.text)
        if name.text in own:
            context.error(
                f"{owner} already has a parameter or derived quantity `{name.text}` "
                f"(line {own[name.text].span.line})",
                name.span,
            )
            continue
        if not context.check_new_global(name, f"; a {what} needs a name of its own"):
            continue
        own[name.text] = item
        value = context.palette if kind == COLOUR_PARAMETER else None
        local[name.text] = Symbol(name.text, kind, item.span, value, ordered=False)
    return local, own


def compile_locals(
    context: CompileContext,
    own: dict[str, ast.Choice | ast.Let],
    local: dict[str, Symbol],
    pending: Owner,
    parameters_allowed: bool,
) -> None:
    """Compile a class's (or sensor's) parameters and derived quantities in an order
    where each comes after what it uses, reporting any that depend on themselves."""
    deps = {
        name: list(
            dict.fromkeys(
                n.id
                for n in names_in(item.prior if isinstance(item, ast.Choice) else item.value)
                if n.id in own and n.id != name
            )
        )
        if parameters_allowed
        else []
        for name, item in own.items()
    }
    broken = _cycles(context, own, deps)
    order = topological(list(own), deps, broken)
    for name in order:
        item = own[name]
        if isinstance(item, ast.Let):
            scope = Scope(local, parameters_allowed=True, where="a derived quantity")
            value = context.expr.number(item.value, scope)
            local[name] = replace(local[name], value=value)
            continue
        if item.name.text == "count":
            continue
        reads = parameters_read(name, deps, own)
        where = "a prior" if parameters_allowed else "a noise prior"
        scope = Scope(local, parameters_allowed=parameters_allowed, where=where)
        parameter = context.priors.parameter(item, scope, reads)
        if parameter is None:
            continue
        pending.parameters.append(parameter)
        if isinstance(parameter.domain, Finite):
            local[name] = replace(local[name], labels=parameter.domain.values)


def _cycles(
    context: CompileContext, own: Mapping[str, Any], deps: Mapping[str, list[str]]
) -> set[str]:
    """Report each cycle of dependencies once; return the names on cycles."""
    index = {name: i for i, name in enumerate(own)}
    on_cycle: set[str] = set()
    for component in strongly_connected(list(own), deps):
        if len(component) < 2:
            continue
        on_cycle |= component
        first = min(component, key=index.__getitem__)
        path = cycle_path(first, deps, component)
        context.error(
            f"`{first}` depends on itself: {' -> '.join(path)}",
            own[first].name.span,
            "parameters and derived quantities must not depend on each other in a circle",
        )
    return on_cycle
