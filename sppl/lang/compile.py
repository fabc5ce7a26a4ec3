"""Syntax tree to ``Model``: the semantic checks of a model file, then the model itself.

The compiler walks the statements in order, so a name must be defined before it is used, and
reports every error it finds rather than stopping at the first: a file's errors are raised
together as one ``ModelErrors``, sorted by position. Nothing here knows any concrete class:
an object class is whatever its declarations say, and its geometry is compiled to a function
from parameter values to posed parts.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..domains import Real
from ..errors import ModelError, ModelErrors, Span
from ..geometry import Part, rotation_z, scaling, translation
from ..model import (
    InferenceSettings,
    Model,
    ObjectClass,
    Parameter,
    RenderSettings,
    Sensor,
    Values,
)
from . import ast
from .expressions import (
    BUILTINS,
    COLOUR,
    CONSTANT,
    RGB,
    Colour,
    Expressions,
    Numeric,
    Scope,
    Symbol,
    as_function,
    did_you_mean,
    failure_reason,
    known,
)
from .parser import parse
from .priors import Priors, parameter_kind

DEFAULT_PATH = "<string>"


def load_model(path: str | Path) -> Model:
    """Read, check and compile a ``.scn`` file; raise ``ModelError`` if anything is wrong."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as e:
        raise ModelError(f"cannot read the model file: {e.strerror}", path=path) from None
    except UnicodeDecodeError:
        raise ModelError("the model file is not UTF-8 text", path=path) from None
    return compile_model(text, path)


def compile_model(text: str, path: str | Path = DEFAULT_PATH) -> Model:
    """Check and compile the text of a model file; ``path`` is used in error messages."""
    return _Compiler(parse(text, str(path))).compile()


# ---- what the language knows by name ------------------------------------------------------

# How each primitive's arguments scale its unit shape (see sppl/geometry.py for the shapes).
_PRIMITIVES: dict[str, tuple[tuple[str, ...], Callable[..., tuple[float, float, float]]]] = {
    "box": (("width", "depth", "height"), lambda w, d, h: (w, d, h)),
    "cylinder": (("radius", "height"), lambda r, h: (r, r, h)),
    "cone": (("radius", "height"), lambda r, h: (r, r, h)),
    "sphere": (("radius",), lambda r: (r, r, r)),
}

_CONSTRAINTS = ("no_overlap",)
_SENSOR_KINDS = ("image", "depth")
_RENDER_KEYS = ("background", "ambient", "light")
_INFERENCE_KEYS = ("p_jump", "data_birth", "data_birth_spread")
_JUMPS = ("birth", "death", "change")


# ---- the compiler -------------------------------------------------------------------------


@dataclass
class _Owner:
    """A class or sensor being compiled; its parameters get their steps once all are known."""

    name: str
    parameters: list[Parameter] = field(default_factory=list)
    declared: set[str] = field(default_factory=set)  # parameter names, compiled or not


@dataclass
class _PendingClass(_Owner):
    rate: float | None = None
    parts: list[tuple[Span, Callable[[Values], Part]]] = field(default_factory=list)
    span: Span | None = None  # of the class's first definition
    position: tuple[str, str] | None = None


@dataclass
class _PendingSensor(_Owner):
    likelihood: str | None = None
    options: dict[str, float] = field(default_factory=dict)


class _Compiler:
    def __init__(self, program: ast.Program) -> None:
        self.program = program
        self.errors: list[ModelError] = []
        self.expr = Expressions(self.error)
        self.priors = Priors(self.expr, self.error, program.source)
        self.symbols: dict[str, Symbol] = dict(BUILTINS)
        self.palette: dict[str, RGB] = {}
        self.classes: dict[str, _PendingClass] = {}
        self.sensors: dict[str, _PendingSensor] = {}
        self.no_overlap = False
        self.render: dict[str, object] = {}
        self.inference: dict[str, object] = {}
        self.jump_weights: dict[str, float] = {}
        self.steps: list[ast.Step] = []
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

    def compile(self) -> Model:
        self._declare_globals()
        handlers = {
            ast.Colours: self._colours,
            ast.Let: self._let,
            ast.ClassDef: self._class,
            ast.Constraint: self._constraint,
            ast.Sensor: self._sensor,
            ast.Render: self._render,
            ast.Inference: self._inference,
        }
        for statement in self.program.statements:
            handlers[type(statement)](statement)
        if not any(isinstance(s, ast.ClassDef) for s in self.program.statements):
            self.error(
                "the model declares no object classes",
                Span(1, 1),
                "add one with `class NAME { ... }`",
            )
        self._apply_steps()
        if self.errors:
            raise ModelErrors(self.errors)
        return self._model()

    def _model(self) -> Model:
        classes = tuple(
            ObjectClass(
                c.name, c.rate, tuple(c.parameters), _build(c, self.program), position=c.position
            )
            for c in self.classes.values()
        )
        sensors = {
            kind: Sensor(kind, s.likelihood, tuple(s.parameters), dict(s.options))
            for kind, s in self.sensors.items()
        }
        path = self.program.path
        return Model(
            classes=classes,
            sensors=sensors,
            inference=InferenceSettings(**self.inference, **self._jump_weights()),
            render=RenderSettings(**self.render),
            colours=dict(self.palette),
            no_overlap=self.no_overlap,
            path=None if path == DEFAULT_PATH else Path(path),
            source=self.program.source,
        )

    def _global_scope(self) -> Scope:
        return Scope(self.symbols, parameters_allowed=False, where="a model setting")

    # ---- constants and colours ----

    def _declare_globals(self) -> None:
        """Register every constant and palette colour before compiling any statement.

        Then a name used before its definition can be told apart from one never defined.
        """
        for statement in self.program.statements:
            if isinstance(statement, ast.Let):
                self._declare(statement.name, CONSTANT, statement.span)
            elif isinstance(statement, ast.Colours):
                for definition in statement.definitions:
                    self._declare(definition.name, COLOUR, definition.span)

    def _declare(self, name: ast.Ident, kind: str, span: Span) -> None:
        if not self._check_new_global(name):
            return
        self.symbols[name.text] = Symbol(name.text, kind, span)

    def _check_new_global(self, name: ast.Ident, suffix: str = "") -> bool:
        """Whether ``name`` may be defined, reporting a clash with a global name if not."""
        existing = self.symbols.get(name.text)
        if existing is None:
            return True
        if existing.span.line == 0:
            self.error(f"`{name.text}` is built in and cannot be redefined{suffix}", name.span)
        else:
            self.error(
                f"`{name.text}` is already defined on line {existing.span.line}{suffix}", name.span
            )
        return False

    def _defines(self, name: ast.Ident, span: Span) -> bool:
        """Whether this statement is the definition registered for ``name`` (not a duplicate)."""
        symbol = self.symbols.get(name.text)
        return symbol is not None and symbol.span == span

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

    def _class(self, node: ast.ClassDef) -> None:
        name = node.name.text
        pending = _PendingClass(name, span=node.span)
        if name in self.classes:
            self.error(
                f"class `{name}` is already defined on line {self.classes[name].span.line}",
                node.name.span,
            )
        else:
            self.classes[name] = pending
        local = self._declare_parameters(node.body, pending, f"class `{name}`")
        count: ast.Choice | None = None
        for item in node.body:
            if isinstance(item, ast.Geometry):
                part = self._geometry(item, local)
                if part is not None:
                    pending.parts.append((item.span, part))
            elif item.name.text == "count":
                if count is not None:
                    self.error(
                        f"`count` is already given on line {count.span.line}", item.name.span
                    )
                count = item
                pending.rate = self._count(item, local)
            else:
                self._add_parameter(pending, item, local)
        pending.position = _ground_position(node, pending)
        if count is None:
            self.error(
                f"class `{name}` has no count", node.name.span, "add a line `count ~ poisson(rate)`"
            )
        if not any(isinstance(item, ast.Geometry) for item in node.body):
            self.error(
                f"class `{name}` has no geometry",
                node.name.span,
                "add a line such as `geometry box(1, 1, 1) colour red`",
            )

    def _declare_parameters(self, body, pending: _Owner, owner: str) -> dict[str, Symbol]:
        """The symbols visible inside a class or sensor: the globals and its parameters."""
        local = dict(self.symbols)
        own: dict[str, Span] = {}
        for item in body:
            # `count` is a class's number of objects, not a parameter; a choice with no
            # domain is reported where it is compiled.
            if not isinstance(item, ast.Choice) or item.domain is None or item.name.text == "count":
                continue
            name = item.name
            pending.declared.add(name.text)
            if name.text in own:
                self.error(
                    f"{owner} already has a parameter `{name.text}` (line {own[name.text].line})",
                    name.span,
                )
                continue
            if not self._check_new_global(name, "; a parameter needs a name of its own"):
                continue
            own[name.text] = item.span
            local[name.text] = Symbol(
                name.text, parameter_kind(item.domain), item.span, self.palette
            )
        return local

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
                "write `count ~ poisson(rate)`",
            )
            return None
        prior = self.priors.prior(call, Scope(local, where="a prior"), colours=False)
        return None if prior is None else prior.rate

    def _add_parameter(
        self, owner: _Owner, choice: ast.Choice, local: Mapping[str, Symbol]
    ) -> None:
        if choice.domain is None:
            self.error(
                f"`{choice.name.text}` has no domain",
                choice.name.span,
                f"write `{choice.name.text} : DOMAIN ~ PRIOR`, e.g. `: real`",
            )
            return
        parameter = self.priors.parameter(choice, local)
        # A duplicate or clashing name was reported where it was declared.
        if parameter is not None and local[parameter.name].span == choice.span:
            owner.parameters.append(parameter)

    # ---- geometry ----

    def _geometry(
        self, node: ast.Geometry, local: Mapping[str, Symbol]
    ) -> Callable[[Values], Part] | None:
        """A function from parameter values to the posed part, or None after reporting."""
        scope = Scope(local, parameters_allowed=True, where="geometry")
        sizes = self._primitive(node.primitive, scope)
        modifiers: dict[str, ast.Modifier] = {}
        for modifier in node.modifiers:
            if modifier.keyword in modifiers:
                self.error(f"`{modifier.keyword}` is given twice", modifier.span)
            else:
                modifiers[modifier.keyword] = modifier
        position = self._position(modifiers.get("at"), scope)
        angle: Numeric | None = 0.0
        if "rotate" in modifiers:
            angle = self.expr.number(modifiers["rotate"].value, scope)
        colour: Colour | None = None
        if "colour" in modifiers:
            colour = self.expr.colour(modifiers["colour"].value, scope)
        else:
            self.error(
                "a geometry line needs a colour",
                node.span,
                "add `colour NAME` or `colour rgb(r, g, b)`",
            )
        if sizes is None or position is None or angle is None or colour is None:
            return None
        return _part(node.primitive.func.text, sizes, position, angle, colour)

    def _primitive(self, call: ast.Call, scope: Scope) -> list[Numeric] | None:
        name = call.func.text
        if name not in _PRIMITIVES:
            self.error(
                f"unknown primitive `{name}`",
                call.func.span,
                did_you_mean(name, _PRIMITIVES) or known("primitives", _PRIMITIVES),
            )
            return None
        arguments, _ = _PRIMITIVES[name]
        signature = f"{name}({', '.join(arguments)})"
        bound = self.expr.bind(call, arguments, signature)
        if bound is None:
            return None
        if len(bound) != len(arguments):
            self.expr.arity_error(call, signature)
            return None
        sizes = [self.expr.number(bound[a], scope) for a in arguments]
        return None if any(s is None for s in sizes) else sizes

    def _position(self, modifier: ast.Modifier | None, scope: Scope) -> list[Numeric] | None:
        if modifier is None:
            return [0.0, 0.0, 0.0]
        items = modifier.value.items
        if len(items) > 3:
            self.error(
                f"`at` takes (x, y) or (x, y, z), got {len(items)} values", modifier.value.span
            )
            return None
        # Objects rest on the ground unless the model lifts them.
        position = [self.expr.number(e, scope) for e in items] + [0.0] * (3 - len(items))
        return None if any(p is None for p in position) else position

    # ---- constraints, sensors, settings ----

    def _constraint(self, node: ast.Constraint) -> None:
        if node.name.text not in _CONSTRAINTS:
            self.error(
                f"unknown constraint `{node.name.text}`",
                node.name.span,
                did_you_mean(node.name.text, _CONSTRAINTS) or known("constraints", _CONSTRAINTS),
            )
            return
        self.no_overlap = True

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
        local = self._declare_parameters(node.body, pending, f"sensor `{kind}`")
        likelihood: ast.Likelihood | None = None
        for item in node.body:
            if isinstance(item, ast.Likelihood):
                if likelihood is not None:
                    self.error(
                        f"the likelihood is already given on line {likelihood.span.line}", item.span
                    )
                likelihood = item
                # Likelihoods are looked up by name when the sampler starts; third-party ones
                # register there, so the name cannot be checked here.
                pending.likelihood = item.name.text
            elif isinstance(item, ast.Setting):
                if item.key.text in pending.declared:
                    self.error(f"`{item.key.text}` is already a noise parameter", item.key.span)
                elif self._first(("sensor", kind, item.key.text), item):
                    value = self.expr.constant(item.value, self._global_scope())
                    if value is not None:
                        pending.options[item.key.text] = value
            elif item.name.text == "count":
                self.error("a sensor has no `count`; counts belong to classes", item.name.span)
            else:
                self._add_parameter(pending, item, local)
        if likelihood is None:
            self.error(
                f"sensor `{kind}` has no likelihood",
                node.kind.span,
                "add a line such as `likelihood gaussian`",
            )

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
        for setting in node.settings:
            key = setting.key.text
            if key not in _RENDER_KEYS:
                self._unknown_setting(setting, "render", _RENDER_KEYS)
            elif self._first(("render", key), setting):
                value = self._render_value(key, setting.value, scope)
                if value is not None:
                    self.render[key] = value

    def _render_value(self, key: str, value: ast.Value, scope: Scope) -> object | None:
        if key == "background":
            return self.expr.colour(value, scope)
        if key == "ambient":
            ambient = self.expr.constant(value, scope)
            if ambient is not None and not 0.0 <= ambient <= 1.0:
                self.error(f"`ambient` lies in [0, 1], got {ambient:g}", value.span)
                return None
            return ambient
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
                    self.error(f"`data_birth_spread` must be positive, got {value:g}", item.value.span)
                else:
                    self.inference[key] = value

    def _jump_weight_settings(self, node: ast.JumpWeights, scope: Scope) -> None:
        for setting in node.weights:
            key = setting.key.text
            if key not in _JUMPS:
                self.error(
                    f"unknown jump `{key}`",
                    setting.key.span,
                    did_you_mean(key, _JUMPS) or known("jumps", _JUMPS),
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
        # Birth and death are each other's reverse: one without the other cannot be balanced.
        if (weights["birth"] > 0) != (weights["death"] > 0):
            self.error("birth and death need both a positive weight or both zero", node.span)
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
        for owner in [*self.classes.values(), *self.sensors.values()]:
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
        for owner in [*self.classes.values(), *self.sensors.values()]:
            owner.parameters = [
                replace(p, proposal_scale=_scale(scales, owner.name, p.name))
                if p.continuous and _scale(scales, owner.name, p.name) is not None
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
        if not any(p.continuous for p in matches):
            self.error(
                f"`{name}` is categorical; steps are for continuous parameters", step.name.span
            )
            return False
        return True


# ---- building objects -----------------------------------------------------------------------


def _scale(scales: Mapping[tuple[str | None, str], float], owner: str, name: str) -> float | None:
    if (owner, name) in scales:
        return scales[owner, name]
    return scales.get((None, name))


def _part(
    primitive: str,
    sizes: list[Numeric],
    position: list[Numeric],
    angle: Numeric,
    colour: Colour,
) -> Callable[[Values], Part]:
    _, scale = _PRIMITIVES[primitive]
    sizes_fn = [as_function(s) for s in sizes]
    x, y, z = (as_function(p) for p in position)
    angle_fn = as_function(angle)
    colour_fn = colour if callable(colour) else (lambda values: colour)

    def part(values: Values) -> Part:
        matrix = (
            translation(x(values), y(values), z(values))
            @ rotation_z(angle_fn(values))
            @ scaling(*scale(*(s(values) for s in sizes_fn)))
        )
        return Part(primitive, matrix, tuple(float(c) for c in colour_fn(values)))

    return part


def _ground_position(node: ast.ClassDef, pending: _PendingClass) -> tuple[str, str] | None:
    """The two parameters that place the object on the ground, when its first geometry line
    says ``at (x, y ...)`` with two real-valued parameters of the class: data-driven birth
    proposals draw these near unexplained observations instead of from their prior."""
    reals = {p.name for p in pending.parameters if isinstance(p.domain, Real)}
    for item in node.body:
        if isinstance(item, ast.Geometry):
            for m in item.modifiers:
                if m.keyword == "at" and isinstance(m.value, ast.Tuple):
                    a, b = m.value.items[:2]
                    if isinstance(a, ast.Name) and isinstance(b, ast.Name) and a.id != b.id:
                        if {a.id, b.id} <= reals:
                            return (a.id, b.id)
            return None
    return None


def _build(pending: _PendingClass, program: ast.Program) -> Callable[[Values], tuple[Part, ...]]:
    parts = tuple(pending.parts)
    name = pending.name

    def build(values: Values) -> tuple[Part, ...]:
        built = []
        for span, part in parts:
            try:
                built.append(part(values))
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
