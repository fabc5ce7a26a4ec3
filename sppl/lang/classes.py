"""Object classes: ``class NAME { ... }``, and the classes other files bring by import.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext`` and its
``Shapes``: a class's parameters and derived quantities are compiled by ``declarations.py``, its
pose, footprint and geometry by ``shapes.py``, its count here. Nothing here knows any concrete
class: an object class is whatever its declarations say.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from ..errors import ModelError, Span
from ..model.domains import Real
from ..model.geometry import Part
from ..model.types import (
    MAX_SCENE_OBJECTS,
    SCENE_TAIL,
    ObjectClass,
    Values,
    probability_of_more_objects,
)
from . import ast
from .context import CompileContext, PendingClass
from .declarations import compile_locals, declare_locals
from .expressions import Scope, Symbol, did_you_mean, failure_reason, known
from .shapes import Matrix, Shapes, modifier_of, posed

_CLASS_SETTINGS = ("count", "max_count")


class Classes:
    """The classes of one file, its own and those it imports."""

    def __init__(self, context: CompileContext, shapes: Shapes) -> None:
        self.context = context
        self.shapes = shapes
        self.error = context.error
        self.imported_at: dict[int, Span] = {}  # id(class): the import that brought it

    def add(self, pending: PendingClass, name: ast.Ident, imported_at: Span | None = None) -> bool:
        """Add a class under ``name``, defined here or brought by the import at ``imported_at``;
        whether it is new (a name clash is reported)."""
        existing = self.context.classes.get(name.text)
        if existing is pending:
            return False  # the same class, imported twice
        if existing is not None:
            if existing.program is not self.context.program:
                where = f"imported on line {self._import_line(existing)}"
            else:
                where = f"defined on line {existing.span.line}"
            self.error(f"class `{name.text}` is already {where}", name.span)
            return False
        self.context.classes[name.text] = pending
        if imported_at is not None:
            self.imported_at[id(pending)] = imported_at
        return True

    def _import_line(self, pending: PendingClass) -> int:
        span = self.imported_at.get(id(pending))
        return span.line if span else 0

    def compile(self, node: ast.ClassDef) -> None:
        name = node.name.text
        pending = PendingClass(name, span=node.span, program=self.context.program)
        self.add(pending, node.name)
        local, own = declare_locals(self.context, node.body, pending, f"class `{name}`")
        scope = Scope(local, parameters_allowed=True, where="geometry")
        compile_locals(self.context, own, local, pending, parameters_allowed=True)
        self._counts(node, pending, local)

        poses = [item for item in node.body if isinstance(item, ast.Pose)]
        for extra in poses[1:]:
            self.error(f"`pose` is already given on line {poses[0].span.line}", extra.span)
        pose: Matrix | None = np.eye(4)
        if poses:
            pose = self.shapes.transform(poses[0].modifiers, "pose", scope)
        footprints = [item for item in node.body if isinstance(item, ast.Footprint)]
        for extra in footprints[1:]:
            self.error(
                f"`footprint` is already given on line {footprints[0].span.line}", extra.span
            )
        if footprints and pose is not None:
            pending.footprint = self.shapes.footprint(footprints[0], pose, scope)
        floats = [item for item in node.body if isinstance(item, ast.Floating)]
        for extra in floats[1:]:
            self.error(f"`floating` is already given on line {floats[0].span.line}", extra.span)
        pending.floating = bool(floats)
        for item in node.body:
            if isinstance(item, ast.Geometry):
                part = self.shapes.geometry(item, scope)
                if part is not None and pose is not None:
                    pending.parts.append((item.span, posed(pose, part)))
        pending.position = _ground_position(node, pending)
        if not any(isinstance(item, ast.Geometry) for item in node.body):
            self.error(
                f"class `{name}` has no geometry",
                node.name.span,
                "add a line such as `geometry box(1, 1, 1) colour red`",
            )

    def _counts(self, node: ast.ClassDef, pending: PendingClass, local) -> None:
        count: ast.Choice | ast.Setting | None = None
        for item in node.body:
            if isinstance(item, ast.Choice) and item.name.text == "count":
                if count is not None:
                    self.error(
                        f"`count` is already given on line {count.span.line}", item.name.span
                    )
                    continue
                count = item
                pending.count_span = item.span
                pending.rate = self._count(item, local)
            elif isinstance(item, ast.Choice) and item.domain is None:
                self.context.no_domain(item, "real")
            elif isinstance(item, ast.Setting):
                key = item.key.text
                if key not in _CLASS_SETTINGS:
                    self.error(
                        f"unknown class setting `{key}`",
                        item.key.span,
                        did_you_mean(key, _CLASS_SETTINGS) or known("settings", _CLASS_SETTINGS),
                    )
                    continue
                if key == "count" and count is not None:
                    self.error(
                        f"`count` is already given on line {count.span.line}", item.key.span
                    )
                    continue
                if key == "max_count" and not self.context.first(
                    ("class", pending.name, key), item
                ):
                    continue
                n = whole(self.context, item.value, f"`{key}`")
                if key == "count":
                    count = item
                    pending.count_span = item.span
                    pending.count = n
                    pending.rate = None if n is None else float(n)
                else:
                    pending.max_count = n
        if count is None:
            self.error(
                f"class `{pending.name}` has no count",
                node.name.span,
                "add a line `count ~ poisson(rate)`",
            )
        elif pending.count is not None and pending.max_count is not None:
            self.error(
                "a fixed count needs no `max_count`",
                next(i.span for i in node.body if isinstance(i, ast.Setting)
                     and i.key.text == "max_count"),
            )

    def _count(self, choice: ast.Choice, local: Mapping[str, Symbol]) -> float | None:
        call = choice.prior
        if choice.domain is not None:
            self.error(
                "`count` is the number of objects and takes no domain",
                choice.domain.span,
                "write `count ~ poisson(rate)`",
            )
            return None
        if call.func.text != "poisson":
            self.error(
                "the count of a class needs a poisson prior",
                call.span,
                "write `count ~ poisson(rate)`, or `count = n` for exactly n objects",
            )
            return None
        prior = self.context.priors.prior(call, Scope(local, where="a count"), colours=False)
        return None if prior is None else prior.rate

    def check_scene_size(self, max_objects: int | None) -> None:
        """Refuse a prior that puts real mass on more objects than a run can handle: the
        sampler would grind through such scenes, and `sppl simulate` would try to build one."""
        if max_objects is not None and max_objects <= MAX_SCENE_OBJECTS:
            return
        classes = [c for c in self.context.classes.values()
                   if c.rate is not None or c.count is not None]
        compiled = [ObjectClass(c.name, float(c.count) if c.count is not None else c.rate, (),
                                lambda values: (), count=c.count, max_count=c.max_count)
                    for c in classes]
        p = probability_of_more_objects(compiled, MAX_SCENE_OBJECTS)
        if p <= SCENE_TAIL:
            return
        # Pointed at the count that contributes most (in this file, or its import).
        worst = max(classes, key=lambda c: c.count if c.count is not None else c.rate)
        span = (worst.count_span if worst.program is self.context.program and worst.count_span
                else self.imported_at.get(id(worst), worst.span))
        expected = sum(c.count if c.count is not None else c.rate for c in classes)
        self.error(
            f"the prior puts probability {p:.3g} on scenes of more than {MAX_SCENE_OBJECTS} "
            f"objects (class `{worst.name}` alone expects {worst.count or worst.rate:g}, all "
            f"classes {expected:g}), more than a run can sample",
            span,
            "lower the rate, or bound the count with `max_count = n` in the class or "
            f"`constraint max_objects(n)` with n at most {MAX_SCENE_OBJECTS}",
        )

    def object_class(self, c: PendingClass, restriction: object | None) -> ObjectClass:
        """The class as the model holds it; ``restriction`` is the region's on its position."""
        correspondences = {
            other.name: dict(pairs)
            for other, pairs in c.pairs.values()
            if self.context.classes.get(other.name) is other
        }
        scales = {
            other.name: dict(c.scales[key])
            for key, (other, _) in c.pairs.items()
            if key in c.scales and self.context.classes.get(other.name) is other
        }
        rate = float(c.count) if c.count is not None else c.rate
        return ObjectClass(
            c.name,
            rate,
            tuple(c.parameters),
            _build(c),
            footprint_fn=c.footprint,
            position=c.position,
            count=c.count,
            max_count=c.max_count,
            floating=c.floating,
            correspondences=correspondences,
            correspondence_scales=scales,
            restriction=restriction,
        )


def whole(context: CompileContext, expr: ast.Value, what: str) -> int | None:
    """A number of objects given as a constant (a count, a bound), or None after reporting."""
    value = context.expr.constant(expr, context.global_scope())
    if value is None:
        return None
    if value < 0 or value != int(value):
        context.error(f"{what} is a whole number of objects, got {value:g}", expr.span)
        return None
    return int(value)


def _ground_position(node: ast.ClassDef, pending: PendingClass) -> tuple[str, str] | None:
    """The two parameters that place the object on the ground, when its pose (or, without
    one, its first geometry line) says ``at (x, y ...)`` with two independent real-valued
    parameters of the class that no other parameter depends on: data-driven birth proposals
    draw these near unexplained observations instead of from their prior."""
    reals = {p.name for p in pending.parameters if isinstance(p.domain, Real) and not p.depends_on}
    source = next((i for i in node.body if isinstance(i, ast.Pose)), None) or next(
        (i for i in node.body if isinstance(i, ast.Geometry)), None
    )
    if source is None:
        return None
    at = modifier_of(source.modifiers, "at")
    if at is None or not isinstance(at.value, ast.Tuple):
        return None
    a, b = at.value.items[:2]
    if not (isinstance(a, ast.Name) and isinstance(b, ast.Name) and a.id != b.id):
        return None
    if not {a.id, b.id} <= reals:
        return None
    # Births redraw the position after the other parameters: none may depend on it.
    reads = {p.name: set(p.depends_on) for p in pending.parameters}
    for p in pending.parameters:
        seen, stack = set(), list(p.depends_on)
        while stack:
            d = stack.pop()
            if d in (a.id, b.id):
                return None
            if d not in seen:
                seen.add(d)
                stack.extend(reads.get(d, ()))
    return (a.id, b.id)


def _build(pending: PendingClass) -> Callable[[Values], tuple[Part, ...]]:
    parts = tuple(pending.parts)
    name = pending.name
    program = pending.program

    def build(values: Values) -> tuple[Part, ...]:
        built: list[Part] = []
        for span, part in parts:
            try:
                built.extend(part(values))
            except (ArithmeticError, ValueError) as e:
                # An expression such as sqrt(x - 1) can fail for some parameter values.
                raise ModelError(
                    f"the geometry of class `{name}` cannot be evaluated for "
                    f"{dict(values)}: {failure_reason(e)}",
                    path=program.path,
                    span=span,
                    source=program.source,
                ) from e
        return tuple(built)

    return build
