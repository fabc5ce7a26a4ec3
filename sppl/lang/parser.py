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

# The comments of the parse in progress, collected by the lexer (lark drops ignored tokens).
_comments: list[Token] = []


def _collect_comment(token: Token) -> Token:
    _comments.append(token)
    return token


@cache
def _parser() -> Lark:
    # Built once per process: LALR gives linear-time parsing and the contextual lexer, which is
    # what lets most keywords double as parameter names.
    return Lark.open_from_package(
        "sppl",
        "scn.lark",
        ("lang",),
        parser="lalr",
        propagate_positions=True,
        lexer_callbacks={"COMMENT": _collect_comment},
    )


def parse(text: str, path: str = "<string>") -> ast.Program:
    """Parse the text of a model file into its syntax tree; raise ``ModelError`` if malformed."""
    # Keywords found to be names are capitalised in the text the parser reads (no keyword
    # starts with a capital), which keeps every position, and get their text back in the AST.
    names: dict[int, str] = {}
    working = text
    while True:
        _comments.clear()
        try:
            tree = _parser().parse(working, on_error=partial(_keyword_as_name, working))
            break
        except UnexpectedInput as e:
            position = _keyword_before(e, working)
            if position is None:
                raise _unfinished(e, working, text, str(path)) or _syntax_error(
                    e, text, str(path)
                ) from None
            word = _WORD.match(working, position).group(0)
            names[position] = word
            working = working[:position] + word[0].upper() + working[position + 1 :]
    statements = _ToAst(names).transform(tree).children
    comments = tuple(
        ast.Comment(str(t), Span(t.line, t.column, t.end_line, t.end_column)) for t in _comments
    )
    return ast.Program(tuple(statements), str(path), text, comments)


_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


_WORD_BEFORE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\s|#[^\n]*)*$")


def _keyword_before(e: UnexpectedInput, text: str) -> int | None:
    """Where a keyword that should have been a name starts, or None.

    The contextual lexer reads a keyword wherever the parser may take it, so a parameter
    called `size` right after a geometry line is read as the start of a `size` modifier, and
    the error only shows at the `:` after it. No keyword is ever followed by `:`, `~` or `=`,
    so a keyword just before one of these is a name; the file is parsed again reading it so.
    """
    if not isinstance(e, UnexpectedToken) or str(e.token) not in (":", "~", "="):
        return None
    match = _WORD_BEFORE.search(text, 0, e.token.start_pos)
    if match is None or not _is_keyword_text(match.group(1)):
        return None
    return match.start(1)


# Keywords that start a statement: one read as a name just before a syntax error most likely
# follows a statement left unfinished (`let a = 2 +` on the line before `class`).
_STATEMENT_KEYWORDS = frozenset(
    "import from colours colors let class static ground change constraint sensor render "
    "inference".split()
)


def _unfinished(e: UnexpectedInput, working: str, text: str, path: str) -> ModelError | None:
    """The error at a statement keyword that the lexer took for a name, or None.

    After an operator the lexer reads any word as a name, so a statement left unfinished
    only fails at the word after the next statement's keyword; the error belongs at the
    keyword, with what the parser expected just before it.
    """
    if not isinstance(e, UnexpectedToken) or e.token.type == "$END":
        return None
    match = _WORD_BEFORE.search(working, 0, e.token.start_pos)
    if match is None or match.group(1) not in _STATEMENT_KEYWORDS:
        return None
    start = match.start(1)
    try:
        _parser().parse(working[:start])
    except UnexpectedToken as before:
        if before.token.type != "$END":
            return None
        expected = _describe_expected(_expected_terminals(before))
    except UnexpectedInput:
        return None
    else:
        return None
    line = working.count("\n", 0, start) + 1
    column = start - (working.rfind("\n", 0, start) + 1) + 1
    message = f"unexpected `{match.group(1)}`; expected {expected}"
    return ModelError(message, path=path, span=Span(line, column), source=text)


@cache
def _keywords() -> frozenset[str]:
    return frozenset(
        t.pattern.value
        for t in _parser().terminals
        if isinstance(t.pattern, PatternStr) and t.pattern.value.isidentifier()
    )


def _is_keyword_text(word: str) -> bool:
    return word in _keywords()


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
_DESCRIPTIONS = {
    "NAME": "a name",
    "NUMBER": "a number",
    "STRING": 'a file name in double quotes ("...")',
    "$END": "the end of the file",
}
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
        terminals = terminals - _EXPRESSION_STARTS - {"STRING"}
        words.append("an expression")
    texts = [_pattern(t) for t in terminals]
    # The American spellings are accepted everywhere the British ones are: list those only.
    texts = [p for p in texts if p not in ("color", "colors")]
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
    if token.type == "STRING":
        return f"text {token}"
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

    def __init__(self, names: dict[int, str]) -> None:
        super().__init__()
        self.names = names  # start offset: text of a keyword read as a name

    def _text(self, token: Token) -> str:
        return self.names.get(token.start_pos, str(token))

    def ident(self, meta, children):
        (token,) = children
        return ast.Ident(self._text(token), _token_span(token))

    def name(self, meta, children):
        (token,) = children
        return ast.Name(self._text(token), _token_span(token))

    def number(self, meta, children):
        (token,) = children
        return ast.Number(float(token), _token_span(token))

    add, sub, mul, div, pow = (_binary(op) for op in "+-*/^")
    neg, pos = _unary("-"), _unary("+")

    def string(self, meta, children):
        (token,) = children
        return ast.String(str(token)[1:-1], _token_span(token))

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
        name, *definitions = children
        return ast.Colours(name, tuple(definitions), _span(meta))

    def import_all(self, meta, children):
        return ast.Import(children[0], None, _span(meta))

    def import_from(self, meta, children):
        path, *names = children
        return ast.Import(path, tuple(names), _span(meta))

    def let(self, meta, children):
        return ast.Let(*children, _span(meta))

    def choice(self, meta, children):
        return ast.Choice(*children, _span(meta))

    def at(self, meta, children):
        return ast.Modifier("at", children[0], _span(meta))

    def rotate(self, meta, children):
        angle, axis = children
        return ast.Modifier("rotate", angle, _span(meta), axis)

    def scale(self, meta, children):
        return ast.Modifier("scale", children[0], _span(meta))

    def colour(self, meta, children):
        return ast.Modifier("colour", children[0], _span(meta))

    def size(self, meta, children):
        return ast.Modifier("size", children[0], _span(meta))

    def geometry(self, meta, children):
        primitive, *modifiers = children
        return ast.Geometry(primitive, tuple(modifiers), _span(meta))

    def pose(self, meta, children):
        return ast.Pose(tuple(children), _span(meta))

    def footprint(self, meta, children):
        shape, *modifiers = children
        return ast.Footprint(shape, tuple(modifiers), _span(meta))

    def floating(self, meta, children):
        return ast.Floating(_span(meta))

    def class_def(self, meta, children):
        name, *body = children
        return ast.ClassDef(name, tuple(body), _span(meta))

    def static_def(self, meta, children):
        name, *body = children
        return ast.StaticDef(name, tuple(body), _span(meta))

    def ground(self, meta, children):
        return ast.Ground(tuple(children), _span(meta))

    def change(self, meta, children):
        return ast.Change(*children, _span(meta))

    def constraint(self, meta, children):
        return ast.Constraint(children[0], _span(meta))

    def region(self, meta, children):
        kind, *args = children
        return ast.Region(kind, tuple(a for a in args if a is not None), _span(meta))

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
