"""What the parts of one file's compilation share, handed to each of them explicitly.

A model file is compiled by several parts (``names.py``, ``imports.py``, ``classes.py``,
``declarations.py``, ``shapes.py``, ``scenery.py``, ``sensors.py``, ``settings.py``,
``constraints.py``, ``steps.py``, ``changes.py``), driven by ``compile.py``. They all report
to one list of errors and read one table of top-level names, so these, with the classes and
sensors whose parameters are still being collected, live here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ModelError, Span
from ..model.geometry import Part
from ..model.types import Parameter, Values
from . import ast
from .expressions import BUILTINS, RGB, Expressions, Scope, Symbol
from .priors import Priors

if TYPE_CHECKING:
    from .imports import Loader

# The path of a model given as text rather than read from a file.
DEFAULT_PATH = "<string>"


@dataclass
class Owner:
    """A class or sensor being compiled; its parameters get their steps once all are known."""

    name: str
    parameters: list[Parameter] = field(default_factory=list)
    declared: set[str] = field(default_factory=set)  # parameter names, compiled or not

    def parameter(self, name: str) -> Parameter | None:
        return next((p for p in self.parameters if p.name == name), None)


@dataclass(eq=False)
class PendingClass(Owner):
    rate: float | None = None
    count: int | None = None
    max_count: int | None = None
    count_span: Span | None = None  # of its `count` line
    parts: list[tuple[Span, Callable[[Values], tuple[Part, ...]]]] = field(default_factory=list)
    span: Span | None = None  # of the class's definition
    program: ast.Program | None = None  # the file it is defined in
    position: tuple[str, str] | None = None
    footprint: Callable[[Values], np.ndarray] | None = None
    floating: bool = False
    # Declared change correspondences: id(other class) -> (other, {parameter here: there}),
    # and the factor of each that is scaled (here = factor * there).
    pairs: dict[int, tuple[PendingClass, dict[str, str]]] = field(default_factory=dict)
    scales: dict[int, dict[str, float]] = field(default_factory=dict)
    # Where each paired parameter was paired, for repeated pairings.
    paired_at: dict[tuple[int, str], Span] = field(default_factory=dict)


@dataclass
class PendingSensor(Owner):
    likelihood: str | None = None
    options: dict[str, float] = field(default_factory=dict)


class CompileContext:
    """One file's compilation: its program, its errors, its names and its classes."""

    def __init__(self, program: ast.Program, loader: Loader) -> None:
        self.program = program
        self.loader = loader
        self.errors: list[ModelError] = []
        # Those of the files it imports, each file's reported once.
        self.imported_errors: list[ModelError] = []
        self.expr = Expressions(self.error)
        self.priors = Priors(self.expr, self.error, program.path, program.source)
        self.symbols: dict[str, Symbol] = dict(BUILTINS)
        self.palette: dict[str, RGB] = {}
        self.classes: dict[str, PendingClass] = {}
        # Where each setting key was first given, to report a repeated one.
        self.seen: dict[tuple[str, ...], Span] = {}

    def error(self, message: str, span: Span, hint: str | None = None) -> None:
        self.errors.append(
            ModelError(
                message,
                path=self.program.path,
                span=span,
                source=self.program.source,
                hint=hint,
            )
        )

    def global_scope(self, where: str = "a model setting") -> Scope:
        return Scope(self.symbols, parameters_allowed=False, where=where)

    def folder(self) -> Path:
        """Where the file's imports and meshes are looked for."""
        path = self.program.path
        return Path(".") if path == DEFAULT_PATH else Path(path).parent

    def declare(self, name: ast.Ident, symbol: Symbol) -> bool:
        if not self.check_new_global(name):
            return False
        self.symbols[name.text] = symbol
        return True

    def check_new_global(self, name: ast.Ident, suffix: str = "") -> bool:
        """Whether ``name`` may be defined, reporting a clash with a global name if not."""
        existing = self.symbols.get(name.text)
        if existing is None:
            return True
        if existing.span.line == 0:
            self.error(f"`{name.text}` is built in and cannot be redefined{suffix}", name.span)
        else:
            how = "imported" if existing.imported else "defined"
            self.error(
                f"`{name.text}` is already {how} on line {existing.span.line}{suffix}", name.span
            )
        return False

    def defines(self, name: ast.Ident, span: Span) -> bool:
        """Whether this statement is the definition registered for ``name`` (not a duplicate)."""
        symbol = self.symbols.get(name.text)
        return symbol is not None and symbol.span == span and symbol.imported is None

    def first(self, key: tuple[str, ...], node: ast.Setting | ast.Step) -> bool:
        """Whether this is the first time a setting is given, reporting a repeat if not."""
        if key in self.seen:
            label = node.key if isinstance(node, ast.Setting) else node.name
            self.error(f"`{label.text}` is already set on line {self.seen[key].line}", label.span)
            return False
        self.seen[key] = node.span
        return True

    def no_domain(self, item: ast.Choice, example: str) -> None:
        name = item.name.text
        self.error(f"`{name}` has no domain", item.name.span,
                   f"write `{name} : DOMAIN ~ PRIOR`, e.g. `: {example}`")
