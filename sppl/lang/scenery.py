"""Static scenery: the ``static`` elements and the ``ground``, fixed parts of every scene.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``; their
geometry is compiled by ``shapes.py`` with no parameters to vary, so it is evaluated once.
"""

from __future__ import annotations

import numpy as np

from ..errors import Span
from ..model.geometry import Part
from . import ast
from .context import CompileContext
from .expressions import Scope, failure_reason
from .shapes import Shapes, posed

_GROUND_SIZE = 20.0  # metres on a side
_GROUND_THICKNESS = 0.01


class Scenery:
    """The parts every scene of the model holds, whatever its objects."""

    def __init__(self, context: CompileContext, shapes: Shapes) -> None:
        self.context = context
        self.shapes = shapes
        self.parts: list[Part] = []
        self.names: dict[str, Span] = {}  # of the static elements, where each is defined
        self.ground_at: Span | None = None  # where the ground is given

    def static(self, node: ast.StaticDef) -> None:
        context = self.context
        name = node.name.text
        if name in self.names:
            context.error(f"static `{name}` is already defined on line {self.names[name].line}",
                          node.name.span)
        else:
            self.names[name] = node.span
        scope = Scope(context.symbols, where="a static element")
        poses = [item for item in node.body if isinstance(item, ast.Pose)]
        for extra in poses[1:]:
            context.error(f"`pose` is already given on line {poses[0].span.line}", extra.span)
        pose = self.shapes.transform(poses[0].modifiers, "pose", scope) if poses else np.eye(4)
        geometries = [item for item in node.body if isinstance(item, ast.Geometry)]
        if not geometries:
            context.error(f"static `{name}` has no geometry", node.name.span)
        for item in geometries:
            parts = self.shapes.geometry(item, scope)
            if parts is None or pose is None:
                continue
            try:
                self.parts.extend(posed(pose, parts)({}))
            except (ArithmeticError, ValueError) as e:
                context.error(f"this geometry cannot be evaluated: {failure_reason(e)}", item.span)

    def ground(self, node: ast.Ground) -> None:
        context = self.context
        if self.ground_at is not None:
            context.error(f"the ground is already given on line {self.ground_at.line}", node.span)
            return
        self.ground_at = node.span
        scope = context.global_scope("the ground")
        ok = self.shapes.transform(
            tuple(m for m in node.modifiers if m.keyword not in ("colour", "size")),
            "ground",
            scope,
        )
        seen: dict[str, ast.Modifier] = {}
        for modifier in node.modifiers:
            if modifier.keyword in seen and modifier.keyword in ("colour", "size"):
                context.error(f"`{modifier.keyword}` is given twice", modifier.span)
                ok = None
            seen.setdefault(modifier.keyword, modifier)
        colour = None
        if "colour" in seen:
            colour = context.expr.colour(seen["colour"].value, scope)
        else:
            context.error(
                "the ground needs a colour", node.span, "e.g. `ground colour rgb(0.4, 0.4, 0.4)`"
            )
        size = _GROUND_SIZE
        if "size" in seen:
            size = context.expr.constant(seen["size"].value, scope)
            if size is not None and size <= 0:
                context.error(f"the size of the ground must be positive, got {size:g}",
                              seen["size"].value.span)
                size = None
        if ok is None or colour is None or size is None:
            return
        matrix = np.diag([size, size, _GROUND_THICKNESS, 1.0])
        matrix[2, 3] = -_GROUND_THICKNESS
        # The ground is drawn first: objects resting on it hide its top face where they stand.
        self.parts.insert(0, Part("box", matrix, tuple(float(c) for c in colour)))
