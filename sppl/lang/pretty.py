"""The canonical text of a model: what ``sppl fmt`` prints.

One statement or declaration per line, blocks indented by four spaces with their closing brace
on a line of its own, single spaces around ``=``, ``~``, ``:`` of a declaration and the binary
operators (none around ``^``), the fewest parentheses that keep an expression's meaning, numbers
as written (``.5`` gains its ``0``), ``colour`` and ``colours`` spelt the British way,
and the ``=`` of a ``colours`` block aligned. Blank lines are kept where the source has them
(several become one), and a blank line always separates a block from its neighbours at the top
level.

Comments are kept: a comment on a line of its own stays before the declaration it precedes, at
that declaration's indentation; a comment at the end of a line stays at the end of the line that
holds what it followed. The one place a comment moves is the inside of an expression written
over several lines: it goes after that declaration. Formatting canonical text changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from . import ast
from .parser import parse

INDENT = "    "

# Binding strength of each expression form, loosest first.
_SUM, _PRODUCT, _UNARY, _POWER, _ATOM = range(1, 6)
_LEVEL = {"+": _SUM, "-": _SUM, "*": _PRODUCT, "/": _PRODUCT, "^": _POWER}


def format_source(text: str, path: str = "<string>") -> str:
    """The canonical form of a model's text; ``ModelError`` if it does not parse."""
    return format_program(parse(text, path))


def format_program(program: ast.Program) -> str:
    return _Printer(program).run()


# The source lines of the program being printed, for numbers kept as written.
_source_lines: list[str] = []


# ---- expressions ---------------------------------------------------------------------------


def expression(node) -> str:
    """The canonical text of an expression, tuple, string or call argument."""
    if isinstance(node, ast.Number):
        return _number(node)
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.String):
        return f'"{node.value}"'
    if isinstance(node, ast.Tuple):
        return "(" + ", ".join(expression(i) for i in node.items) + ")"
    if isinstance(node, ast.Call):
        return call(node)
    if isinstance(node, ast.Keyword):
        return f"{node.name.text}={expression(node.value)}"
    if isinstance(node, ast.Labelled):
        return f"{node.label.text}: {expression(node.weight)}"
    if isinstance(node, ast.UnaryOp):
        operand = _wrap(node.operand, _level(node.operand) < _UNARY)
        return f"{node.op}{operand}"
    if isinstance(node, ast.BinOp):
        level = _LEVEL[node.op]
        if node.op == "^":
            # Right-associative, and its left operand is an atom in the grammar.
            left = _wrap(node.left, _level(node.left) < _ATOM)
            right = _wrap(node.right, _level(node.right) < _UNARY)
            return f"{left}^{right}"
        left = _wrap(node.left, _level(node.left) < level)
        right = _wrap(node.right, _level(node.right) <= level)
        return f"{left} {node.op} {right}"
    raise TypeError(f"not an expression: {node!r}")


def call(node: ast.Call) -> str:
    return f"{node.func.text}(" + ", ".join(expression(a) for a in node.args) + ")"


def _level(node) -> int:
    if isinstance(node, ast.BinOp):
        return _LEVEL[node.op]
    if isinstance(node, ast.UnaryOp):
        return _UNARY
    return _ATOM


def _wrap(node, parenthesise: bool) -> str:
    text = expression(node)
    return f"({text})" if parenthesise else text


def _number(node: ast.Number) -> str:
    """A number as written (``0.70`` stays ``0.70``), with a leading ``0`` added to ``.5``."""
    span = node.span
    if span.end_line == span.line and 0 < span.line <= len(_source_lines):
        text = _source_lines[span.line - 1][span.column - 1 : span.end_column - 1]
        if text and (text[0].isdigit() or text[0] == "."):
            return "0" + text if text.startswith(".") else text
    value = node.value
    if math.isfinite(value) and value == int(value) and abs(value) < 1e16:
        return str(int(value))
    return repr(value)


# ---- statements ----------------------------------------------------------------------------


@dataclass
class _Entry:
    """One line of output and the source lines it comes from."""

    text: str
    depth: int
    first: int  # first source line
    last: int  # last source line
    block: bool = False  # a top-level block's first line (separated by blank lines)
    closes: bool = False  # a closing brace (comments before it belong inside the block)


class _Printer:
    def __init__(self, program: ast.Program) -> None:
        self.program = program
        self.lines = program.source.splitlines()
        self.entries: list[_Entry] = []

    def run(self) -> str:
        global _source_lines
        _source_lines = self.lines
        try:
            for statement in self.program.statements:
                self._statement(statement)
        finally:
            _source_lines = []
        return self._merge()

    # -- producing entries --

    def _add(self, text: str, depth: int, span, block: bool = False) -> None:
        last = span.end_line or span.line
        self.entries.append(_Entry(text, depth, span.line, last, block))

    def _open(self, text: str, node) -> None:
        self.entries.append(_Entry(text + " {", 0, node.span.line, node.span.line, block=True))

    def _close(self, node, depth: int = 0) -> None:
        end = node.span.end_line or node.span.line
        self.entries.append(_Entry("}", depth, end, end, closes=True))

    def _statement(self, node) -> None:
        if isinstance(node, ast.Import):
            path = expression(node.path)
            if node.names is None:
                self._add(f"import {path}", 0, node.span)
            else:
                names = ", ".join(n.text for n in node.names)
                self._add(f"from {path} import {names}", 0, node.span)
        elif isinstance(node, ast.Colours):
            self._open("colours" + (f" {node.name.text}" if node.name else ""), node)
            width = max((len(d.name.text) for d in node.definitions), default=0)
            for d in node.definitions:
                self._add(f"{d.name.text.ljust(width)} = {expression(d.value)}", 1, d.span)
            self._close(node)
        elif isinstance(node, ast.Let):
            self._add(self._let(node), 0, node.span)
        elif isinstance(node, ast.ClassDef):
            self._open(f"class {node.name.text}", node)
            for item in node.body:
                self._add(self._class_item(item), 1, item.span)
            self._close(node)
        elif isinstance(node, ast.StaticDef):
            self._open(f"static {node.name.text}", node)
            for item in node.body:
                self._add(self._class_item(item), 1, item.span)
            self._close(node)
        elif isinstance(node, ast.Ground):
            self._add(_join("ground", _modifiers(node.modifiers)), 0, node.span)
        elif isinstance(node, ast.Change):
            factor = "" if node.factor is None else f"{_number(node.factor)} * "
            text = (
                f"change {node.first_class.text}.{node.first.text} <-> {factor}"
                f"{node.second_class.text}.{node.second.text}"
            )
            self._add(text, 0, node.span)
        elif isinstance(node, ast.Constraint):
            self._add(f"constraint {_rule(node.rule)}", 0, node.span)
        elif isinstance(node, ast.Region):
            args = f"({', '.join(expression(a) for a in node.args)})" if node.args else ""
            self._add(f"region {node.kind.text}{args}", 0, node.span)
        elif isinstance(node, ast.Sensor):
            self._open(f"sensor {node.kind.text}", node)
            for item in node.body:
                if isinstance(item, ast.Likelihood):
                    self._add(f"likelihood {_rule(item.rule)}", 1, item.span)
                elif isinstance(item, ast.Setting):
                    self._add(_setting(item), 1, item.span)
                else:
                    self._add(_choice(item), 1, item.span)
            self._close(node)
        elif isinstance(node, ast.Render):
            self._open("render", node)
            for item in node.settings:
                line = _setting(item) if isinstance(item, ast.Setting) else _choice(item)
                self._add(line, 1, item.span)
            self._close(node)
        elif isinstance(node, ast.Inference):
            self._open("inference", node)
            for item in node.body:
                self._add(self._inference_item(item), 1, item.span)
            self._close(node)
        else:
            raise TypeError(f"not a statement: {node!r}")

    def _let(self, node: ast.Let) -> str:
        return f"let {node.name.text} = {expression(node.value)}"

    def _class_item(self, item) -> str:
        if isinstance(item, ast.Choice):
            return _choice(item)
        if isinstance(item, ast.Let):
            return self._let(item)
        if isinstance(item, ast.Setting):
            return _setting(item)
        if isinstance(item, ast.Geometry):
            return _join(f"geometry {call(item.primitive)}", _modifiers(item.modifiers))
        if isinstance(item, ast.Pose):
            return _join("pose", _modifiers(item.modifiers))
        if isinstance(item, ast.Footprint):
            return _join(f"footprint {call(item.shape)}", _modifiers(item.modifiers))
        if isinstance(item, ast.Floating):
            return "floating"
        raise TypeError(f"not a class item: {item!r}")

    def _inference_item(self, item) -> str:
        if isinstance(item, ast.Step):
            owner = f"{item.owner.text}." if item.owner else ""
            return f"step {owner}{item.name.text} = {expression(item.value)}"
        if isinstance(item, ast.JumpWeights):
            return "jump_weights " + ", ".join(_setting(s) for s in item.weights)
        return _setting(item)

    # -- merging comments and blank lines --

    def _merge(self) -> str:
        comments = sorted(self.program.comments, key=lambda c: (c.span.line, c.span.column))
        out: list[str] = []
        previous: _Entry | None = None  # the last entry written
        source_line = 0  # the last source line accounted for
        i = 0

        def trailing(comment: ast.Comment) -> bool:
            line = self.lines[comment.span.line - 1]
            return bool(line[: comment.span.column - 1].strip())

        for entry in self.entries:
            # A comment at the end of the line the previous entry ended on stays there.
            while (
                i < len(comments)
                and previous is not None
                and comments[i].span.line == previous.last
                and comments[i].span.line < entry.first
                and trailing(comments[i])
            ):
                out[-1] += "  " + comments[i].text
                i += 1
            # Comments before this entry, and the blank line that may precede them.
            leading = []
            while i < len(comments) and comments[i].span.line < entry.first:
                leading.append(comments[i])
                i += 1
            start = leading[0].span.line if leading else entry.first
            if self._blank_before(out, previous, entry, source_line, start):
                out.append("")
            depth = entry.depth + 1 if entry.closes else entry.depth
            for j, comment in enumerate(leading):
                if j and comment.span.line > leading[j - 1].span.line + 1:
                    out.append("")  # a blank line between comments is kept
                out.append(INDENT * depth + comment.text)
            if leading and self._gap(leading[-1].span.line, entry.first) and not entry.closes:
                out.append("")
            out.append(INDENT * entry.depth + entry.text)
            previous = entry
            source_line = entry.last
        for comment in comments[i:]:
            if previous is not None and comment.span.line == previous.last and trailing(comment):
                out[-1] += "  " + comment.text
            else:
                if previous is not None and self._gap(source_line, comment.span.line):
                    out.append("")
                out.append(comment.text)
            source_line = comment.span.line
        return "\n".join(out) + "\n" if out else ""

    def _gap(self, after: int, before: int) -> bool:
        """Whether the source has a blank line strictly between two lines."""
        return any(not self.lines[k - 1].strip() for k in range(after + 1, before))

    def _blank_before(self, out, previous, entry, source_line, start) -> bool:
        if previous is None or not out or out[-1].endswith("{") or entry.closes:
            return False
        if entry.depth == 0 and (entry.block or previous.closes or previous.block):
            return True
        return self._gap(source_line, start)


def _choice(item: ast.Choice) -> str:
    domain = "" if item.domain is None else f" : {expression(item.domain)}"
    if domain == " : color":
        domain = " : colour"
    return f"{item.name.text}{domain} ~ {call(item.prior)}"


def _setting(item: ast.Setting) -> str:
    return f"{item.key.text} = {expression(item.value)}"


def _rule(rule) -> str:
    return call(rule) if isinstance(rule, ast.Call) else rule.text


def _modifiers(modifiers) -> list[str]:
    texts = []
    for m in modifiers:
        text = f"{m.keyword} {expression(m.value)}"
        if m.axis is not None:
            text += f" about {expression(m.axis)}"
        texts.append(text)
    return texts


def _join(head: str, parts: list[str]) -> str:
    return " ".join([head, *parts])
