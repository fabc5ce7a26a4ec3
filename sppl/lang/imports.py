"""Imports: ``import "file.scn"`` and ``from "file.scn" import a, b``.

A part of the compiler (``sppl.lang.compile``), which it is mixed into. An imported file is
compiled once per compilation, by a compiler of its own that shares the ``Loader``; what it
offers (its classes, constants, colours and palettes) is a ``Module``. The loader also keeps
the chain of files being imported, which is how a cycle is found, and the meshes already
loaded.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..errors import ModelError
from . import ast
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


class ImportsMixin:
    """The compiler's imports. Uses the compiler's ``program``, ``loader``, ``error``,
    ``errors``, ``imported_errors``, ``symbols``, ``classes``, ``palette``, ``_declare``,
    ``_add_class`` and ``_folder``."""

    def module(self) -> Module:
        exported = {
            n: s for n, s in self.symbols.items() if n not in BUILTINS and s.kind in _EXPORTED
        }
        return Module(
            self.program.path,
            dict(self.classes),
            exported,
            dict(self.palette),
            self.errors + self.imported_errors,
        )

    def _import(self, node: ast.Import) -> None:
        module = self._load(node)
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
                self.error(
                    f"`{node.path.value}` has no class, constant, colour or palette "
                    f"`{ident.text}`",
                    ident.span,
                    did_you_mean(ident.text, exports) or known("names", exports),
                )
        for ident, name in wanted:
            if name in module.classes:
                if self._add_class(module.classes[name], ident, node.span, imported=True):
                    # Its colours, for the model's record (the importer's own names win).
                    for colour, rgb in module.palette.items():
                        self.palette.setdefault(colour, rgb)
                continue
            origin = module.symbols[name].imported or str(Path(module.path).resolve())
            symbol = replace(module.symbols[name], span=node.span, imported=origin)
            existing = self.symbols.get(name)
            if existing is not None and existing.imported == origin:
                continue  # the same name from the same file, through another import
            if self._declare(ident, symbol):
                if symbol.kind == COLOUR and symbol.value is not None:
                    self.palette[name] = symbol.value
                if symbol.kind == PALETTE:
                    for colour in symbol.value:
                        if colour in module.palette:
                            self.palette.setdefault(colour, module.palette[colour])

    def _load(self, node: ast.Import) -> Module | None:
        """The imported file, compiled (once per compilation), or None after reporting."""
        text = node.path.value
        path = Path(os.path.normpath(self._folder() / text))
        if not path.is_file():
            self.error(
                f"cannot find the imported file `{text}`",
                node.path.span,
                f"looked for {path}; the path is relative to the importing file",
            )
            return None
        resolved = path.resolve()
        if resolved in self.loader.stack:
            start = self.loader.stack.index(resolved)
            chain = [p.name for p in self.loader.stack[start:]] + [resolved.name]
            self.error(
                f"`{text}` is imported in a cycle: {' -> '.join(chain)}",
                node.path.span,
                "a file cannot import itself, directly or through other files",
            )
            return None
        module = self.loader.modules.get(resolved)
        first_time = module is None
        if module is None:
            module = self._compile_import(path, resolved)
            self.loader.modules[resolved] = module
        if module.errors:
            n = len(module.errors)
            self.error(
                f"the imported file `{text}` has {n} error{'s' if n > 1 else ''}",
                node.path.span,
                "listed below",
            )
            if first_time:
                self.imported_errors.extend(module.errors)
        return module

    def _compile_import(self, path: Path, resolved: Path) -> Module:
        try:
            program = parse(read_source(path), str(path))
        except ModelError as error:
            return Module(str(path), {}, {}, {}, [error])
        child = type(self)(program, self.loader, main=False)
        self.loader.stack.append(resolved)
        try:
            child.check()
        finally:
            self.loader.stack.pop()
        return child.module()
