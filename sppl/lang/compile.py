"""Syntax tree to ``Model``: the semantic checks of a model file, then the model itself.

The compiler walks the statements in order, so a top-level name (a constant, a colour, a
palette, an imported name) must be defined before it is used; inside a class, parameters and
derived quantities may come in any order, as long as none depends on itself. It reports every
error it finds rather than stopping at the first: a file's errors are raised together as one
``ModelErrors``, sorted by position. Nothing here knows any concrete class: an object class is
whatever its declarations say, and its geometry is compiled to a function from parameter
values to posed parts.

This module drives the parts, each handed the file's ``CompileContext`` (``context.py``):
``names.py`` (constants and colours), ``imports.py``, ``classes.py`` with ``declarations.py``
and ``shapes.py``, ``scenery.py``, ``sensors.py``, ``settings.py`` (render and inference),
``constraints.py`` (and the region), then ``steps.py`` and ``changes.py`` once every
statement is compiled. The ordering of a class's declarations is in ``order.py``; priors and
domains in ``priors.py``.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from ..errors import ModelErrors, Span
from ..model.types import Model, Sensor
from . import ast, names
from .changes import resolve_changes
from .classes import Classes
from .constraints import Constraints
from .context import DEFAULT_PATH, CompileContext
from .expressions import CATEGORICAL_PARAMETER, COLOUR
from .imports import Imports, Loader, Module, module_of, read_source
from .parser import parse
from .scenery import Scenery
from .sensors import Sensors
from .settings import Settings
from .shapes import Shapes
from .steps import apply_steps


def load_model(path: str | Path) -> Model:
    """Read, check and compile a ``.scn`` file; raise ``ModelError`` if anything is wrong."""
    return compile_model(read_source(path), path)


def compile_model(text: str, path: str | Path = DEFAULT_PATH) -> Model:
    """Check and compile the text of a model file; ``path`` is used in error messages and
    to find the files it imports and the meshes it loads (relative to its folder)."""
    loader = Loader()
    if str(path) != DEFAULT_PATH:
        loader.stack.append(Path(path).resolve())  # so that a file importing it is a cycle
    return _Compiler(parse(text, str(path)), loader).compile()


class _Compiler:
    """One file's compilation: the parts, and the order they run in. ``main`` is false for
    an imported file, which need not declare a class and is not a model on its own."""

    def __init__(self, program: ast.Program, loader: Loader, main: bool = True) -> None:
        self.context = context = CompileContext(program, loader)
        self.main = main
        shapes = Shapes(context)
        self.classes = Classes(context, shapes)
        self.imports = Imports(context, self.classes.add, _check_import)
        self.scenery = Scenery(context, shapes)
        self.sensors = Sensors(context)
        self.settings = Settings(context)
        self.constraints = Constraints(context)
        # Resolved once every class is known: a change may name one defined after it.
        self.changes: list[ast.Change] = []

    def check(self) -> None:
        """Compile every statement, collecting errors."""
        context = self.context
        names.declare_globals(context, self.imports.load)
        handlers = {
            ast.Import: lambda node: None,  # done by declare_globals
            ast.Colours: partial(names.colours, context),
            ast.Let: partial(names.let, context),
            ast.ClassDef: self.classes.compile,
            ast.StaticDef: self.scenery.static,
            ast.Ground: self.scenery.ground,
            ast.Change: self.changes.append,
            ast.Constraint: self.constraints.add_constraint,
            ast.Region: self.constraints.set_region,
            ast.Sensor: self.sensors.compile,
            ast.Render: self.settings.render,
            ast.Inference: self.settings.inference,
        }
        for statement in context.program.statements:
            handlers[type(statement)](statement)
        if self.main and not context.classes:
            context.error(
                "the model declares no object classes",
                Span(1, 1),
                "add one with `class NAME { ... }`",
            )
        owners = [*context.classes.values(), *self.sensors.by_kind.values(),
                  self.settings.lighting]
        apply_steps(context, self.settings.steps, owners)
        resolve_changes(context, self.changes)
        self.constraints.restrict()
        if self.main and not context.errors and not context.imported_errors:
            self.classes.check_scene_size(self.constraints.max_objects)

    def compile(self) -> Model:
        self.check()
        context = self.context
        if context.errors or context.imported_errors:
            raise ModelErrors(context.errors + context.imported_errors)
        return self._model()

    def _model(self) -> Model:
        context = self.context
        restrictions = self.constraints.restrictions
        classes = tuple(self.classes.object_class(c, restrictions.get(c.name))
                        for c in context.classes.values())
        sensors = {
            kind: Sensor(kind, s.likelihood, tuple(s.parameters), dict(s.options))
            for kind, s in self.sensors.by_kind.items()
        }
        path = context.program.path
        return Model(
            classes=classes,
            sensors=sensors,
            inference=self.settings.inference_settings(),
            render=self.settings.render_settings(),
            colours=dict(context.palette),
            no_overlap=self.constraints.no_overlap,
            max_objects=self.constraints.max_objects,
            region=self.constraints.region,
            static_parts=tuple(self.scenery.parts),
            path=None if path == DEFAULT_PATH else Path(path),
            source=context.program.source,
        )


def _check_import(program: ast.Program, loader: Loader) -> Module:
    """An imported file, checked by a compiler of its own that shares the loader."""
    compiler = _Compiler(program, loader, main=False)
    compiler.check()
    return module_of(compiler.context)


__all__ = ["compile_model", "load_model", "COLOUR", "CATEGORICAL_PARAMETER"]
