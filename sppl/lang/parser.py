"""Text to syntax tree: the lark parser for ``scn.lark`` and its error messages.

``parse`` either returns an ``ast.Program`` or raises a ``ModelError`` that names the file,
line and column, shows the line with a caret and says in words what was expected there; no
lark exception escapes.
"""

from __future__ import annotations

import re
from functools import cache, partial

from lark import Lark, Token, Transformer, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken
from lark.lexer import PatternStr

from ..errors import ModelError, Span
from . import ast


@cache
def _parser() -> Lark:
    # Built once per process: LALR gives linear-time parsing and the contextual lexer, which is
    # what lets most keywords double as parameter names.
    return Lark.open_from_package(
        "sppl", "scn.lark", ("lang",), parser="lalr", propagate_positions=True
    )


def parse(text: str, path: str = "<string>") -> ast.Program:
    """Parse the text of a model file into its syntax tree; raise ``ModelError`` if malformed."""
    try:
        tree = _parser().parse(text, on_error=partial(_keyword_as_name, text))
    except UnexpectedInput as e:
        raise _syntax_error(e, text, str(path)) from None
    statements = _ToAst().transform(tree).children
    return ast.Program(tuple(statements), str(path), text)


# What follows a name that starts a declaration or setting: `x : ...`, `x ~ ...`, `x = ...`.
_DECLARATION_FOLLOWS = re.compile(r"(?:\s|#[^\n]*)*[:~=]")


def _keyword_as_name(text: str, e: UnexpectedInput) -> bool:
    """Retry a keyword the parser cannot take here as a plain name, e.g. a parameter `colour`.

    LALR merges the lookahead sets of similar states, so the contextual lexer sometimes reads a
    keyword where only a name can follow (after `x ~ normal(0, 1)` a new line may start with a
    parameter called `colour`). Such a name always starts a declaration or a setting; any
    other keyword out of place is a real mistake, such as a missing `}` before `class`, whose
    message is better left as it is.
    """
    if not isinstance(e, UnexpectedToken) or not _is_keyword(e.token.type):
        return False
    if not _DECLARATION_FOLLOWS.match(text, e.token.end_pos):
        return False
    # Ask first: a failed feed would leave the parser half-reduced, and its state is what
    # the error message describes.
    if "NAME" not in e.interactive_parser.accepts():
        return False
    e.interactive_parser.feed_token(Token.new_borrow_pos("NAME", e.token, e.token))
    return True


def _is_keyword(terminal: str) -> bool:
    pattern = _pattern(terminal)
    return pattern is not None and pattern.isidentifier()


def _pattern(terminal: str) -> str | None:
    """The literal text of a keyword or punctuation terminal, or None for NAME, NUMBER, $END."""
    try:
        pattern = _parser().get_terminal(terminal).pattern
    except KeyError:
        return None
    return pattern.value if isinstance(pattern, PatternStr) else None


# ---- error messages -------------------------------------------------------------------------

_OPERATORS = {"+", "-", "*", "/", "^", "**"}
_DESCRIPTIONS = {"NAME": "a name", "NUMBER": "a number", "$END": "the end of the file"}
_EXPRESSION_STARTS = {"NUMBER", "NAME", "LPAR", "PLUS", "MINUS"}


def _syntax_error(e: UnexpectedInput, text: str, path: str) -> ModelError:
    expected = _describe_expected(_expected_terminals(e))
    if isinstance(e, UnexpectedToken) and e.token.type == "$END":
        # lark places the end-of-input token at the start of the last token; just after that
        # token is where the missing text belongs.
        line = e.token.end_line or 1
        column = e.token.end_column or 1
        message = "the file ends too early"
    elif isinstance(e, UnexpectedToken):
        line, column = e.line, e.column
        message = f"unexpected {_describe_token(e.token)}"
    elif isinstance(e, UnexpectedCharacters):
        line, column = e.line, e.column
        message = f"unexpected character `{text[e.pos_in_stream]}`"
    else:
        line, column = max(e.line, 1), max(e.column, 1)
        message = "syntax error"
    if expected:
        message += f"; expected {expected}"
    return ModelError(message, path=path, span=Span(line, column), source=text)


def _expected_terminals(e: UnexpectedInput) -> set[str]:
    # The interactive parser simulates each candidate token, which is exact; the `expected`
    # set lark attaches is the LALR state's, which can list tokens that cannot follow here.
    parser = getattr(e, "interactive_parser", None)
    if parser is not None:
        try:
            return set(parser.accepts())
        except UnexpectedInput:
            pass
    return set(getattr(e, "expected", None) or getattr(e, "allowed", None) or ())


def _describe_expected(terminals: set[str]) -> str:
    words = []
    if "NUMBER" in terminals:
        # Where a number may start, so may any expression: say that once rather than listing
        # `(`, `-`, a name and a number.
        terminals = terminals - _EXPRESSION_STARTS
        words.append("an expression")
    texts = [_pattern(t) for t in terminals]
    symbols = sorted(f"`{p}`" for p in texts if p and p not in _OPERATORS)
    if any(p in _OPERATORS for p in texts):
        symbols.append("an operator")
    choices = symbols + [d for t, d in _DESCRIPTIONS.items() if t in terminals] + words
    if len(choices) <= 1:
        return "".join(choices)
    return ", ".join(choices[:-1]) + " or " + choices[-1]


def _describe_token(token: Token) -> str:
    if token.type == "NAME":
        return f"name `{token}`"
    if token.type == "NUMBER":
        return f"number `{token}`"
    return f"`{token}`"


# ---- parse tree to AST ----------------------------------------------------------------------


def _span(meta) -> Span:
    if getattr(meta, "empty", True):
        return Span(1, 1)
    return Span(meta.line, meta.column, meta.end_line, meta.end_column)


def _token_span(token: Token) -> Span:
    return Span(token.line, token.column, token.end_line, token.end_column)


def _binary(op: str):
    def build(self, meta, children):
        left, right = children
        return ast.BinOp(op, left, right, _span(meta))

    return build


def _unary(op: str):
    def build(self, meta, children):
        (operand,) = children
        return ast.UnaryOp(op, operand, _span(meta))

    return build


@v_args(meta=True)
class _ToAst(Transformer):
    """Builds the frozen AST bottom-up; each method is named after the grammar rule it builds."""

    def ident(self, meta, children):
        (token,) = children
        return ast.Ident(str(token), _token_span(token))

    def name(self, meta, children):
        (token,) = children
        return ast.Name(str(token), _token_span(token))

    def number(self, meta, children):
        (token,) = children
        return ast.Number(float(token), _token_span(token))

    add, sub, mul, div, pow = (_binary(op) for op in "+-*/^")
    neg, pos = _unary("-"), _unary("+")

    def tuple(self, meta, children):
        return ast.Tuple(tuple(children), _span(meta))

    def call(self, meta, children):
        func, *args = children
        # `[a ("," a)*]` leaves a single None placeholder when there are no arguments.
        return ast.Call(func, tuple(a for a in args if a is not None), _span(meta))

    def keyword(self, meta, children):
        return ast.Keyword(*children, _span(meta))

    def labelled(self, meta, children):
        return ast.Labelled(*children, _span(meta))

    def colour_def(self, meta, children):
        return ast.ColourDef(*children, _span(meta))

    def colours(self, meta, children):
        return ast.Colours(tuple(children), _span(meta))

    def let(self, meta, children):
        return ast.Let(*children, _span(meta))

    def choice(self, meta, children):
        return ast.Choice(*children, _span(meta))

    def at(self, meta, children):
        return ast.Modifier("at", children[0], _span(meta))

    def rotate(self, meta, children):
        return ast.Modifier("rotate", children[0], _span(meta))

    def colour(self, meta, children):
        return ast.Modifier("colour", children[0], _span(meta))

    def geometry(self, meta, children):
        primitive, *modifiers = children
        return ast.Geometry(primitive, tuple(modifiers), _span(meta))

    def class_def(self, meta, children):
        name, *body = children
        return ast.ClassDef(name, tuple(body), _span(meta))

    def constraint(self, meta, children):
        return ast.Constraint(children[0], _span(meta))

    def setting(self, meta, children):
        return ast.Setting(*children, _span(meta))

    def likelihood(self, meta, children):
        return ast.Likelihood(children[0], _span(meta))

    def sensor(self, meta, children):
        kind, *body = children
        return ast.Sensor(kind, tuple(body), _span(meta))

    def render(self, meta, children):
        return ast.Render(tuple(children), _span(meta))

    def step(self, meta, children):
        first, second, value = children
        owner, name = (None, first) if second is None else (first, second)
        return ast.Step(owner, name, value, _span(meta))

    def jump_weights(self, meta, children):
        return ast.JumpWeights(tuple(children), _span(meta))

    def inference(self, meta, children):
        return ast.Inference(tuple(children), _span(meta))
