"""Imports: ``import "file.scn"`` and ``from "file.scn" import a, b``.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. An
imported file is compiled once per compilation, by a compiler of its own (which the compiler
passes in as a callback) that shares the ``Loader``; what it offers (its classes, constants,
colours and palettes) is a ``Module``. The loader also keeps the chain of files being
imported, which is how a cycle is found, and the meshes already loaded.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..errors import ModelError, Span
from . import ast
from .context import CompileContext, PendingClass
from .expressions import BUILTINS, COLOUR, CONSTANT, PALETTE, RGB, Symbol, did_you_mean, known
from .parser import parse


def read_source(path: str | Path) -> str:
    """The text of a model file, or ``ModelError`` saying why it cannot be read."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as e:
        raise ModelError(f"cannot read the model file: {e.strerror}", path=path) from None
    except UnicodeDecodeError:
        raise ModelError("the model file is not UTF-8 text", path=path) from None


# Kinds of top-level names another file may import.
_EXPORTED = (CONSTANT, COLOUR, PALETTE)


@dataclass
class Module:
    """What an imported file offers: its classes and its top-level names."""

    path: str
    classes: dict[str, Any]
    symbols: dict[str, Symbol]
    palette: dict[str, RGB]
    errors: list[ModelError]


class Loader:
    """What one compilation shares with the files it imports: the chain of files being
    imported (to find cycles), the files already compiled, and the meshes already loaded."""

    def __init__(self) -> None:
        self.stack: list[Path] = []
        self.modules: dict[Path, Module] = {}
        self.meshes: dict[Path, str | None] = {}  # file: why it cannot be used, or None


def module_of(context: CompileContext) -> Module:
    """What a compiled file offers the files that import it."""
    exported = {
        n: s for n, s in context.symbols.items() if n not in BUILTINS and s.kind in _EXPORTED
    }
    return Module(
        context.program.path,
        dict(context.classes),
        exported,
        dict(context.palette),
        context.errors + context.imported_errors,
    )


# Adds a class to the file's classes (its name, the import that brings it): whether it was new.
AddClass = Callable[[PendingClass, ast.Ident, Span], bool]
# Checks an imported file's program with a compiler of its own, sharing the loader.
CheckImport = Callable[[ast.Program, Loader], Module]


class Imports:
    """The ``import`` statements of one file."""

    def __init__(
        self, context: CompileContext, add_class: AddClass, check_import: CheckImport
    ) -> None:
        self.context = context
        self.add_class = add_class
        self.check_import = check_import

    def load(self, node: ast.Import) -> None:
        """Add the names the statement imports to the file's own."""
        context = self.context
        module = self._module(node)
        if module is None:
            return
        exports: dict[str, Any] = {**module.symbols, **module.classes}
        if node.names is None:
            wanted = [(ast.Ident(n, node.path.span), n) for n in exports]
        else:
            wanted = []
            for ident in node.names:
                if ident.text in exports:
                    wanted.append((ident, ident.text))
                    continue
                context.error(
                    f"`{node.path.value}` has no class, constant, colour or palette "
                    f"`{ident.text}`",
                    ident.span,
                    did_you_mean(ident.text, exports) or known("names", exports),
                )
        for ident, name in wanted:
            if name in module.classes:
                if self.add_class(module.classes[name], ident, node.span):
                    # Its colours, for the model's record (the importer's own names win).
                    for colour, rgb in module.palette.items():
                        context.palette.setdefault(colour, rgb)
                continue
            origin = module.symbols[name].imported or str(Path(module.path).resolve())
            symbol = replace(module.symbols[name], span=node.span, imported=origin)
            existing = context.symbols.get(name)
            if existing is not None and existing.imported == origin:
                continue  # the same name from the same file, through another import
            if context.declare(ident, symbol):
                if symbol.kind == COLOUR and symbol.value is not None:
                    context.palette[name] = symbol.value
                if symbol.kind == PALETTE:
                    for colour in symbol.value:
                        if colour in module.palette:
                            context.palette.setdefault(colour, module.palette[colour])

    def _module(self, node: ast.Import) -> Module | None:
        """The imported file, compiled (once per compilation), or None after reporting."""
        context = self.context
        text = node.path.value
        path = Path(os.path.normpath(context.folder() / text))
        if not path.is_file():
            context.error(
                f"cannot find the imported file `{text}`",
                node.path.span,
                f"looked for {path}; the path is relative to the importing file",
            )
            return None
        resolved = path.resolve()
        if resolved in context.loader.stack:
            start = context.loader.stack.index(resolved)
            chain = [p.name for p in context.loader.stack[start:]] + [resolved.name]
            context.error(
                f"`{text}` is imported in a cycle: {' -> '.join(chain)}",
                node.path.span,
                "a file cannot import itself, directly or through other files",
            )
            return None
        module = context.loader.modules.get(resolved)
        first_time = module is None
        if module is None:
            module = self._compile_import(path, resolved)
            context.loader.modules[resolved] = module
        if module.errors:
            n = len(module.errors)
            context.error(
                f"the imported file `{text}` has {n} error{'s' if n > 1 else ''}",
                node.path.span,
                "listed below",
            )
            if first_time:
                context.imported_errors.extend(module.errors)
        return module

    def _compile_import(self, path: Path, resolved: Path) -> Module:
        try:
            program = parse(read_source(path), str(path))
        except ModelError as error:
            return Module(str(path), {}, {}, {}, [error])
        loader = self.context.loader
        loader.stack.append(resolved)
        try:
            return self.check_import(program, loader)
        finally:
            loader.stack.pop()
