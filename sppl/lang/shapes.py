"""The geometry of a model file: primitives, meshes, poses and footprints.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``: each
construct is checked and compiled to a function from an object's values to posed parts (or to
its footprint), folded to constants where it uses none of the object's values. Classes
(``classes.py``) and static scenery (``scenery.py``) are built from these.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from ..model.geometry import MESH_PREFIX, ROUND_SECTIONS, Part, load_mesh, rotation_z
from ..model.primitives import get_primitive, primitive_names
from ..model.types import Values
from . import ast
from .context import CompileContext
from .expressions import (
    Colour,
    Numeric,
    Scope,
    as_function,
    did_you_mean,
    known,
)


class _Arguments(Mapping):
    """Each shape a geometry line can name, with its arguments: the registered primitives
    (``sppl.model.primitives``), read when a model is compiled so that a shape registered
    after import is known, and ``mesh("file")``."""

    def _all(self) -> dict[str, tuple[str, ...]]:
        return {**{n: get_primitive(n).arguments for n in primitive_names()}, "mesh": ("file",)}

    def __getitem__(self, name: str) -> tuple[str, ...]:
        return self._all()[name]

    def __iter__(self):
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


_PRIMITIVES = _Arguments()


def _pieces(primitive: str, s: list[float]) -> list[tuple[str, np.ndarray]]:
    """The base shapes a primitive is made of at these argument values, with their matrices."""
    return get_primitive(primitive).parts(s)


_FOOTPRINTS = {"rectangle": ("width", "depth"), "circle": ("radius",)}
# Which modifiers each construct takes.
_MODIFIERS = {
    "geometry": ("at", "rotate", "scale", "colour"),
    "pose": ("at", "rotate", "scale"),
    "footprint": ("at", "rotate", "scale"),
    "ground": ("colour", "size"),
}

Matrix = np.ndarray | Callable[[Values], np.ndarray]


class Shapes:
    """The geometry of one file: what its classes and static elements are made of."""

    def __init__(self, context: CompileContext) -> None:
        self.context = context
        # What nearly every construct below uses.
        self.expr = context.expr
        self.error = context.error

    def geometry(
        self, node: ast.Geometry, scope: Scope
    ) -> Callable[[Values], tuple[Part, ...]] | None:
        """A function from parameter values to the posed parts, or None after reporting."""
        pieces = self._shape(node.primitive, scope)
        transform = self.transform(node.modifiers, "geometry", scope)
        colour_modifier = modifier_of(node.modifiers, "colour")
        colour: Colour | None = None
        if colour_modifier is not None:
            colour = self.expr.colour(colour_modifier.value, scope)
        else:
            self.error(
                "a geometry line needs a colour",
                node.span,
                "add `colour NAME` or `colour rgb(r, g, b)`",
            )
        if pieces is None or transform is None or colour is None:
            return None
        colour_fn = colour if callable(colour) else (lambda values: colour)

        def parts(values: Values) -> tuple[Part, ...]:
            m = _evaluate(transform, values)
            rgb = tuple(float(c) for c in colour_fn(values))
            return tuple(Part(name, m @ _evaluate(pm, values), rgb) for name, pm in pieces)

        return parts

    def _shape(self, call: ast.Call, scope: Scope) -> list[tuple[str, Matrix]] | None:
        """The unit shapes a primitive is made of, each with its scaling matrix."""
        name = call.func.text
        if name not in _PRIMITIVES:
            self.error(
                f"unknown primitive `{name}`",
                call.func.span,
                did_you_mean(name, _PRIMITIVES) or known("primitives", _PRIMITIVES),
            )
            return None
        arguments = _PRIMITIVES[name]
        signature = f"{name}({', '.join(arguments)})"
        bound = self.expr.bind(call, arguments, signature)
        if bound is None:
            return None
        if len(bound) != len(arguments):
            self.expr.arity_error(call, signature)
            return None
        if name == "mesh":
            mesh = self._mesh(bound["file"])
            return None if mesh is None else [(mesh, np.eye(4))]
        sizes = [self.expr.number(bound[a], scope) for a in arguments]
        if any(s is None for s in sizes):
            return None
        for size, a in zip(sizes, arguments, strict=True):
            if isinstance(size, float) and size <= 0:
                self.error(f"the {a} of a {name} must be positive, got {size:g}", bound[a].span)
                return None
        if all(isinstance(s, float) for s in sizes):
            return list(_pieces(name, sizes))
        functions = [as_function(s) for s in sizes]
        count = len(_pieces(name, [1.0] * len(sizes)))
        return [
            (
                _pieces(name, [1.0] * len(sizes))[i][0],
                lambda values, i=i: _pieces(name, [f(values) for f in functions])[i][1],
            )
            for i in range(count)
        ]

    def _mesh(self, expr: ast.Expr) -> str | None:
        """The primitive name of a mesh file (relative to the model file), after checking that
        it exists and loads; None after reporting."""
        if not isinstance(expr, ast.String):
            self.error(
                'a mesh is read from a file: mesh("file.obj")', expr.span, "the path is in quotes"
            )
            return None
        path = Path(os.path.normpath(self.context.folder() / expr.value))
        if not path.is_file():
            self.error(
                f"cannot find the mesh file `{expr.value}`",
                expr.span,
                f"looked for {path}; the path is relative to the model file",
            )
            return None
        resolved = path.resolve()
        if resolved not in self.context.loader.meshes:
            try:
                load_mesh(str(resolved))
                self.context.loader.meshes[resolved] = None
            except ValueError as error:
                self.context.loader.meshes[resolved] = str(error)
        problem = self.context.loader.meshes[resolved]
        if problem is not None:
            self.error(
                f"the mesh file `{expr.value}` cannot be loaded as a triangle mesh",
                expr.span,
                "OBJ, PLY, STL, OFF and GLB files are understood",
            )
            return None
        return MESH_PREFIX + str(resolved)

    def transform(
        self, modifiers: tuple[ast.Modifier, ...], construct: str, scope: Scope
    ) -> Matrix | None:
        """translate @ rotate @ scale from the modifiers, checking which may be given."""
        allowed = _MODIFIERS[construct]
        seen: dict[str, ast.Modifier] = {}
        ok = True
        for modifier in modifiers:
            if modifier.keyword in seen:
                self.error(f"`{modifier.keyword}` is given twice", modifier.span)
                ok = False
            elif modifier.keyword not in allowed:
                listed = ", ".join(f"`{a}`" for a in allowed)
                self.error(
                    f"a {construct} takes {listed}, not `{modifier.keyword}`", modifier.span
                )
                ok = False
            else:
                seen[modifier.keyword] = modifier
        position = self._position(seen.get("at"), scope)
        rotation = self._rotation(seen.get("rotate"), scope)
        scale = self._scale(seen.get("scale"), scope)
        if not ok or position is None or rotation is None or scale is None:
            return None
        parts = [position, rotation, scale]
        if all(isinstance(p, np.ndarray) for p in parts):
            return position @ rotation @ scale
        return lambda values: (
            _evaluate(position, values) @ _evaluate(rotation, values) @ _evaluate(scale, values)
        )

    def _position(self, modifier: ast.Modifier | None, scope: Scope) -> Matrix | None:
        if modifier is None:
            return np.eye(4)
        items = modifier.value.items
        if len(items) > 3:
            self.error(
                f"`at` takes (x, y) or (x, y, z), got {len(items)} values", modifier.value.span
            )
            return None
        # Objects rest on the ground unless the model lifts them.
        xyz = [self.expr.number(e, scope) for e in items] + [0.0] * (3 - len(items))
        if any(p is None for p in xyz):
            return None
        if all(isinstance(p, float) for p in xyz):
            return _translation(xyz)
        functions = [as_function(p) for p in xyz]
        return lambda values: _translation([f(values) for f in functions])

    def _rotation(self, modifier: ast.Modifier | None, scope: Scope) -> Matrix | None:
        if modifier is None:
            return np.eye(4)
        angle = self.expr.number(modifier.value, scope)
        axis: list[Numeric | None] = [0.0, 0.0, 1.0]
        if modifier.axis is not None:
            if len(modifier.axis.items) != 3:
                n = len(modifier.axis.items)
                self.error(f"an axis is (x, y, z), got {n} values", modifier.axis.span)
                return None
            axis = [self.expr.number(e, scope) for e in modifier.axis.items]
        if angle is None or any(a is None for a in axis):
            return None
        if all(isinstance(a, float) for a in axis) and not any(axis):
            self.error("the axis of a rotation must not be (0, 0, 0)", modifier.axis.span)
            return None
        if isinstance(angle, float) and all(isinstance(a, float) for a in axis):
            return _rotation(axis, angle)
        angle_fn = as_function(angle)
        axis_fns = [as_function(a) for a in axis]
        return lambda values: _rotation([f(values) for f in axis_fns], angle_fn(values))

    def _scale(self, modifier: ast.Modifier | None, scope: Scope) -> Matrix | None:
        if modifier is None:
            return np.eye(4)
        value = modifier.value
        items = list(value.items) if isinstance(value, ast.Tuple) else [value]
        if len(items) not in (1, 3):
            self.error(
                f"`scale` takes one factor or (x, y, z) factors, got {len(items)}", value.span
            )
            return None
        factors = [self.expr.number(e, scope) for e in items]
        if any(f is None for f in factors):
            return None
        for f, e in zip(factors, items, strict=True):
            if isinstance(f, float) and f <= 0:
                self.error(f"a scale factor must be positive, got {f:g}", e.span)
                return None
        if len(factors) == 1:
            factors = factors * 3
        if all(isinstance(f, float) for f in factors):
            return np.diag([*factors, 1.0])
        functions = [as_function(f) for f in factors]
        return lambda values: np.diag([*(f(values) for f in functions), 1.0])

    def footprint(
        self, node: ast.Footprint, pose: Matrix, scope: Scope
    ) -> Callable[[Values], np.ndarray] | None:
        """A declared footprint: the shape's outline, posed by its modifiers and the pose."""
        call = node.shape
        name = call.func.text
        if name not in _FOOTPRINTS:
            self.error(
                f"unknown footprint shape `{name}`",
                call.func.span,
                did_you_mean(name, _FOOTPRINTS) or known("footprint shapes", _FOOTPRINTS),
            )
            return None
        arguments = _FOOTPRINTS[name]
        signature = f"{name}({', '.join(arguments)})"
        bound = self.expr.bind(call, arguments, signature)
        transform = self.transform(node.modifiers, "footprint", scope)
        if bound is None or transform is None:
            return None
        if len(bound) != len(arguments):
            self.expr.arity_error(call, signature)
            return None
        sizes = [self.expr.number(bound[a], scope) for a in arguments]
        if any(s is None for s in sizes):
            return None
        functions = [as_function(s) for s in sizes]

        def footprint(values: Values) -> np.ndarray:
            m = _evaluate(pose, values) @ _evaluate(transform, values)
            outline = _outline(name, [f(values) for f in functions])
            return (outline @ m.T)[:, :2]

        return footprint


# ---- helpers ---------------------------------------------------------------------------------


def modifier_of(modifiers: tuple[ast.Modifier, ...], keyword: str) -> ast.Modifier | None:
    return next((m for m in modifiers if m.keyword == keyword), None)


def _evaluate(matrix: Matrix, values: Values) -> np.ndarray:
    return matrix(values) if callable(matrix) else matrix


def posed(
    pose: Matrix, parts: Callable[[Values], tuple[Part, ...]]
) -> Callable[[Values], tuple[Part, ...]]:
    if isinstance(pose, np.ndarray) and np.array_equal(pose, np.eye(4)):
        return parts

    def moved(values: Values) -> tuple[Part, ...]:
        m = _evaluate(pose, values)
        return tuple(Part(p.primitive, m @ p.matrix, p.colour) for p in parts(values))

    return moved


def _translation(xyz) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = xyz
    return m


def _rotation(axis, angle: float) -> np.ndarray:
    """Counter-clockwise (right-handed) rotation by ``angle`` about ``axis`` (Rodrigues)."""
    x, y, z = (float(a) for a in axis)
    if x == 0.0 and y == 0.0 and z > 0.0:
        return rotation_z(angle)
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        raise ValueError("the axis of a rotation is (0, 0, 0)")
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    m = np.eye(4)
    m[:3, :3] = (
        (c + x * x * C, x * y * C - z * s, x * z * C + y * s),
        (y * x * C + z * s, c + y * y * C, y * z * C - x * s),
        (z * x * C - y * s, z * y * C + x * s, c + z * z * C),
    )
    return m


def _outline(shape: str, sizes: list[float]) -> np.ndarray:
    """A footprint shape's outline in homogeneous coordinates, counter-clockwise."""
    if shape == "rectangle":
        w, d = sizes
        xy = np.array([[-w / 2, -d / 2], [w / 2, -d / 2], [w / 2, d / 2], [-w / 2, d / 2]])
    else:
        (r,) = sizes
        t = np.linspace(0.0, 2.0 * math.pi, ROUND_SECTIONS, endpoint=False)
        xy = r * np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.column_stack([xy, np.zeros(len(xy)), np.ones(len(xy))])
