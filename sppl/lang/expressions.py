"""Expressions of a model file: name resolution, constant folding and compiled closures.

An expression that uses no parameter is folded to a float when the model is compiled, so its
errors (an unknown name, a division by zero) are reported with their position. One that uses
an object's parameters becomes a function of the object's parameter values, evaluated each
time the object is built. Either way the result is a ``Numeric``; ``None`` stands for an
expression whose error has already been reported, so that one mistake is reported once.
"""

from __future__ import annotations

import difflib
import math
import operator
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import Span
from ..model.types import Values
from . import ast

Numeric = float | Callable[[Values], float]
RGB = tuple[float, float, float]
Colour = RGB | Callable[[Values], RGB]
Report = Callable[[str, Span, str | None], None]

# Kinds of symbol. A colour parameter's value is a palette name, a categorical one's any label.
CONSTANT = "constant"
COLOUR = "colour"
PALETTE = "palette"
PARAMETER = "parameter"
COLOUR_PARAMETER = "colour parameter"
CATEGORICAL_PARAMETER = "categorical parameter"
DERIVED = "derived quantity"
PARAMETER_KINDS = (PARAMETER, COLOUR_PARAMETER, CATEGORICAL_PARAMETER)
# Kinds whose value differs from object to object: only some places may use them.
OBJECT_KINDS = (*PARAMETER_KINDS, DERIVED)


@dataclass(frozen=True)
class Symbol:
    """What a name in an expression denotes, and where it is defined."""

    name: str
    kind: str
    span: Span  # the defining statement (an import for imported names); line 0 for built-ins
    # A constant's float, a palette colour's RGB, a palette's colour names, a derived
    # quantity's ``Numeric`` (None for any of these if its definition failed), or, for a
    # colour parameter, the palette its values are looked up in.
    value: Any = None
    # Whether a use before the definition is an error: true for top-level names, false for
    # a class's parameters and derived quantities, which may come in any order.
    ordered: bool = True
    # The values a categorical or colour parameter takes, once its prior is compiled.
    labels: tuple[str, ...] | None = None
    # The file an imported name comes from.
    imported: str | None = None


BUILTINS = {"pi": Symbol("pi", CONSTANT, Span(0, 0, 0, 0), math.pi)}


@dataclass(frozen=True)
class Scope:
    """The names visible to an expression, and whether parameters may be used there."""

    symbols: Mapping[str, Symbol]
    parameters_allowed: bool = False
    where: str = "this expression"  # for "a prior may use constants only"


_BINARY = {
    "+": operator.add,
    "-": operator.sub,
    "*": operator.mul,
    "/": operator.truediv,
    # math.pow, unlike **, raises instead of returning a complex number for (-8) ** (1/3).
    "^": math.pow,
}
_UNARY = {"-": operator.neg, "+": operator.pos}
# name: (fewest arguments, most arguments or None for any number, function)
_FUNCTIONS: dict[str, tuple[int, int | None, Callable[..., float]]] = {
    "sqrt": (1, 1, math.sqrt),
    "sin": (1, 1, math.sin),
    "cos": (1, 1, math.cos),
    "tan": (1, 1, math.tan),
    "asin": (1, 1, math.asin),
    "acos": (1, 1, math.acos),
    "atan": (1, 1, math.atan),
    "atan2": (2, 2, math.atan2),
    "hypot": (2, None, math.hypot),
    "exp": (1, 1, math.exp),
    "log": (1, 1, math.log),
    "abs": (1, 1, abs),
    "floor": (1, 1, math.floor),
    "ceil": (1, 1, math.ceil),
    "min": (2, None, min),
    "max": (2, None, max),
    "clamp": (3, 3, lambda x, low, high: min(max(x, low), high)),
    "deg": (1, 1, math.radians),  # degrees to radians: rotate deg(90)
}
# Functions of another kind, known by name so that a misuse gets a message of its own.
SPECIAL_FUNCTIONS = ("select", "rgb", "shade")
FUNCTION_NAMES = (*_FUNCTIONS, *SPECIAL_FUNCTIONS)


def did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    """A hint naming the closest candidate to a misspelt name, or None if nothing is close."""
    matches = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f"did you mean `{matches[0]}`?" if matches else None


def known(what: str, names: Iterable[str]) -> str:
    """A hint listing the names that would have been understood."""
    return f"known {what}: {', '.join(names)}"


def as_function(value: Numeric) -> Callable[[Values], float]:
    if isinstance(value, float):
        return lambda values: value
    return value


class Expressions:
    """Compiles expressions against a scope, reporting each error once through ``report``."""

    def __init__(self, report: Report) -> None:
        self.report = report

    # ---- numbers ----

    def number(self, expr: ast.Expr | ast.Tuple, scope: Scope) -> Numeric | None:
        if isinstance(expr, ast.Number):
            if math.isfinite(expr.value):
                return expr.value
            self.report("this number is too large", expr.span, None)
            return None
        if isinstance(expr, ast.Name):
            return self._name_as_number(expr, scope)
        if isinstance(expr, ast.UnaryOp):
            return self._apply(_UNARY[expr.op], [expr.operand], scope, expr.span)
        if isinstance(expr, ast.BinOp):
            return self._apply(_BINARY[expr.op], [expr.left, expr.right], scope, expr.span)
        if isinstance(expr, ast.Call):
            return self._function(expr, scope)
        if isinstance(expr, ast.String):
            self.report("expected a number here, not a file name", expr.span, None)
            return None
        self.report("expected a number here, not a tuple", expr.span, None)
        return None

    def constant(self, expr: ast.Expr | ast.Tuple, scope: Scope) -> float | None:
        """A number that must not depend on any parameter (``scope`` should not allow them)."""
        value = self.number(expr, scope)
        assert value is None or isinstance(value, float), "a constant scope allowed parameters"
        return value

    def constants(self, exprs: Iterable[ast.Expr], scope: Scope) -> list[float] | None:
        values = [self.constant(e, scope) for e in exprs]
        return None if any(v is None for v in values) else values

    def _name_as_number(self, name: ast.Name, scope: Scope) -> Numeric | None:
        symbol = self.resolve(name, scope, (CONSTANT, PARAMETER, DERIVED))
        if symbol is None:
            return None
        if symbol.kind in (CONSTANT, DERIVED):
            return symbol.value
        if symbol.kind == PARAMETER:
            key = symbol.name
            return lambda values: float(values[key])
        hint = None
        if symbol.kind in (COLOUR_PARAMETER, CATEGORICAL_PARAMETER):
            hint = f"turn its values into numbers with `select({name.id}, value: number, ...)`"
        self.report(f"`{name.id}` is a {symbol.kind}, not a number", name.span, hint)
        return None

    def _function(self, call: ast.Call, scope: Scope) -> Numeric | None:
        name = call.func.text
        if name in ("rgb", "shade"):
            self.report(f"{name}(...) is a colour, not a number", call.span, None)
            return None
        if name == "select":
            return self.select(call, scope, self.number)
        if name not in _FUNCTIONS:
            hint = did_you_mean(name, FUNCTION_NAMES)
            self.report(f"unknown function `{name}`", call.func.span, hint)
            return None
        fewest, most, function = _FUNCTIONS[name]
        args = self.positional(call)
        if args is None:
            return None
        if len(args) < fewest or (most is not None and len(args) > most):
            wanted = f"{fewest}" if fewest == most else f"at least {fewest}"
            plural = "" if wanted == "1" else "s"
            self.report(
                f"`{name}` takes {wanted} argument{plural}, got {len(args)}", call.span, None
            )
            return None
        return self._apply(function, args, scope, call.span)

    # ---- calls ----

    def bind(
        self,
        call: ast.Call,
        positional: tuple[str, ...],
        signature: str,
        keyword_only: tuple[str, ...] = (),
    ) -> dict[str, ast.Expr] | None:
        """Match a call's arguments to parameter names as Python does, or None after reporting.

        Which arguments are required is the caller's business (see ``arity_error``).
        """
        bound: dict[str, ast.Expr] = {}
        names = positional + keyword_only
        used = 0
        for arg in call.args:
            if isinstance(arg, ast.Labelled):
                self.report("`label: weight` pairs are for categorical only", arg.span, None)
                return None
            if isinstance(arg, ast.Keyword):
                key, value = arg.name.text, arg.value
                if key not in names:
                    hint = did_you_mean(key, names)
                    self.report(f"`{call.func.text}` has no argument `{key}`", arg.name.span, hint)
                    return None
            elif used == len(positional):
                self.arity_error(call, signature)
                return None
            else:
                key, value = positional[used], arg
                used += 1
            if key in bound:
                self.report(f"`{key}` is given twice", arg.span, None)
                return None
            bound[key] = value
        return bound

    def arity_error(self, call: ast.Call, signature: str) -> None:
        n = len(call.args)
        self.report(
            f"wrong number of arguments to `{call.func.text}`: expected {signature}, "
            f"got {n} argument{'' if n == 1 else 's'}",
            call.span,
            None,
        )

    def positional(self, call: ast.Call) -> list[ast.Expr] | None:
        """The arguments of a call that takes only positional ones, or None after reporting."""
        for arg in call.args:
            if isinstance(arg, ast.Keyword | ast.Labelled):
                name = arg.name if isinstance(arg, ast.Keyword) else arg.label
                self.report(
                    f"`{call.func.text}` takes no named arguments, such as `{name.text}`",
                    arg.span,
                    None,
                )
                return None
        return list(call.args)

    def _apply(
        self, function: Callable[..., float], operands: list[ast.Expr], scope: Scope, span: Span
    ) -> Numeric | None:
        values = [self.number(e, scope) for e in operands]
        if any(v is None for v in values):
            return None
        if all(isinstance(v, float) for v in values):
            try:
                result = float(function(*values))
                if not math.isfinite(result):
                    raise OverflowError
                return result
            except (ArithmeticError, ValueError) as e:
                self.report(f"this expression cannot be evaluated: {failure_reason(e)}", span, None)
                return None
        parts = [as_function(v) for v in values]
        return lambda v: float(function(*(p(v) for p in parts)))

    def select(self, call: ast.Call, scope: Scope, compile_branch: Callable) -> Any:
        """``select(p, a: x, b: y)``: x where the categorical parameter p is a, y where it is b.

        ``compile_branch`` compiles each branch (``number`` or ``colour``); the result is a
        function of the object's values, or None after reporting.
        """
        signature = "select(parameter, value: result, ...)"
        if not call.args or not isinstance(call.args[0], ast.Name):
            self.report(
                f"select's first argument is a categorical or colour parameter: {signature}",
                call.args[0].span if call.args else call.span,
                None,
            )
            return None
        first, branches = call.args[0], call.args[1:]
        symbol = self.resolve(first, scope, (CATEGORICAL_PARAMETER, COLOUR_PARAMETER))
        if symbol is None:
            return None
        if symbol.kind not in (CATEGORICAL_PARAMETER, COLOUR_PARAMETER):
            self.report(
                f"select chooses by a categorical or colour parameter, and `{first.id}` is a "
                f"{symbol.kind}",
                first.span,
                None,
            )
            return None
        compiled: dict[str, Callable[[Values], Any]] = {}
        ok = True
        for arg in branches:
            if not isinstance(arg, ast.Labelled):
                self.report(
                    f"each choice of select is `value: result`: {signature}", arg.span, None
                )
                return None
            label = arg.label.text
            if label in compiled:
                self.report(f"`{label}` is listed twice", arg.label.span, None)
                ok = False
                continue
            if symbol.labels is not None and label not in symbol.labels:
                hint = did_you_mean(label, symbol.labels) or known("values", symbol.labels)
                self.report(f"`{first.id}` never takes the value `{label}`", arg.label.span, hint)
                ok = False
            value = compile_branch(arg.weight, scope)
            if value is None:
                ok = False
                continue
            compiled[label] = value if callable(value) else (lambda v, c=value: c)
        if not ok:
            return None
        missing = [v for v in symbol.labels or () if v not in compiled]
        if missing:
            self.report(
                f"select by `{first.id}` needs a result for "
                + ", ".join(f"`{m}`" for m in missing),
                call.span,
                None,
            )
            return None
        key = symbol.name
        return lambda values: compiled[values[key]](values)

    # ---- colours ----

    def colour(self, expr: ast.Expr | ast.Tuple, scope: Scope) -> Colour | None:
        """A palette colour, a colour parameter, ``rgb(r, g, b)``, ``(r, g, b)``,
        ``shade(colour, factor)`` or ``select(p, a: colour, ...)``."""
        if isinstance(expr, ast.Name):
            symbol = self.resolve(expr, scope, (COLOUR, COLOUR_PARAMETER), "colour")
            if symbol is None:
                return None
            if symbol.kind == COLOUR:
                return symbol.value
            if symbol.kind == COLOUR_PARAMETER:
                key, palette = symbol.name, symbol.value
                return lambda values: palette[values[key]]
            self.report(f"`{expr.id}` is a {symbol.kind}, not a colour", expr.span, None)
            return None
        if isinstance(expr, ast.Call) and expr.func.text == "rgb":
            args = self.positional(expr)
            return None if args is None else self._rgb(args, scope, expr.span)
        if isinstance(expr, ast.Call) and expr.func.text == "select":
            return self.select(expr, scope, self.colour)
        if isinstance(expr, ast.Call) and expr.func.text == "shade":
            return self._shade(expr, scope)
        if isinstance(expr, ast.Tuple):
            return self._rgb(list(expr.items), scope, expr.span)
        self.report(
            "expected a colour: a palette colour, a colour parameter or rgb(r, g, b)",
            expr.span,
            None,
        )
        return None

    def _shade(self, call: ast.Call, scope: Scope) -> Colour | None:
        """``shade(colour, factor)``: the colour with each component times the factor, at
        most 1 (a darker or lighter variant: a material, say)."""
        args = self.positional(call)
        if args is None:
            return None
        if len(args) != 2:
            self.arity_error(call, "shade(colour, factor)")
            return None
        colour, factor = self.colour(args[0], scope), self.number(args[1], scope)
        if colour is None or factor is None:
            return None
        if isinstance(factor, float) and factor < 0:
            self.report(f"a shade factor must not be negative, got {factor:g}", args[1].span, None)
            return None

        def scaled(rgb: RGB, k: float) -> RGB:
            return tuple(min(max(c * k, 0.0), 1.0) for c in rgb)

        if not callable(colour) and isinstance(factor, float):
            return scaled(colour, factor)
        colour_fn = colour if callable(colour) else (lambda values: colour)
        factor_fn = as_function(factor)
        return lambda values: scaled(colour_fn(values), factor_fn(values))

    def _rgb(self, items: list[ast.Expr], scope: Scope, span: Span) -> Colour | None:
        if len(items) != 3:
            self.report(f"a colour has 3 components (r, g, b), got {len(items)}", span, None)
            return None
        channels = [self.number(e, scope) for e in items]
        if any(c is None for c in channels):
            return None
        for c, e in zip(channels, items, strict=True):
            if isinstance(c, float) and not 0.0 <= c <= 1.0:
                self.report(f"colour components lie in [0, 1], got {c:g}", e.span, None)
                return None
        if all(isinstance(c, float) for c in channels):
            return tuple(channels)
        parts = [as_function(c) for c in channels]
        # A component computed from parameters is kept inside [0, 1].
        return lambda values: tuple(min(max(p(values), 0.0), 1.0) for p in parts)

    # ---- names ----

    def resolve(
        self, name: ast.Name, scope: Scope, kinds: tuple[str, ...], noun: str = "name"
    ) -> Symbol | None:
        """The symbol a name denotes, or None after reporting why it cannot be used here.

        ``kinds`` are the kinds that make sense at this place; they choose the "did you mean".
        """
        symbol = scope.symbols.get(name.id)
        if symbol is None:
            candidates = [
                s.name
                for s in scope.symbols.values()
                if s.kind in kinds and (scope.parameters_allowed or s.kind not in OBJECT_KINDS)
            ]
            hint = did_you_mean(name.id, candidates)
            self.report(f"unknown {noun} `{name.id}`", name.span, hint)
            return None
        use = (name.span.line, name.span.column)
        start = (symbol.span.line, symbol.span.column)
        end = (symbol.span.end_line or symbol.span.line, symbol.span.end_column or 0)
        if start <= use < end and symbol.imported is None:
            self.report(f"`{name.id}` is used in its own definition", name.span, None)
            return None
        if use < start and symbol.ordered:
            self.report(
                f"`{name.id}` is used before its definition on line {symbol.span.line}",
                name.span,
                None,
            )
            return None
        if symbol.kind in OBJECT_KINDS and not scope.parameters_allowed:
            what = "a parameter" if symbol.kind in PARAMETER_KINDS else f"a {symbol.kind}"
            self.report(
                f"{scope.where} may use constants only, and `{name.id}` is {what}",
                name.span,
                None,
            )
            return None
        if symbol.kind in (CONSTANT, COLOUR, PALETTE, DERIVED) and symbol.value is None:
            return None  # its definition failed and was reported there
        return symbol


def names_in(node: Any) -> list[ast.Name]:
    """The names an expression or call refers to (a categorical's value labels excluded)."""
    found: list[ast.Name] = []

    def walk(n: Any) -> None:
        if isinstance(n, ast.Name):
            found.append(n)
        elif isinstance(n, ast.BinOp):
            walk(n.left)
            walk(n.right)
        elif isinstance(n, ast.UnaryOp):
            walk(n.operand)
        elif isinstance(n, ast.Tuple):
            for item in n.items:
                walk(item)
        elif isinstance(n, ast.Call):
            for arg in n.args:
                if isinstance(arg, ast.Keyword):
                    walk(arg.value)
                elif isinstance(arg, ast.Labelled):
                    walk(arg.weight)
                elif not (n.func.text == "categorical" and isinstance(arg, ast.Name)):
                    walk(arg)

    walk(node)
    return found


def failure_reason(e: Exception) -> str:
    """Why evaluating an expression raised ``e``, in words for a user."""
    if isinstance(e, ZeroDivisionError):
        return "division by zero"
    if isinstance(e, OverflowError):
        return "the result is too large"
    return "a function is applied outside its domain"
