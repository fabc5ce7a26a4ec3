"""``change`` statements: which parameters a change of class carries between two classes.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. They are
resolved after every statement is compiled, since a change may name classes defined (or
imported) after it; each class keeps its pairings, which become its ``correspondences``.
"""

from __future__ import annotations

import math

from ..model.domains import Positive, Real
from . import ast
from .context import CompileContext, PendingClass
from .expressions import did_you_mean, known


def resolve_changes(context: CompileContext, changes: list[ast.Change]) -> None:
    """Pair the parameters each `change` statement names, checking they can be paired."""
    for node in changes:
        first = _change_side(context, node.first_class, node.first)
        second = _change_side(context, node.second_class, node.second)
        if first is None or second is None:
            continue
        (a, p), (b, q) = first, second
        if a is b:
            context.error(
                "a change of class is between two different classes", node.second_class.span
            )
            continue
        pa, pb = a.parameter(p.text), b.parameter(q.text)
        if pa is None or pb is None:
            continue  # it failed to compile, which was reported there
        factor = 1.0 if node.factor is None else node.factor.value
        if factor != 1.0 and not (factor > 0 and math.isfinite(factor)):
            context.error(f"a change's factor must be positive, got {factor:g}",
                       node.factor.span)
            continue
        if factor != 1.0 and not (pa.domain == pb.domain and _scale_free(pa.domain)):
            context.error(
                f"`{a.name}.{p.text}` ({pa.domain.describe()}) and `{b.name}.{q.text}` "
                f"({pb.domain.describe()}) cannot be paired with a factor",
                node.factor.span,
                "a scaled value stays in its domain only for two real or two positive "
                "parameters",
            )
            continue
        if pa.domain != pb.domain:
            context.error(
                f"`{a.name}.{p.text}` ({pa.domain.describe()}) and `{b.name}.{q.text}` "
                f"({pb.domain.describe()}) have different domains",
                node.second.span,
                "a change carries a value as it is, so both need the same domain",
            )
            continue
        clash = False
        for owner, other, mine in ((a, b, p), (b, a, q)):
            where = owner.paired_at.get((id(other), mine.text))
            if where is not None:
                context.error(
                    f"`{owner.name}.{mine.text}` is already paired with a parameter of "
                    f"`{other.name}` on line {where.line}",
                    mine.span,
                )
                clash = True
        if clash:
            continue
        for owner, other, mine, theirs, k in ((a, b, p, q, factor), (b, a, q, p, 1 / factor)):
            owner.paired_at[id(other), mine.text] = node.span
            owner.pairs.setdefault(id(other), (other, {}))[1][mine.text] = theirs.text
            if factor != 1.0:
                owner.scales.setdefault(id(other), {})[mine.text] = k


def _change_side(
    context: CompileContext, cls: ast.Ident, name: ast.Ident
) -> tuple[PendingClass, ast.Ident] | None:
    pending = context.classes.get(cls.text)
    if pending is None:
        context.error(
            f"unknown class `{cls.text}`",
            cls.span,
            did_you_mean(cls.text, context.classes) or known("classes", context.classes),
        )
        return None
    if name.text not in pending.declared:
        context.error(
            f"class `{cls.text}` has no parameter `{name.text}`",
            name.span,
            did_you_mean(name.text, pending.declared)
            or known("parameters", sorted(pending.declared)),
        )
        return None
    return pending, name


def _scale_free(domain) -> bool:
    """Domains that a positive factor maps onto themselves."""
    return isinstance(domain, (Real, Positive))
