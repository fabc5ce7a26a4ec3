"""The syntax tree of a ``.scn`` model: one frozen dataclass per grammar rule.

Nodes record what was written and where (``span``), nothing more: names are not resolved and
numbers are not checked here, so that the compiler can report every semantic error of a file
with its position. Class names match the grammar's rule names in CamelCase.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import Span


@dataclass(frozen=True)
class Ident:
    """A name being declared or used as a label (a class, a parameter, a setting key)."""

    text: str
    span: Span


# ---- expressions ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Number:
    value: float
    span: Span


@dataclass(frozen=True)
class Name:
    """A reference to a constant, a parameter, a palette colour or ``pi``."""

    id: str
    span: Span


@dataclass(frozen=True)
class Keyword:
    """``name = value`` inside a call, as in ``gamma(2, rate=3)``."""

    name: Ident
    value: Expr
    span: Span


@dataclass(frozen=True)
class Labelled:
    """``label: weight`` inside a call, as in ``categorical(red: 0.5, blue: 0.5)``."""

    label: Ident
    weight: Expr
    span: Span


@dataclass(frozen=True)
class Call:
    """``f(args)``: a distribution, domain, primitive, function or ``rgb``; which one is the
    compiler's business, since the syntax is the same."""

    func: Ident
    args: tuple[Expr | Keyword | Labelled, ...]
    span: Span


@dataclass(frozen=True)
class BinOp:
    op: str  # one of + - * / ^
    left: Expr
    right: Expr
    span: Span


@dataclass(frozen=True)
class UnaryOp:
    op: str  # + or -
    operand: Expr
    span: Span


@dataclass(frozen=True)
class String:
    """Text in double quotes: a file name (an import, a mesh)."""

    value: str
    span: Span


@dataclass(frozen=True)
class Tuple:
    """``(a, b, ...)`` with at least two items: a position, a light direction, a colour."""

    items: tuple[Expr, ...]
    span: Span


Expr = Number | Name | Call | BinOp | UnaryOp | String
Value = Expr | Tuple


# ---- statements -----------------------------------------------------------------------------


@dataclass(frozen=True)
class ColourDef:
    name: Ident
    value: Value
    span: Span


@dataclass(frozen=True)
class Colours:
    """``colours { ... }``, or ``colours NAME { ... }``, which also names the set: a palette."""

    name: Ident | None
    definitions: tuple[ColourDef, ...]
    span: Span


@dataclass(frozen=True)
class Import:
    """``import "file.scn"`` (``names`` None: everything) or ``from "file.scn" import a, b``."""

    path: String
    names: tuple[Ident, ...] | None
    span: Span


@dataclass(frozen=True)
class Let:
    name: Ident
    value: Expr
    span: Span


@dataclass(frozen=True)
class Choice:
    """``name : domain ~ prior``; without a domain it is a class's ``count ~ poisson(rate)``."""

    name: Ident
    domain: Name | Call | None
    prior: Call
    span: Span


@dataclass(frozen=True)
class Modifier:
    """``at (x, y)``, ``rotate angle [about (x, y, z)]``, ``scale s``, ``colour c`` or
    ``size s`` after a geometry's primitive, a pose, a footprint or the ground."""

    keyword: str  # at, rotate, scale, colour (``color`` is read as ``colour``) or size
    value: Value
    span: Span
    axis: Tuple | None = None  # rotate's ``about (x, y, z)``


@dataclass(frozen=True)
class Geometry:
    """One posed, coloured primitive of a class; a class with several is a composite object.

    Modifiers are kept in the order written, so that the compiler can point at a repeated one.
    """

    primitive: Call
    modifiers: tuple[Modifier, ...]
    span: Span


@dataclass(frozen=True)
class Pose:
    """``pose at (x, y) rotate a``: where the whole object is; its parts are posed in it."""

    modifiers: tuple[Modifier, ...]
    span: Span


@dataclass(frozen=True)
class Footprint:
    """``footprint rectangle(w, d)`` or ``footprint circle(r)``, in place of the derived one."""

    shape: Call
    modifiers: tuple[Modifier, ...]
    span: Span


@dataclass(frozen=True)
class Floating:
    """``floating``: the class's objects do not rest on the ground."""

    span: Span


@dataclass(frozen=True)
class ClassDef:
    name: Ident
    body: tuple[Choice | Let | Setting | Geometry | Pose | Footprint | Floating, ...]
    span: Span


@dataclass(frozen=True)
class StaticDef:
    """``static NAME { geometry ... }``: fixed parts every hypothesis renders."""

    name: Ident
    body: tuple[Geometry | Pose, ...]
    span: Span


@dataclass(frozen=True)
class Ground:
    """``ground colour c [size s]``: a flat square under the scene, its top at z = 0."""

    modifiers: tuple[Modifier, ...]
    span: Span


@dataclass(frozen=True)
class Change:
    """``change a.p <-> [k *] b.q``: a change of class between a and b carries p's value to
    q, and back; with a factor k, a.p = k b.q."""

    first_class: Ident
    first: Ident
    factor: Number | None
    second_class: Ident
    second: Ident
    span: Span


@dataclass(frozen=True)
class Constraint:
    """``constraint no_overlap`` or ``constraint max_objects(n)``."""

    rule: Ident | Call
    span: Span


@dataclass(frozen=True)
class Region:
    """``region box(...)``, ``region polygon(...)`` or ``region cameras[(names)]``."""

    kind: Ident
    args: tuple  # expressions, tuples and strings; () when written without parentheses
    span: Span


@dataclass(frozen=True)
class Setting:
    """``key = value``: in a ``render``, ``inference`` or ``sensor`` block, or ``jump_weights``."""

    key: Ident
    value: Value
    span: Span


@dataclass(frozen=True)
class Likelihood:
    """``likelihood NAME`` or ``likelihood NAME(option = value, ...)``."""

    rule: Ident | Call
    span: Span


@dataclass(frozen=True)
class Sensor:
    kind: Ident
    body: tuple[Likelihood | Setting | Choice, ...]
    span: Span


@dataclass(frozen=True)
class Render:
    """``render { ... }``: settings, and choices of the latent lighting parameters."""

    settings: tuple[Setting | Choice, ...]
    span: Span


@dataclass(frozen=True)
class Step:
    """``step name = v`` or ``step owner.name = v``: a parameter's proposal scale."""

    owner: Ident | None  # a class or sensor; None means every parameter with that name
    name: Ident
    value: Expr
    span: Span


@dataclass(frozen=True)
class JumpWeights:
    weights: tuple[Setting, ...]
    span: Span


@dataclass(frozen=True)
class Inference:
    body: tuple[Setting | Step | JumpWeights, ...]
    span: Span


Statement = (
    Import
    | Colours
    | Let
    | ClassDef
    | StaticDef
    | Ground
    | Change
    | Constraint
    | Sensor
    | Render
    | Inference
)


@dataclass(frozen=True)
class Comment:
    """A ``# ...`` comment, kept so that ``sppl fmt`` can put it back."""

    text: str
    span: Span


@dataclass(frozen=True)
class Program:
    statements: tuple[Statement, ...]
    path: str
    source: str
    comments: tuple[Comment, ...] = ()
