"""Syntax tree to ``Model``: the semantic checks of a model file, then the model itself.

The compiler walks the statements in order, so a top-level name (a constant, a colour, a
palette, an imported name) must be defined before it is used; inside a class, parameters and
derived quantities may come in any order, as long as none depends on itself. It reports every
error it finds rather than stopping at the first: a file's errors are raised together as one
``ModelErrors``, sorted by position. Nothing here knows any concrete class: an object class is
whatever its declarations say, and its geometry is compiled to a function from parameter
values to posed parts. Imports are in ``imports.py``, geometry and scenery in ``shapes.py``,
the ordering of a class's declarations in ``order.py``; priors and domains in ``priors.py``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelError, ModelErrors, Span, SpplError
from ..model.domains import Finite, Interval, Periodic, Positive, Real
from ..model.geometry import Part
from ..model.jumps import jump_names, reverse_pairs
from ..model.types import (
    LIGHTING,
    MAX_SCENE_OBJECTS,
    RENDER_GROUP,
    SCENE_TAIL,
    InferenceSettings,
    Model,
    ObjectClass,
    Parameter,
    RenderSettings,
    Sensor,
    Values,
    probability_of_more_objects,
)
from . import ast
from .expressions import (
    BUILTINS,
    CATEGORICAL_PARAMETER,
    COLOUR,
    COLOUR_PARAMETER,
    CONSTANT,
    DERIVED,
    PALETTE,
    RGB,
    Expressions,
    Scope,
    Symbol,
    did_you_mean,
    failure_reason,
    known,
    names_in,
)
from .imports import ImportsMixin, Loader, read_source
from .order import cycle_path, parameters_read, strongly_connected, topological
from .parser import parse
from .priors import Priors, parameter_kind
from .shapes import Matrix, ShapesMixin, modifier_of, posed

DEFAULT_PATH = "<string>"


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


# ---- what the language knows by name ------------------------------------------------------

_CONSTRAINTS = ("no_overlap", "max_objects")
_SENSOR_KINDS = ("image", "depth")
_RENDER_KEYS = ("background", "ambient", "light", "intensity", "sheen", "gain", "red", "blue",
                "shadows")
# Lighting parameters whose values must be at least 0, and those of them also at most 1 (a
# share of the light, a grey level).
_NONNEGATIVE = ("ambient", "intensity", "sheen", "gain", "red", "blue")
_UNIT = ("ambient", "sheen")
_INFERENCE_KEYS = ("p_jump", "data_birth", "data_birth_spread", "adapt", "anneal", "anneal_from",
                   "tries", "tempered", "tempered_from")
_CLASS_SETTINGS = ("count", "max_count")


# ---- what is compiled ---------------------------------------------------------------------


@dataclass
class _Owner:
    """A class or sensor being compiled; its parameters get their steps once all are known."""

    name: str
    parameters: list[Parameter] = field(default_factory=list)
    declared: set[str] = field(default_factory=set)  # parameter names, compiled or not


@dataclass(eq=False)
class _PendingClass(_Owner):
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
    pairs: dict[int, tuple[_PendingClass, dict[str, str]]] = field(default_factory=dict)
    scales: dict[int, dict[str, float]] = field(default_factory=dict)
    # Where each paired parameter was paired, for repeated pairings.
    paired_at: dict[tuple[int, str], Span] = field(default_factory=dict)


@dataclass
class _PendingSensor(_Owner):
    likelihood: str | None = None
    options: dict[str, float] = field(default_factory=dict)


def _domain_within(domain, low: float, high: float) -> bool:
    """Whether every value of a (continuous) domain lies in [low, high]."""
    if isinstance(domain, Positive):
        return low <= 0.0 and high == math.inf
    if isinstance(domain, (Interval, Periodic)):
        return low <= domain.low and domain.high <= high
    return False


def _scale_free(domain) -> bool:
    """Domains that a positive factor maps onto themselves."""
    return isinstance(domain, (Real, Positive))


# ---- the compiler -------------------------------------------------------------------------


class _Compiler(ImportsMixin, ShapesMixin):
    def __init__(self, program: ast.Program, loader: Loader, main: bool = True) -> None:
        self.program = program
        self.loader = loader
        self.main = main
        self.errors: list[ModelError] = []
        self.imported_errors: list[ModelError] = []
        self.expr = Expressions(self.error)
        self.priors = Priors(self.expr, self.error, program.path, program.source)
        self.symbols: dict[str, Symbol] = dict(BUILTINS)
        self.palette: dict[str, RGB] = {}
        self.classes: dict[str, _PendingClass] = {}
        self.sensors: dict[str, _PendingSensor] = {}
        self.no_overlap = False
        self.max_objects: int | None = None
        self.region = None  # sppl.model.region.Region or CamerasRegion
        self.region_span: Span | None = None
        self.restrictions: dict[str, object] = {}
        self.static_parts: list[Part] = []
        self.statics: dict[str, Span] = {}
        self.ground: Span | None = None
        self.render: dict[str, object] = {}
        # The render block's latent lighting parameters, stepped like a sensor's noise.
        self.lighting = _PendingSensor(RENDER_GROUP)
        self.inference: dict[str, object] = {}
        self.jump_weights: dict[str, float] = {}
        self.steps: list[ast.Step] = []
        self.changes: list[ast.Change] = []
        self.imported_at: dict[int, Span] = {}  # id(class): the import that brought it
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

    def check(self) -> None:
        """Compile every statement, collecting errors."""
        self._declare_globals()
        handlers = {
            ast.Import: lambda node: None,  # done by _declare_globals
            ast.Colours: self._colours,
            ast.Let: self._let,
            ast.ClassDef: self._class,
            ast.StaticDef: self._static,
            ast.Ground: self._ground,
            ast.Change: self.changes.append,
            ast.Constraint: self._constraint,
            ast.Region: self._region,
            ast.Sensor: self._sensor,
            ast.Render: self._render,
            ast.Inference: self._inference,
        }
        for statement in self.program.statements:
            handlers[type(statement)](statement)
        if self.main and not self.classes:
            self.error(
                "the model declares no object classes",
                Span(1, 1),
                "add one with `class NAME { ... }`",
            )
        self._apply_steps()
        self._resolve_changes()
        self._restrict()
        if self.main and not self.errors and not self.imported_errors:
            self._check_scene_size()

    def _check_scene_size(self) -> None:
        """Refuse a prior that puts real mass on more objects than a run can handle: the
        sampler would grind through such scenes, and `sppl simulate` would try to build one."""
        if self.max_objects is not None and self.max_objects <= MAX_SCENE_OBJECTS:
            return
        classes = [c for c in self.classes.values() if c.rate is not None or c.count is not None]
        compiled = [ObjectClass(c.name, float(c.count) if c.count is not None else c.rate, (),
                                lambda values: (), count=c.count, max_count=c.max_count)
                    for c in classes]
        p = probability_of_more_objects(compiled, MAX_SCENE_OBJECTS)
        if p <= SCENE_TAIL:
            return
        # Pointed at the count that contributes most (in this file, or its import).
        worst = max(classes, key=lambda c: c.count if c.count is not None else c.rate)
        span = (worst.count_span if worst.program is self.program and worst.count_span
                else self.imported_at.get(id(worst), worst.span))
        expected = sum(c.count if c.count is not None else c.rate for c in classes)
        self.error(
            f"the prior puts probability {p:.3g} on scenes of more than {MAX_SCENE_OBJECTS} "
            f"objects (class `{worst.name}` alone expects {worst.count or worst.rate:g}, all "
            f"classes {expected:g}), more than a run can sample",
            span,
            "lower the rate, or bound the count with `max_count = n` in the class or "
            f"`constraint max_objects(n)` with n at most {MAX_SCENE_OBJECTS}",
        )

    def compile(self) -> Model:
        self.check()
        if self.errors or self.imported_errors:
            raise ModelErrors(self.errors + self.imported_errors)
        return self._model()

    def _model(self) -> Model:
        classes = tuple(self._object_class(c) for c in self.classes.values())
        sensors = {
            kind: Sensor(kind, s.likelihood, tuple(s.parameters), dict(s.options))
            for kind, s in self.sensors.items()
        }
        path = self.program.path
        return Model(
            classes=classes,
            sensors=sensors,
            inference=InferenceSettings(**self.inference, **self._jump_weights()),
            render=RenderSettings(**self.render, latent=tuple(self.lighting.parameters)),
            colours=dict(self.palette),
            no_overlap=self.no_overlap,
            max_objects=self.max_objects,
            region=self.region,
            static_parts=tuple(self.static_parts),
            path=None if path == DEFAULT_PATH else Path(path),
            source=self.program.source,
        )

    def _object_class(self, c: _PendingClass) -> ObjectClass:
        correspondences = {
            other.name: dict(pairs)
            for other, pairs in c.pairs.values()
            if self.classes.get(other.name) is other
        }
        scales = {
            other.name: dict(c.scales[key])
            for key, (other, _) in c.pairs.items()
            if key in c.scales and self.classes.get(other.name) is other
        }
        rate = float(c.count) if c.count is not None else c.rate
        return ObjectClass(
            c.name,
            rate,
            tuple(c.parameters),
            _build(c),
            footprint_fn=c.footprint,
            position=c.position,
            count=c.count,
            max_count=c.max_count,
            floating=c.floating,
            correspondences=correspondences,
            correspondence_scales=scales,
            restriction=self.restrictions.get(c.name),
        )

    def _global_scope(self, where: str = "a model setting") -> Scope:
        return Scope(self.symbols, parameters_allowed=False, where=where)

    def _folder(self) -> Path:
        path = self.program.path
        return Path(".") if path == DEFAULT_PATH else Path(path).parent

    # ---- imports, constants and colours ----

    def _declare_globals(self) -> None:
        """Register every import, constant, colour and palette before compiling any statement.

        Then a name used before its definition can be told apart from one never defined.
        """
        for statement in self.program.statements:
            if isinstance(statement, ast.Import):
                self._import(statement)
            elif isinstance(statement, ast.Let):
                self._declare(statement.name, Symbol(statement.name.text, CONSTANT, statement.span))
            elif isinstance(statement, ast.Colours):
                for definition in statement.definitions:
                    symbol = Symbol(definition.name.text, COLOUR, definition.span)
                    self._declare(definition.name, symbol)
                if statement.name is not None:
                    names = tuple(d.name.text for d in statement.definitions)
                    symbol = Symbol(statement.name.text, PALETTE, statement.span, names)
                    self._declare(statement.name, symbol)

    def _declare(self, name: ast.Ident, symbol: Symbol) -> bool:
        if not self._check_new_global(name):
            return False
        self.symbols[name.text] = symbol
        return True

    def _check_new_global(self, name: ast.Ident, suffix: str = "") -> bool:
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

    def _defines(self, name: ast.Ident, span: Span) -> bool:
        """Whether this statement is the definition registered for ``name`` (not a duplicate)."""
        symbol = self.symbols.get(name.text)
        return symbol is not None and symbol.span == span and symbol.imported is None

    def _colours(self, node: ast.Colours) -> None:
        for definition in node.definitions:
            value = self.expr.colour(definition.value, self._global_scope())
            if value is not None and self._defines(definition.name, definition.span):
                self.symbols[definition.name.text] = replace(
                    self.symbols[definition.name.text], value=value
                )
                self.palette[definition.name.text] = value

    def _let(self, node: ast.Let) -> None:
        value = self.expr.constant(node.value, self._global_scope())
        if value is not None and self._defines(node.name, node.span):
            self.symbols[node.name.text] = replace(self.symbols[node.name.text], value=value)

    # ---- classes ----

    def _add_class(
        self, pending: _PendingClass, name: ast.Ident, span: Span, imported: bool = False
    ) -> bool:
        existing = self.classes.get(name.text)
        if existing is pending:
            return False  # the same class, imported twice
        if existing is not None:
            if existing.program is not self.program:
                where = f"imported on line {self._import_line(existing)}"
            else:
                where = f"defined on line {existing.span.line}"
            self.error(f"class `{name.text}` is already {where}", name.span)
            return False
        self.classes[name.text] = pending
        if imported:
            self.imported_at[id(pending)] = span
        return True

    def _import_line(self, pending: _PendingClass) -> int:
        span = self.imported_at.get(id(pending))
        return span.line if span else 0

    def _class(self, node: ast.ClassDef) -> None:
        name = node.name.text
        pending = _PendingClass(name, span=node.span, program=self.program)
        self._add_class(pending, node.name, node.span)
        local, own = self._declare_locals(node.body, pending, f"class `{name}`")
        scope = Scope(local, parameters_allowed=True, where="geometry")
        self._compile_locals(own, local, pending, parameters_allowed=True)
        self._counts(node, pending, local)

        poses = [item for item in node.body if isinstance(item, ast.Pose)]
        for extra in poses[1:]:
            self.error(f"`pose` is already given on line {poses[0].span.line}", extra.span)
        pose: Matrix | None = np.eye(4)
        if poses:
            pose = self._transform(poses[0].modifiers, "pose", scope)
        footprints = [item for item in node.body if isinstance(item, ast.Footprint)]
        for extra in footprints[1:]:
            self.error(
                f"`footprint` is already given on line {footprints[0].span.line}", extra.span
            )
        if footprints and pose is not None:
            pending.footprint = self._footprint(footprints[0], pose, scope)
        floats = [item for item in node.body if isinstance(item, ast.Floating)]
        for extra in floats[1:]:
            self.error(f"`floating` is already given on line {floats[0].span.line}", extra.span)
        pending.floating = bool(floats)
        for item in node.body:
            if isinstance(item, ast.Geometry):
                part = self._geometry(item, scope)
                if part is not None and pose is not None:
                    pending.parts.append((item.span, posed(pose, part)))
        pending.position = _ground_position(node, pending)
        if not any(isinstance(item, ast.Geometry) for item in node.body):
            self.error(
                f"class `{name}` has no geometry",
                node.name.span,
                "add a line such as `geometry box(1, 1, 1) colour red`",
            )

    def _declare_locals(
        self, body, pending: _Owner, owner: str
    ) -> tuple[dict[str, Symbol], dict[str, ast.Choice | ast.Let]]:
        """The symbols visible inside a class or sensor (the globals, its parameters and
        derived quantities), and the declarations of its own names."""
        local = dict(self.symbols)
        own: dict[str, ast.Choice | ast.Let] = {}
        for item in body:
            # `count` is a class's number of objects, not a parameter; a choice with no
            # domain is reported where it is compiled.
            if isinstance(item, ast.Choice):
                if item.domain is None or item.name.text == "count":
                    continue
                kind = parameter_kind(item.domain)
                what = "parameter"
            elif isinstance(item, ast.Let):
                kind, what = DERIVED, "derived quantity"
            else:
                continue
            name = item.name
            if what == "parameter":
                pending.declared.add(name.text)
            if name.text in own:
                self.error(
                    f"{owner} already has a parameter or derived quantity `{name.text}` "
                    f"(line {own[name.text].span.line})",
                    name.span,
                )
                continue
            if not self._check_new_global(name, f"; a {what} needs a name of its own"):
                continue
            own[name.text] = item
            value = self.palette if kind == COLOUR_PARAMETER else None
            local[name.text] = Symbol(name.text, kind, item.span, value, ordered=False)
        return local, own

    def _compile_locals(
        self,
        own: dict[str, ast.Choice | ast.Let],
        local: dict[str, Symbol],
        pending: _Owner,
        parameters_allowed: bool,
    ) -> None:
        """Compile a class's (or sensor's) parameters and derived quantities in an order
        where each comes after what it uses, reporting any that depend on themselves."""
        deps = {
            name: list(
                dict.fromkeys(
                    n.id
                    for n in names_in(item.prior if isinstance(item, ast.Choice) else item.value)
                    if n.id in own and n.id != name
                )
            )
            if parameters_allowed
            else []
            for name, item in own.items()
        }
        broken = self._cycles(own, deps)
        order = topological(list(own), deps, broken)
        for name in order:
            item = own[name]
            if isinstance(item, ast.Let):
                scope = Scope(local, parameters_allowed=True, where="a derived quantity")
                value = self.expr.number(item.value, scope)
                local[name] = replace(local[name], value=value)
                continue
            if item.name.text == "count":
                continue
            reads = parameters_read(name, deps, own)
            where = "a prior" if parameters_allowed else "a noise prior"
            scope = Scope(local, parameters_allowed=parameters_allowed, where=where)
            parameter = self.priors.parameter(item, scope, reads)
            if parameter is None:
                continue
            pending.parameters.append(parameter)
            if isinstance(parameter.domain, Finite):
                local[name] = replace(local[name], labels=parameter.domain.values)

    def _cycles(self, own: Mapping[str, Any], deps: Mapping[str, list[str]]) -> set[str]:
        """Report each cycle of dependencies once; return the names on cycles."""
        index = {name: i for i, name in enumerate(own)}
        on_cycle: set[str] = set()
        for component in strongly_connected(list(own), deps):
            if len(component) < 2:
                continue
            on_cycle |= component
            first = min(component, key=index.__getitem__)
            path = cycle_path(first, deps, component)
            self.error(
                f"`{first}` depends on itself: {' -> '.join(path)}",
                own[first].name.span,
                "parameters and derived quantities must not depend on each other in a circle",
            )
        return on_cycle

    def _counts(self, node: ast.ClassDef, pending: _PendingClass, local) -> None:
        count: ast.Choice | ast.Setting | None = None
        for item in node.body:
            if isinstance(item, ast.Choice) and item.name.text == "count":
                if count is not None:
                    self.error(
                        f"`count` is already given on line {count.span.line}", item.name.span
                    )
                    continue
                count = item
                pending.count_span = item.span
                pending.rate = self._count(item, local)
            elif isinstance(item, ast.Choice) and item.domain is None:
                self._no_domain(item, "real")
            elif isinstance(item, ast.Setting):
                key = item.key.text
                if key not in _CLASS_SETTINGS:
                    self.error(
                        f"unknown class setting `{key}`",
                        item.key.span,
                        did_you_mean(key, _CLASS_SETTINGS) or known("settings", _CLASS_SETTINGS),
                    )
                    continue
                if key == "count" and count is not None:
                    self.error(
                        f"`count` is already given on line {count.span.line}", item.key.span
                    )
                    continue
                if key == "max_count" and not self._first(("class", pending.name, key), item):
                    continue
                n = self._whole(item.value, f"`{key}`")
                if key == "count":
                    count = item
                    pending.count_span = item.span
                    pending.count = n
                    pending.rate = None if n is None else float(n)
                else:
                    pending.max_count = n
        if count is None:
            self.error(
                f"class `{pending.name}` has no count",
                node.name.span,
                "add a line `count ~ poisson(rate)`",
            )
        elif pending.count is not None and pending.max_count is not None:
            self.error(
                "a fixed count needs no `max_count`",
                next(i.span for i in node.body if isinstance(i, ast.Setting)
                     and i.key.text == "max_count"),
            )

    def _whole(self, expr: ast.Value, what: str) -> int | None:
        value = self.expr.constant(expr, self._global_scope())
        if value is None:
            return None
        if value < 0 or value != int(value):
            self.error(f"{what} is a whole number of objects, got {value:g}", expr.span)
            return None
        return int(value)

    def _count(self, choice: ast.Choice, local: Mapping[str, Symbol]) -> float | None:
        call = choice.prior
        if choice.domain is not None:
            self.error(
                "`count` is the number of objects and takes no domain",
                choice.domain.span,
                "write `count ~ poisson(rate)`",
            )
            return None
        if call.func.text != "poisson":
            self.error(
                "the count of a class needs a poisson prior",
                call.span,
                "write `count ~ poisson(rate)`, or `count = n` for exactly n objects",
            )
            return None
        prior = self.priors.prior(call, Scope(local, where="a count"), colours=False)
        return None if prior is None else prior.rate

    # ---- constraints, changes, sensors, settings ----

    def _constraint(self, node: ast.Constraint) -> None:
        rule = node.rule
        ident = rule.func if isinstance(rule, ast.Call) else rule
        name = ident.text
        if name not in _CONSTRAINTS:
            self.error(
                f"unknown constraint `{name}`",
                ident.span,
                did_you_mean(name, _CONSTRAINTS) or known("constraints", _CONSTRAINTS),
            )
            return
        if not self._first(("constraint", name), ast.Setting(ident, ident, node.span)):
            return
        if name == "no_overlap":
            if isinstance(rule, ast.Call):
                self.error(
                    "`no_overlap` takes no arguments", rule.span, "write `constraint no_overlap`"
                )
                return
            self.no_overlap = True
            return
        if not isinstance(rule, ast.Call) or len(rule.args) != 1:
            self.error(
                "`max_objects` needs its bound: max_objects(n)",
                rule.span,
                "e.g. `constraint max_objects(10)`",
            )
            return
        arg = self.expr.positional(rule)
        if arg is not None:
            self.max_objects = self._whole(arg[0], "`max_objects`")

    def _region(self, node: ast.Region) -> None:
        from ..model import region as regions

        kind = node.kind.text
        if self.region_span is not None:
            self.error(f"the region is already given on line {self.region_span.line}",
                       node.span, "a model has one region; merge them into one polygon")
            return
        self.region_span = node.span
        if kind not in regions.KINDS:
            self.error(f"unknown region `{kind}`", node.kind.span,
                       did_you_mean(kind, regions.KINDS) or known("regions", regions.KINDS))
            return
        scope = self._global_scope(where="a region")
        try:
            if kind == "cameras":
                names = []
                for a in node.args:
                    if isinstance(a, ast.String | ast.Name):
                        names.append(a.value if isinstance(a, ast.String) else a.id)
                    else:
                        self.error("`cameras(...)` takes the names of frames", a.span,
                                   'e.g. `region cameras(left, "right")`')
                        return
                self.region = regions.CamerasRegion(tuple(names), self._where(node.span))
            elif kind == "box":
                if len(node.args) != 4 or any(
                        isinstance(a, ast.Tuple | ast.String) for a in node.args):
                    self.error("`box` takes four numbers: box(x_min, y_min, x_max, y_max)",
                               node.span)
                    return
                values = self.expr.constants(node.args, scope)
                if values is not None:
                    self.region = regions.box(*values)
            else:
                points = []
                for a in node.args:
                    if not isinstance(a, ast.Tuple) or len(a.items) != 2:
                        self.error("a polygon's corners are (x, y) pairs", a.span,
                                   "e.g. `region polygon((0, 0), (4, 0), (0, 3))`")
                        return
                    xy = self.expr.constants(a.items, scope)
                    if xy is None:
                        return
                    points.append(xy)
                self.region = regions.polygon(points)
        except regions.RegionError as error:
            self.error(str(error), node.span)

    def _where(self, span: Span) -> str:
        return f"{self.program.path}:{span.line}:{span.column}"

    def _restrict(self) -> None:
        """Each placed class's position prior restricted to a box or polygon region, with its
        normaliser (a camera region waits for the cameras: ``sppl.model.region.bind``)."""
        from ..model import region as regions

        if self.region is None or isinstance(self.region, regions.CamerasRegion):
            return
        for c in self.classes.values():
            if c.position is None:
                continue
            px, py = (_parameter(c, n) for n in c.position)
            try:
                self.restrictions[c.name] = regions.restrict(
                    self.region, c.position, px.prior, py.prior, c.name)
            except regions.RegionError as error:
                self.error(str(error), self.region_span)

    def _resolve_changes(self) -> None:
        for node in self.changes:
            first = self._change_side(node.first_class, node.first)
            second = self._change_side(node.second_class, node.second)
            if first is None or second is None:
                continue
            (a, p), (b, q) = first, second
            if a is b:
                self.error(
                    "a change of class is between two different classes", node.second_class.span
                )
                continue
            pa, pb = _parameter(a, p.text), _parameter(b, q.text)
            if pa is None or pb is None:
                continue  # it failed to compile, which was reported there
            factor = 1.0 if node.factor is None else node.factor.value
            if factor != 1.0 and not (factor > 0 and math.isfinite(factor)):
                self.error(f"a change's factor must be positive, got {factor:g}",
                           node.factor.span)
                continue
            if factor != 1.0 and not (pa.domain == pb.domain and _scale_free(pa.domain)):
                self.error(
                    f"`{a.name}.{p.text}` ({pa.domain.describe()}) and `{b.name}.{q.text}` "
                    f"({pb.domain.describe()}) cannot be paired with a factor",
                    node.factor.span,
                    "a scaled value stays in its domain only for two real or two positive "
                    "parameters",
                )
                continue
            if pa.domain != pb.domain:
                self.error(
                    f"`{a.name}.{p.text}` ({pa.domain.describe()}) and `{b.name}.{q.text}` "
                    f"({pb.domain.describe()}) have different domains",
                    node.second.span,
                    "a change carries a value as it is, so both need the same domain",
                )
                continue
            clash = False
            for owner, other, mine in ((a, b, p), (b, a, q)):
                where = owner.paired_at.get((id(other), mine.text))
                if where is not None:
                    self.error(
                        f"`{owner.name}.{mine.text}` is already paired with a parameter of "
                        f"`{other.name}` on line {where.line}",
                        mine.span,
                    )
                    clash = True
            if clash:
                continue
            for owner, other, mine, theirs, k in ((a, b, p, q, factor), (b, a, q, p, 1 / factor)):
                owner.paired_at[id(other), mine.text] = node.span
                owner.pairs.setdefault(id(other), (other, {}))[1][mine.text] = theirs.text
                if factor != 1.0:
                    owner.scales.setdefault(id(other), {})[mine.text] = k

    def _change_side(self, cls: ast.Ident, name: ast.Ident):
        pending = self.classes.get(cls.text)
        if pending is None:
            self.error(
                f"unknown class `{cls.text}`",
                cls.span,
                did_you_mean(cls.text, self.classes) or known("classes", self.classes),
            )
            return None
        if name.text not in pending.declared:
            self.error(
                f"class `{cls.text}` has no parameter `{name.text}`",
                name.span,
                did_you_mean(name.text, pending.declared)
                or known("parameters", sorted(pending.declared)),
            )
            return None
        return pending, name

    def _sensor(self, node: ast.Sensor) -> None:
        kind = node.kind.text
        if kind not in _SENSOR_KINDS:
            self.error(
                f"unknown sensor `{kind}`",
                node.kind.span,
                did_you_mean(kind, _SENSOR_KINDS) or known("sensors", _SENSOR_KINDS),
            )
        pending = _PendingSensor(kind)
        if kind in self.sensors:
            self.error(f"sensor `{kind}` is already defined", node.kind.span)
        elif kind in _SENSOR_KINDS:
            self.sensors[kind] = pending
        local, own = self._declare_locals(node.body, pending, f"sensor `{kind}`")
        likelihood: ast.Likelihood | None = None
        for item in node.body:
            if isinstance(item, ast.Likelihood):
                if likelihood is not None:
                    self.error(
                        f"the likelihood is already given on line {likelihood.span.line}", item.span
                    )
                    continue
                likelihood = item
            elif isinstance(item, ast.Setting):
                if item.key.text in pending.declared:
                    self.error(f"`{item.key.text}` is already a noise parameter", item.key.span)
                elif self._first(("sensor", kind, item.key.text), item):
                    value = self._option(item.value)
                    if value is not None:
                        pending.options[item.key.text] = value
            elif item.name.text == "count":
                self.error("a sensor has no `count`; counts belong to classes", item.name.span)
            elif item.domain is None:
                self._no_domain(item, "positive")
        self._compile_locals(own, local, pending, parameters_allowed=False)
        if likelihood is None:
            self.error(
                f"sensor `{kind}` has no likelihood",
                node.kind.span,
                "add a line such as `likelihood gaussian`",
            )
        else:
            self._likelihood(likelihood, pending, own, kind)

    def _likelihood(
        self, node: ast.Likelihood, pending: _PendingSensor, own: Mapping[str, Any], kind: str
    ) -> None:
        """Look the likelihood up (third-party ones included), take its options, and check
        that the sensor gives a prior for each of its noise parameters and no others."""
        from ..model.likelihoods import available_likelihoods, get_likelihood

        rule = node.rule
        ident = rule.func if isinstance(rule, ast.Call) else rule
        name = ident.text
        pending.likelihood = name
        if isinstance(rule, ast.Call):
            for arg in rule.args:
                if not isinstance(arg, ast.Keyword):
                    self.error(
                        "the options of a likelihood are named: NAME(option = value, ...)",
                        arg.span,
                    )
                    return
                key = arg.name.text
                if key in pending.options:
                    self.error(f"the option `{key}` is given twice", arg.name.span)
                    continue
                value = self._option(arg.value)
                if value is not None:
                    pending.options[key] = value
        try:
            names = available_likelihoods()
        except SpplError as error:
            self.error(error.message, ident.span)
            return
        if name not in names:
            self.error(
                f"unknown likelihood `{name}`",
                ident.span,
                did_you_mean(name, names) or known("likelihoods", names),
            )
            return
        try:
            likelihood = get_likelihood(name, pending.options)
        except (SpplError, TypeError) as error:
            message = error.message if isinstance(error, SpplError) else str(error)
            self.error(f"the {name} likelihood cannot be made: {message}", node.span)
            return
        wanted = tuple(getattr(likelihood, "noise_parameters", ()) or ())
        fixed = getattr(likelihood, "fixed", {})
        supports = getattr(likelihood, "noise_supports", {})
        for p in pending.parameters:
            if p.name in supports:
                low, high = supports[p.name]
                if not _domain_within(p.domain, low, high):
                    what = "a probability" if high == 1.0 else "positive"
                    self.error(
                        f"`{p.name}` of the {name} likelihood is {what}, in "
                        f"[{low:g}, {high:g}], but its domain is {p.domain.describe()}",
                        own[p.name].name.span,
                        f"declare it as `{p.name} : interval(0, 1) ~ beta(1, 20)`"
                        if high == 1.0 else f"declare it as `{p.name} : positive`",
                    )
        for noise in wanted:
            if noise not in pending.declared:
                self.error(
                    f"the {name} likelihood needs a prior for its noise parameter `{noise}`",
                    node.span,
                    f"add a line such as `{noise} : interval(0, 1) ~ beta(1, 20)` to sensor "
                    f"`{kind}`" if supports.get(noise, (0, 0))[1] == 1.0 else
                    f"add a line such as `{noise} : positive ~ gamma(2, 0.1)` to sensor `{kind}`",
                )
        for declared, item in own.items():
            if isinstance(item, ast.Choice) and declared in fixed:
                self.error(
                    f"`{declared}` is both fixed by an option and given a prior",
                    item.name.span,
                    f"drop the option `{declared} = ...` or the prior",
                )
            elif isinstance(item, ast.Choice) and declared not in wanted:
                self.error(
                    f"the {name} likelihood has no noise parameter `{declared}`",
                    item.name.span,
                    did_you_mean(declared, wanted) or known("noise parameters", wanted),
                )

    def _option(self, value):
        """A likelihood option's value: a number, or a word such as `laplace` (a bare name
        that is not a constant of the model)."""
        if isinstance(value, ast.Name) and value.id not in self.symbols:
            return value.id
        return self.expr.constant(value, self._global_scope())

    def _no_domain(self, item: ast.Choice, example: str) -> None:
        name = item.name.text
        self.error(f"`{name}` has no domain", item.name.span,
                   f"write `{name} : DOMAIN ~ PRIOR`, e.g. `: {example}`")

    def _first(self, key: tuple[str, ...], node: ast.Setting | ast.Step) -> bool:
        """Whether this is the first time a setting is given, reporting a repeat if not."""
        if key in self.seen:
            label = node.key if isinstance(node, ast.Setting) else node.name
            self.error(f"`{label.text}` is already set on line {self.seen[key].line}", label.span)
            return False
        self.seen[key] = node.span
        return True

    def _render(self, node: ast.Render) -> None:
        scope = self._global_scope()
        choices = []
        for item in node.settings:
            if not isinstance(item, ast.Choice):
                continue
            name = item.name.text
            if name not in LIGHTING:
                self.error(
                    f"the render block has no lighting parameter `{name}`",
                    item.name.span,
                    did_you_mean(name, LIGHTING) or known("lighting parameters", LIGHTING),
                )
            elif item.domain is None:
                self._no_domain(item, "positive")
            elif name in self.lighting.declared:
                self.error(f"the lighting parameter `{name}` is already declared", item.name.span)
            else:
                choices.append(item)
        before = len(self.lighting.parameters)
        local, own = self._declare_locals(choices, self.lighting, "the render block")
        self._compile_locals(own, local, self.lighting, parameters_allowed=False)
        for parameter, item in zip(self.lighting.parameters[before:], choices):
            self._lighting_domain(parameter, item)
        for setting in node.settings:
            if isinstance(setting, ast.Choice):
                continue
            key = setting.key.text
            if key not in _RENDER_KEYS:
                self._unknown_setting(setting, "render", _RENDER_KEYS)
            elif key in self.lighting.declared:
                self.error(f"`{key}` is already a latent lighting parameter", setting.key.span,
                           "give it either a value or a prior, not both")
            elif self._first(("render", key), setting):
                value = self._render_value(key, setting.value, scope)
                if value is not None:
                    self.render[key] = value

    def _lighting_domain(self, parameter, item: ast.Choice) -> None:
        """A latent lighting parameter's domain must hold only values that light a scene."""
        name, domain = parameter.name, parameter.domain
        if isinstance(domain, Finite):
            self.error(f"the lighting parameter `{name}` is a number, not a categorical choice",
                       item.domain.span)
        elif name in _UNIT and (domain.contains(-1e-12) or domain.contains(1.0 + 1e-12)):
            self.error(f"`{name}` lies in [0, 1]: its domain must too", item.domain.span,
                       f"write `{name} : interval(0, 1) ~ ...`")
        elif name in _NONNEGATIVE and domain.contains(-1e-12):
            self.error(f"`{name}` is not negative: its domain must not hold negative values",
                       item.domain.span, f"write `{name} : positive ~ ...`")

    def _render_value(self, key: str, value: ast.Value, scope: Scope) -> object | None:
        if key == "background":
            return self.expr.colour(value, scope)
        if key == "shadows":
            if isinstance(value, ast.Name) and value.id in ("true", "false"):
                return value.id == "true"
            self.error("`shadows` is `true` or `false`", value.span)
            return None
        if key in _NONNEGATIVE:
            number = self.expr.constant(value, scope)
            if number is not None and not (0.0 <= number <= (1.0 if key in _UNIT else math.inf)):
                limits = "[0, 1]" if key in _UNIT else "[0, inf)"
                self.error(f"`{key}` lies in {limits}, got {number:g}", value.span)
                return None
            return number
        if not isinstance(value, ast.Tuple) or len(value.items) != 3:
            self.error("`light` is a direction (x, y, z)", value.span)
            return None
        light = self.expr.constants(value.items, scope)
        if light is not None and not any(light):
            self.error("`light` must not be (0, 0, 0)", value.span)
            return None
        return None if light is None else tuple(light)

    def _inference(self, node: ast.Inference) -> None:
        scope = self._global_scope()
        for item in node.body:
            if isinstance(item, ast.Step):
                self.steps.append(item)
            elif isinstance(item, ast.JumpWeights):
                self._jump_weight_settings(item, scope)
            elif item.key.text not in _INFERENCE_KEYS:
                hint = did_you_mean(item.key.text, _INFERENCE_KEYS + ("step", "jump_weights"))
                self._unknown_setting(item, "inference", _INFERENCE_KEYS, hint)
            elif self._first(("inference", item.key.text), item):
                key = item.key.text
                value = self.expr.constant(item.value, scope)
                if value is None:
                    continue
                if key == "p_jump" and not 0.0 <= value <= 1.0:
                    self.error(f"`p_jump` is a probability, got {value:g}", item.value.span)
                elif key == "data_birth" and not 0.0 <= value < 1.0:
                    self.error(
                        f"`data_birth` is a probability below 1, got {value:g}",
                        item.value.span,
                        "with 1 a birth could never land where nothing is unexplained",
                    )
                elif key == "data_birth_spread" and not value > 0.0:
                    self.error(
                        f"`data_birth_spread` must be positive, got {value:g}", item.value.span
                    )
                elif key in ("adapt", "anneal") and not (value >= 0 and value == int(value)):
                    self.error(f"`{key}` is a number of sweeps, got {value:g}", item.value.span,
                               "0 switches it off")
                elif key == "tries" and not (value >= 1 and value == int(value)):
                    self.error(f"`tries` is a number of candidates, at least 1, got {value:g}",
                               item.value.span)
                elif key == "tempered" and not (value >= 1 and value == int(value)):
                    self.error(f"`tempered` is a number of chains, at least 1, got {value:g}",
                               item.value.span, "1 switches tempering off")
                elif key in ("anneal_from", "tempered_from") and not 0.0 < value <= 1.0:
                    self.error(f"`{key}` is a power of the likelihood in (0, 1], got "
                               f"{value:g}", item.value.span)
                else:
                    if key in ("adapt", "anneal", "tries", "tempered"):
                        value = int(value)
                    self.inference[key] = value

    def _jump_weight_settings(self, node: ast.JumpWeights, scope: Scope) -> None:
        # The registered jumps, the built-in ones (sppl.infer.jumps) and any a user added.
        names = jump_names()
        for setting in node.weights:
            key = setting.key.text
            if key not in names:
                self.error(
                    f"unknown jump `{key}`",
                    setting.key.span,
                    did_you_mean(key, names) or known("jumps", names),
                )
            elif self._first(("jump_weights", key), setting):
                weight = self.expr.constant(setting.value, scope)
                if weight is not None and weight < 0:
                    self.error(
                        f"a jump weight must not be negative, got {weight:g}", setting.value.span
                    )
                elif weight is not None:
                    self.jump_weights[key] = weight
        weights = {**InferenceSettings().jump_weights, **self.jump_weights}
        # Each pair is each other's reverse: one without the other cannot be balanced.
        unpaired = next(((a, b) for a, b in reverse_pairs()
                         if (weights.get(a, 0.0) > 0) != (weights.get(b, 0.0) > 0)), None)
        if unpaired is not None:
            self.error(f"{unpaired[0]} and {unpaired[1]} need both a positive weight or both "
                       "zero", node.span)
        elif not any(weights.values()):
            self.error("at least one jump weight must be positive", node.span)

    def _jump_weights(self) -> dict[str, Mapping[str, float]]:
        if not self.jump_weights:
            return {}
        return {"jump_weights": {**InferenceSettings().jump_weights, **self.jump_weights}}

    def _unknown_setting(
        self, setting: ast.Setting, block: str, keys: tuple[str, ...], hint: str | None = None
    ) -> None:
        self.error(
            f"unknown {block} setting `{setting.key.text}`",
            setting.key.span,
            hint or did_you_mean(setting.key.text, keys) or known("settings", keys),
        )

    # ---- steps ----

    def _apply_steps(self) -> None:
        """Give each parameter its proposal scale: `step owner.name` wins over `step name`."""
        owners: dict[str, list[_Owner]] = {}
        for owner in [*self.classes.values(), *self.sensors.values(), self.lighting]:
            owners.setdefault(owner.name, []).append(owner)
        scales: dict[tuple[str | None, str], float] = {}  # (owner or None, parameter): step
        for step in self.steps:
            owner = None if step.owner is None else step.owner.text
            if not self._step_target_exists(step, owners):
                continue
            if not self._first(("step", owner or "", step.name.text), step):
                continue
            value = self.expr.constant(step.value, self._global_scope())
            if value is not None and value <= 0:
                self.error(f"a step must be positive, got {value:g}", step.value.span)
            elif value is not None:
                scales[owner, step.name.text] = value
        for owner in [*self.classes.values(), *self.sensors.values(), self.lighting]:
            owner.parameters = [
                replace(p, proposal_scale=_scale(scales, owner.name, p.name))
                if _steppable(p) and _scale(scales, owner.name, p.name) is not None
                else p
                for p in owner.parameters
            ]

    def _step_target_exists(self, step: ast.Step, owners: dict[str, list[_Owner]]) -> bool:
        name = step.name.text
        if step.owner is None:
            candidates = [o for group in owners.values() for o in group]
        elif step.owner.text in owners:
            candidates = owners[step.owner.text]
        else:
            self.error(
                f"no class or sensor is called `{step.owner.text}`",
                step.owner.span,
                did_you_mean(step.owner.text, owners),
            )
            return False
        declared = {n for o in candidates for n in o.declared}
        if name not in declared:
            where = "" if step.owner is None else f" in `{step.owner.text}`"
            self.error(
                f"no parameter `{name}`{where} to step",
                step.name.span,
                did_you_mean(name, declared),
            )
            return False
        matches = [p for o in candidates for p in o.parameters if p.name == name]
        if not matches:
            return False  # it failed to compile, which was reported there
        if not any(_steppable(p) for p in matches):
            self.error(
                f"`{name}` is categorical; steps are for numeric parameters", step.name.span
            )
            return False
        return True




# ---- helpers --------------------------------------------------------------------------------


def _steppable(p: Parameter) -> bool:
    return not isinstance(p.domain, Finite)


def _scale(scales: Mapping[tuple[str | None, str], float], owner: str, name: str) -> float | None:
    if (owner, name) in scales:
        return scales[owner, name]
    return scales.get((None, name))


def _parameter(pending: _Owner, name: str) -> Parameter | None:
    return next((p for p in pending.parameters if p.name == name), None)


def _ground_position(node: ast.ClassDef, pending: _PendingClass) -> tuple[str, str] | None:
    """The two parameters that place the object on the ground, when its pose (or, without
    one, its first geometry line) says ``at (x, y ...)`` with two independent real-valued
    parameters of the class that no other parameter depends on: data-driven birth proposals
    draw these near unexplained observations instead of from their prior."""
    reals = {p.name for p in pending.parameters if isinstance(p.domain, Real) and not p.depends_on}
    source = next((i for i in node.body if isinstance(i, ast.Pose)), None) or next(
        (i for i in node.body if isinstance(i, ast.Geometry)), None
    )
    if source is None:
        return None
    at = modifier_of(source.modifiers, "at")
    if at is None or not isinstance(at.value, ast.Tuple):
        return None
    a, b = at.value.items[:2]
    if not (isinstance(a, ast.Name) and isinstance(b, ast.Name) and a.id != b.id):
        return None
    if not {a.id, b.id} <= reals:
        return None
    # Births redraw the position after the other parameters: none may depend on it.
    reads = {p.name: set(p.depends_on) for p in pending.parameters}
    for p in pending.parameters:
        seen, stack = set(), list(p.depends_on)
        while stack:
            d = stack.pop()
            if d in (a.id, b.id):
                return None
            if d not in seen:
                seen.add(d)
                stack.extend(reads.get(d, ()))
    return (a.id, b.id)


def _build(pending: _PendingClass) -> Callable[[Values], tuple[Part, ...]]:
    parts = tuple(pending.parts)
    name = pending.name
    program = pending.program

    def build(values: Values) -> tuple[Part, ...]:
        built: list[Part] = []
        for span, part in parts:
            try:
                built.extend(part(values))
            except (ArithmeticError, ValueError) as e:
                # An expression such as sqrt(x - 1) can fail for some parameter values.
                raise ModelError(
                    f"the geometry of class `{name}` cannot be evaluated for "
                    f"{dict(values)}: {failure_reason(e)}",
                    path=program.path,
                    span=span,
                    source=program.source,
                ) from e
        return tuple(built)

    return build


__all__ = ["compile_model", "load_model", "COLOUR", "CATEGORICAL_PARAMETER"]
