"""Top-level names: the constants (``let``) and colours of a file, and its imports' names.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. Names are
declared in a first pass over the whole file, then each is given its value where it is defined:
a name used before its definition can so be told apart from one never defined.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from . import ast
from .context import CompileContext
from .expressions import COLOUR, CONSTANT, PALETTE, Symbol


def declare_globals(
    context: CompileContext, load_import: Callable[[ast.Import], None]
) -> None:
    """Register every import, constant, colour and palette before compiling any statement.

    Then a name used before its definition can be told apart from one never defined.
    """
    for statement in context.program.statements:
        if isinstance(statement, ast.Import):
            load_import(statement)
        elif isinstance(statement, ast.Let):
            context.declare(statement.name, Symbol(statement.name.text, CONSTANT, statement.span))
        elif isinstance(statement, ast.Colours):
            for definition in statement.definitions:
                symbol = Symbol(definition.name.text, COLOUR, definition.span)
                context.declare(definition.name, symbol)
            if statement.name is not None:
                names = tuple(d.name.text for d in statement.definitions)
                symbol = Symbol(statement.name.text, PALETTE, statement.span, names)
                context.declare(statement.name, symbol)


def colours(context: CompileContext, node: ast.Colours) -> None:
    for definition in node.definitions:
        value = context.expr.colour(definition.value, context.global_scope())
        if value is not None and context.defines(definition.name, definition.span):
            context.symbols[definition.name.text] = replace(
                context.symbols[definition.name.text], value=value
            )
            context.palette[definition.name.text] = value


def let(context: CompileContext, node: ast.Let) -> None:
    value = context.expr.constant(node.value, context.global_scope())
    if value is not None and context.defines(node.name, node.span):
        context.symbols[node.name.text] = replace(context.symbols[node.name.text], value=value)
