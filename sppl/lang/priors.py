"""Declarations ``name : domain ~ prior``: the domain, the prior, and whether they fit.

A parameter's prior must put all its mass inside its domain, since the engine proposes inside
the domain and scores with the prior: ``normal`` on ``positive`` is an error, ``gamma`` on
``real`` is fine, ``uniform(lo, hi)`` must lie within an interval or periodic domain, whole
numbers (``poisson``, ``discrete_uniform``) belong to ``integer`` and only there, and
``categorical`` belongs to the finite domains (``colour``, whose values must be palette colours,
and ``categorical``, whose values are free labels).

A prior's arguments may use the object's other parameters and derived quantities
(``h : positive ~ uniform(r, 2 * r)``). Such a prior is made afresh from the object's values
each time it is used; what can be checked when the model is compiled (the family's support
against the domain, constant arguments) is, and the rest is checked each time the prior is
made, with an error that names the values that broke it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import ModelError, Span
from ..model.distributions import (
    Beta,
    Categorical,
    Dependent,
    DiscreteUniform,
    Distribution,
    Exponential,
    Gamma,
    LogNormal,
    Normal,
    Poisson,
    TruncatedNormal,
    Uniform,
)
from ..model.domains import Domain, Finite, Integer, Interval, Periodic, Positive, Real
from ..model.types import Parameter, Values
from . import ast
from .expressions import (
    CATEGORICAL_PARAMETER,
    COLOUR,
    COLOUR_PARAMETER,
    PALETTE,
    PARAMETER,
    Expressions,
    Report,
    Scope,
    as_function,
    did_you_mean,
    known,
)

INF = math.inf


@dataclass(frozen=True)
class _Spec:
    """A distribution the language names: its arguments, how to make it, what it needs."""

    arguments: tuple[str, ...]
    signature: str
    make: Callable[[Mapping[str, float]], Distribution]
    # Arguments that must be positive, with what they mean (for the message).
    positive: tuple[tuple[str, str], ...] = ()
    # Pairs (low, high) of arguments with low < high (<= for whole numbers).
    ordered: tuple[str, str] | None = None
    # The support, as a function of the arguments that bound it ((low, high) argument names,
    # or a fixed pair).
    support: tuple[str | float, str | float] = (-INF, INF)
    discrete: bool = False
    keyword_only: tuple[str, ...] = ()


def _gamma(a: Mapping[str, float]) -> Gamma:
    return Gamma(a["shape"], 1.0 / a["rate"]) if "rate" in a else Gamma(a["shape"], a["scale"])


_SPECS: dict[str, _Spec] = {
    "normal": _Spec(
        ("mu", "sigma"),
        "normal(mu, sigma)",
        lambda a: Normal(a["mu"], a["sigma"]),
        (("sigma", "standard deviation"),),
    ),
    "truncated_normal": _Spec(
        ("mu", "sigma", "low", "high"),
        "truncated_normal(mu, sigma, low, high)",
        lambda a: TruncatedNormal(a["mu"], a["sigma"], a["low"], a["high"]),
        (("sigma", "standard deviation"),),
        ("low", "high"),
        ("low", "high"),
    ),
    "lognormal": _Spec(
        ("mu", "sigma"),
        "lognormal(mu, sigma)",
        lambda a: LogNormal(a["mu"], a["sigma"]),
        (("sigma", "standard deviation"),),
        support=(0.0, INF),
    ),
    "uniform": _Spec(
        ("low", "high"),
        "uniform(low, high)",
        lambda a: Uniform(a["low"], a["high"]),
        ordered=("low", "high"),
        support=("low", "high"),
    ),
    "gamma": _Spec(
        ("shape", "scale"),
        "gamma(shape, scale) or gamma(shape, rate=...)",
        _gamma,
        (("shape", "shape"), ("scale", "scale"), ("rate", "rate")),
        support=(0.0, INF),
        keyword_only=("rate",),
    ),
    "beta": _Spec(
        ("a", "b"),
        "beta(a, b)",
        lambda a: Beta(a["a"], a["b"]),
        (("a", "first shape"), ("b", "second shape")),
        support=(0.0, 1.0),
    ),
    "exponential": _Spec(
        ("rate",),
        "exponential(rate)",
        lambda a: Exponential(a["rate"]),
        (("rate", "rate"),),
        support=(0.0, INF),
    ),
    "poisson": _Spec(
        ("rate",),
        "poisson(rate)",
        lambda a: Poisson(a["rate"]),
        (("rate", "rate"),),
        support=(0.0, INF),
        discrete=True,
    ),
    "discrete_uniform": _Spec(
        ("low", "high"),
        "discrete_uniform(low, high)",
        lambda a: DiscreteUniform(int(a["low"]), int(a["high"])),
        ordered=("low", "high"),
        support=("low", "high"),
        discrete=True,
    ),
}
_CATEGORICAL_SIGNATURE = "categorical(a, b, ...) or categorical(a: weight, b: weight, ...)"
DISTRIBUTIONS = (*_SPECS, "categorical")

# Domain names and how many bounds each may take.
_DOMAINS: dict[str, tuple[int, ...]] = {
    "real": (0,),
    "positive": (0,),
    "interval": (2,),
    "periodic": (1, 2),
    "integer": (0, 2),
    "colour": (0,),
    "color": (0,),
    "categorical": (0,),
}
_DOMAIN_FORMS = {
    "interval": "interval(low, high)",
    "periodic": "periodic(period) or periodic(low, high)",
    "integer": "integer or integer(low, high)",
}
_COLOUR_DOMAINS = ("colour", "color")
_FINITE_DOMAINS = (*_COLOUR_DOMAINS, "categorical")

# Bounds written as pi/4 in both the domain and the prior must compare equal.
_FIT_TOLERANCE = 1e-9


def parameter_kind(domain: ast.Name | ast.Call) -> str:
    """The kind of symbol a parameter with this domain is, known before it is compiled."""
    name = domain.id if isinstance(domain, ast.Name) else domain.func.text
    if name in _COLOUR_DOMAINS:
        return COLOUR_PARAMETER
    return CATEGORICAL_PARAMETER if name == "categorical" else PARAMETER


@dataclass(frozen=True)
class DynamicPrior:
    """A prior whose arguments depend on the object's values: ``make(values)`` builds it."""

    make: Callable[[Values], Distribution]
    name: str  # the distribution's name
    labels: tuple[str, ...] | None = None  # a categorical's values, which are fixed


Prior = Distribution | DynamicPrior


class Priors:
    """Compiles domains and priors, reporting each error once through ``report``."""

    def __init__(self, expr: Expressions, report: Report, path: str, source: str) -> None:
        self.expr = expr
        self.report = report
        self.path = path
        self.source = source

    # ---- a parameter ----

    def parameter(
        self, choice: ast.Choice, scope: Scope, depends_on: tuple[str, ...] = ()
    ) -> Parameter | None:
        """The parameter a declaration with a domain makes, or None after reporting.

        ``scope`` says whether the prior may use the object's values; ``depends_on`` lists
        the parameters it reads (through derived quantities too).
        """
        local = scope.symbols
        kind = self._domain_kind(choice.domain)
        prior = self.prior(choice.prior, scope, colours=kind in _COLOUR_DOMAINS)
        if kind is None or prior is None:
            return None
        domain = self._domain(choice.domain, kind, prior, Scope(local, where="a domain"))
        if domain is None or not self._fits(prior, domain, kind, choice):
            return None
        name = choice.name.text
        if isinstance(prior, DynamicPrior):
            text = self._text(choice.prior.span)
            make = self._checked(prior, domain, name, text, choice.prior.span)
            return Parameter(name, domain, Dependent(text), prior_fn=make, depends_on=depends_on)
        return Parameter(name, domain, prior)

    def _checked(
        self, prior: DynamicPrior, domain: Domain, name: str, text: str, span: Span
    ) -> Callable[[Values], Distribution]:
        """``prior.make`` with the checks that could not be made when compiling: the
        arguments' constraints (made inside ``make``) and the support against the domain."""
        # A finite domain holds the prior's values by construction: no bounds to check.
        low_d, high_d = (None, None) if isinstance(domain, Finite) else _bounds(domain)
        path, source = self.path, self.source

        def make(values: Values) -> Distribution:
            try:
                dist = prior.make(values)
            except _BadArguments as error:
                problem = str(error)
            except (ArithmeticError, ValueError) as error:
                problem = f"its arguments cannot be evaluated ({type(error).__name__})"
            else:
                if isinstance(domain, Finite):
                    return dist
                low, high = dist.support()
                if low >= low_d - _tolerance(domain) and high <= high_d + _tolerance(domain):
                    return dist
                problem = f"its values range from {low:g} to {high:g}, outside {domain.describe()}"
            shown = ", ".join(f"{k} = {_show(v)}" for k, v in values.items() if k != name)
            raise ModelError(
                f"the prior `{text}` of `{name}` cannot be used where {shown}: {problem}",
                path=path,
                span=span,
                source=source,
            )

        return make

    # ---- priors ----

    def prior(self, call: ast.Call, scope: Scope, colours: bool) -> Prior | None:
        """The distribution a call names; ``colours`` says its values must be palette colours.

        A ``DynamicPrior`` where an argument depends on the object's values.
        """
        name = call.func.text
        if name == "categorical":
            return self._categorical(call, scope, colours)
        if name not in _SPECS:
            hint = did_you_mean(name, DISTRIBUTIONS) or known("distributions", DISTRIBUTIONS)
            self.report(f"unknown distribution `{name}`", call.func.span, hint)
            return None
        spec = _SPECS[name]
        bound = self.expr.bind(call, spec.arguments, spec.signature, spec.keyword_only)
        if bound is None:
            return None
        if name == "gamma" and "scale" in bound and "rate" in bound:
            self.report("gamma takes a scale or a rate, not both", call.span, None)
            return None
        required = set(spec.arguments)
        if "rate" in bound and name == "gamma":
            required = required - {"scale"} | {"rate"}
        if set(bound) != required:
            self.expr.arity_error(call, spec.signature)
            return None
        values = {key: self.expr.number(expr, scope) for key, expr in bound.items()}
        if any(v is None for v in values.values()):
            return None
        constant = {k: v for k, v in values.items() if isinstance(v, float)}
        ok = True
        for key, message in _problems(name, constant):
            self.report(message, bound[key].span if key else call.span, None)
            ok = False
        if not ok:
            return None
        if len(constant) == len(values):
            return spec.make(constant)
        functions = {k: as_function(v) for k, v in values.items()}

        def make(object_values: Values) -> Distribution:
            args = {k: f(object_values) for k, f in functions.items()}
            problems = _problems(name, args)
            if problems:
                raise _BadArguments(problems[0][1])
            return spec.make(args)

        return DynamicPrior(make, name)

    def _categorical(self, call: ast.Call, scope: Scope, colours: bool) -> Prior | None:
        """``categorical(a, b)`` (equal weights) or ``categorical(a: 0.7, b: 0.3)``; for a
        colour, a palette's name stands for all its colours."""
        if not call.args:
            self.report(
                "categorical needs at least one value",
                call.span,
                "e.g. `categorical(red, green, blue)`",
            )
            return None
        weighted = [isinstance(arg, ast.Labelled) for arg in call.args]
        if any(weighted) and not all(weighted):
            self.report("give every value of categorical a weight, or none", call.span, None)
            return None
        labels: list[str] = []
        weights: list[Any] = []
        ok = True
        for arg in call.args:
            if isinstance(arg, ast.Labelled):
                label, weight = ast.Name(arg.label.text, arg.label.span), arg.weight
            elif isinstance(arg, ast.Name):
                label, weight = arg, None
            else:
                self.report(
                    "categorical takes value names, optionally with weights",
                    arg.span,
                    "e.g. `categorical(red, green)` or `categorical(red: 0.7, green: 0.3)`",
                )
                return None
            names = [label.id]
            if colours:
                names = self._colours_of(label, scope, weight is None)
                if names is None:
                    ok = False
                    continue
            for name in names:
                if name in labels:
                    self.report(f"`{name}` is listed twice", label.span, None)
                    ok = False
                    continue
                labels.append(name)
                weights.append(1.0 if weight is None else self._weight(weight, scope))
        if not ok or any(w is None for w in weights):
            return None
        if all(isinstance(w, float) for w in weights):
            if sum(weights) <= 0:
                self.report("the weights of categorical add up to zero", call.span, None)
                return None
            return Categorical(tuple(labels), tuple(weights))
        functions = [as_function(w) for w in weights]
        values = tuple(labels)

        def make(object_values: Values) -> Categorical:
            ws = [f(object_values) for f in functions]
            if any(w < 0 for w in ws) or sum(ws) <= 0:
                raise _BadArguments("its weights must not be negative nor all zero")
            return Categorical(values, tuple(ws))

        return DynamicPrior(make, "categorical", values)

    def _weight(self, expr: ast.Expr, scope: Scope) -> Any:
        weight = self.expr.number(expr, scope)
        if isinstance(weight, float) and weight < 0:
            self.report(f"a weight must not be negative, got {weight:g}", expr.span, None)
            return None
        return weight

    def _colours_of(self, label: ast.Name, scope: Scope, palette_ok: bool) -> list[str] | None:
        """The colour a label names, or the colours of the palette it names."""
        symbol = self.expr.resolve(label, scope, (COLOUR, PALETTE), "colour")
        if symbol is None:
            return None
        if symbol.kind == PALETTE and palette_ok:
            return list(symbol.value)
        if symbol.kind == PALETTE:
            self.report(
                f"`{label.id}` is a palette; give its colours their weights one by one",
                label.span,
                None,
            )
            return None
        if symbol.kind != COLOUR:
            self.report(f"`{label.id}` is a {symbol.kind}, not a palette colour", label.span, None)
            return None
        return [label.id]

    # ---- domains ----

    def _domain_kind(self, node: ast.Name | ast.Call) -> str | None:
        ident = node.func if isinstance(node, ast.Call) else ast.Ident(node.id, node.span)
        if ident.text not in _DOMAINS:
            hint = did_you_mean(ident.text, _DOMAINS) or known("domains", _DOMAINS)
            self.report(f"unknown domain `{ident.text}`", ident.span, hint)
            return None
        return ident.text

    def _domain(
        self, node: ast.Name | ast.Call, kind: str, prior: Prior, scope: Scope
    ) -> Domain | None:
        bounds = node.args if isinstance(node, ast.Call) else ()
        if len(bounds) not in _DOMAINS[kind]:
            if _DOMAINS[kind] == (0,):
                self.report(f"the domain `{kind}` takes no arguments", node.span, None)
            else:
                form = _DOMAIN_FORMS[kind]
                self.report(f"the domain `{kind}` needs bounds: {form}", node.span, None)
            return None
        if kind in _FINITE_DOMAINS:
            labels = _labels(prior)
            if labels is not None:
                return Finite(labels)
            self.report(
                f"a {kind} parameter needs a categorical prior",
                node.span,
                "e.g. `~ categorical(red, green, blue)`",
            )
            return None
        if kind == "real":
            return Real()
        if kind == "positive":
            return Positive()
        if kind == "integer" and not bounds:
            return Integer()
        values = self.expr.positional(node)
        values = values and self.expr.constants(values, scope)
        if values is None:
            return None
        if kind == "periodic" and len(values) == 1:
            (period,) = values
            if not period > 0:
                self.report(f"a period must be positive, got {period:g}", node.span, None)
                return None
            return Periodic(-period / 2, period / 2)
        low, high = values
        if kind == "integer" and not (low == int(low) and high == int(high)):
            self.report(
                f"the bounds of `integer` are whole numbers, got {low:g} and {high:g}",
                node.span,
                None,
            )
            return None
        if not (low < high or (kind == "integer" and low == high)):
            message = f"the bounds of `{kind}` must increase, got {low:g} and {high:g}"
            self.report(message, node.span, None)
            return None
        if kind == "integer":
            return Integer(low, high)
        return Interval(low, high) if kind == "interval" else Periodic(low, high)

    def _fits(self, prior: Prior, domain: Domain, kind: str, choice: ast.Choice) -> bool:
        """Whether the prior's support lies in the domain, reporting it if not (as far as it
        can be told before the object's values are known)."""
        call = choice.prior
        if isinstance(domain, Finite):
            return True  # its values are the prior's, by construction
        name = prior.name if isinstance(prior, DynamicPrior) else call.func.text
        text = self._text(call.span)
        if name == "categorical":
            self.report(
                f"categorical draws names, which do not fit the domain {kind}",
                call.span,
                "use the domain `colour` or `categorical`",
            )
            return False
        spec = _SPECS[name]
        if isinstance(domain, Integer) and not spec.discrete:
            self.report(
                f"the prior `{text}` draws real numbers, which do not fit the domain integer",
                call.span,
                "use poisson or discrete_uniform",
            )
            return False
        if spec.discrete and not isinstance(domain, Integer):
            self.report(
                f"the prior `{text}` draws whole numbers; give `{choice.name.text}` the domain "
                "integer",
                call.span,
                None,
            )
            return False
        if isinstance(prior, DynamicPrior):
            low, high = (_static_bound(spec, b, call) for b in spec.support)
        else:
            low, high = prior.support()
        d_low, d_high = _bounds(domain)
        tol = _tolerance(domain)
        if (low is None or low >= d_low - tol) and (high is None or high <= d_high + tol):
            return True
        shown_low = "?" if low is None else f"{low:g}"
        shown_high = "?" if high is None else f"{high:g}"
        self.report(
            f"the prior `{text}` does not fit the domain {domain.describe()}",
            call.span,
            f"its values range from {shown_low} to {shown_high}",
        )
        return False

    def _text(self, span: Span) -> str:
        """The source text of a span on one line, as written (for quoting in messages)."""
        line = self.source.splitlines()[span.line - 1]
        end = span.end_column if span.end_line == span.line else len(line) + 1
        return line[span.column - 1 : end - 1]


class _BadArguments(ValueError):
    """A dependent prior's arguments broke one of its constraints for some object's values."""


def _problems(name: str, args: Mapping[str, float]) -> list[tuple[str | None, str]]:
    """What is wrong with a distribution's (known) arguments: (argument or None, message)."""
    spec = _SPECS[name]
    found: list[tuple[str | None, str]] = []
    for key, meaning in spec.positive:
        if key in args and not args[key] > 0:
            found.append((key, f"the {meaning} of {name} must be positive, got {args[key]:g}"))
    if spec.discrete:
        for key in ("low", "high"):
            if key in args and args[key] != int(args[key]):
                message = f"the {key} of {name} must be a whole number, got {args[key]:g}"
                found.append((key, message))
    if spec.ordered and all(k in args for k in spec.ordered):
        low, high = (args[k] for k in spec.ordered)
        if not (low < high or (spec.discrete and low == high)):
            found.append((None, f"{name} needs low < high, got {low:g} and {high:g}"))
    return found


def _static_bound(spec: _Spec, bound: str | float, call: ast.Call) -> float | None:
    """A support bound of a dependent prior when it is a constant argument, else None."""
    if isinstance(bound, float):
        return bound
    index = spec.arguments.index(bound)
    args = [a for a in call.args if not isinstance(a, ast.Keyword)]
    keywords = {a.name.text: a.value for a in call.args if isinstance(a, ast.Keyword)}
    expr = keywords.get(bound, args[index] if index < len(args) else None)
    if isinstance(expr, ast.Number):
        return expr.value
    if isinstance(expr, ast.UnaryOp) and expr.op == "-" and isinstance(expr.operand, ast.Number):
        return -expr.operand.value
    return None


def _labels(prior: Prior) -> tuple[str, ...] | None:
    if isinstance(prior, Categorical):
        return prior.values
    if isinstance(prior, DynamicPrior):
        return prior.labels
    return None


def _bounds(domain: Domain) -> tuple[float, float]:
    if isinstance(domain, Real):
        return (-INF, INF)
    if isinstance(domain, Positive):
        return (0.0, INF)
    return (domain.low, domain.high)


def _tolerance(domain: Domain) -> float:
    if isinstance(domain, Finite):
        return 0.0
    bounds = [abs(b) for b in _bounds(domain) if math.isfinite(b)]
    return _FIT_TOLERANCE * max([1.0, *bounds])


def _show(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


__all__ = ["DISTRIBUTIONS", "DynamicPrior", "Priors", "parameter_kind", "PARAMETER"]
