"""Declarations ``name : domain ~ prior``: the domain, the prior, and whether they fit.

A parameter's prior must put all its mass inside its domain, since the engine proposes inside
the domain and scores with the prior: ``normal`` on ``positive`` is an error, ``gamma`` on
``real`` is fine, ``uniform(lo, hi)`` must lie within an interval or periodic domain, and
``categorical`` belongs to the finite domains (``colour``, whose values must be palette colours,
and ``categorical``, whose values are free labels).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..distributions import Categorical, Distribution, Gamma, Normal, Poisson, Uniform
from ..domains import Domain, Finite, Interval, Periodic, Positive, Real
from ..errors import Span
from ..model import Parameter
from . import ast
from .expressions import (
    CATEGORICAL_PARAMETER,
    COLOUR,
    COLOUR_PARAMETER,
    PARAMETER,
    Expressions,
    Report,
    Scope,
    Symbol,
    did_you_mean,
    known,
)

# Arguments of each distribution, in positional order. gamma also takes `rate=` in place of
# its scale; categorical takes value names and is handled on its own.
_ARGUMENTS = {
    "normal": ("mu", "sigma"),
    "uniform": ("low", "high"),
    "gamma": ("shape", "scale"),
    "poisson": ("rate",),
}
_SIGNATURES = {
    "normal": "normal(mu, sigma)",
    "uniform": "uniform(low, high)",
    "gamma": "gamma(shape, scale) or gamma(shape, rate=...)",
    "poisson": "poisson(rate)",
    "categorical": "categorical(a, b, ...) or categorical(a: weight, b: weight, ...)",
}

# Domain names and how many bounds each takes.
_DOMAINS = {
    "real": 0,
    "positive": 0,
    "interval": 2,
    "periodic": 2,
    "colour": 0,
    "color": 0,
    "categorical": 0,
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


class Priors:
    """Compiles domains and priors, reporting each error once through ``report``."""

    def __init__(self, expr: Expressions, report: Report, source: str) -> None:
        self.expr = expr
        self.report = report
        self.source = source

    def parameter(self, choice: ast.Choice, local: Mapping[str, Symbol]) -> Parameter | None:
        """The parameter a declaration with a domain makes, or None after reporting."""
        scope = Scope(local, where="a prior")
        kind = self._domain_kind(choice.domain)
        prior = self.prior(choice.prior, scope, colours=kind in _COLOUR_DOMAINS)
        if kind is None or prior is None:
            return None
        if isinstance(prior, Poisson):
            self.report(
                "poisson is only for a class's count",
                choice.prior.func.span,
                "use normal, uniform, gamma or categorical",
            )
            return None
        domain = self._domain(choice.domain, kind, prior, Scope(local, where="a domain"))
        if domain is None or not self._fits(prior, domain, kind, choice.prior):
            return None
        return Parameter(choice.name.text, domain, prior)

    def prior(self, call: ast.Call, scope: Scope, colours: bool) -> Distribution | Poisson | None:
        """The distribution a call names; ``colours`` says its values must be palette colours."""
        name = call.func.text
        if name == "categorical":
            return self._categorical(call, scope, colours)
        if name not in _ARGUMENTS:
            hint = did_you_mean(name, _SIGNATURES) or known("distributions", _SIGNATURES)
            self.report(f"unknown distribution `{name}`", call.func.span, hint)
            return None
        keyword_only = ("rate",) if name == "gamma" else ()
        bound = self.expr.bind(call, _ARGUMENTS[name], _SIGNATURES[name], keyword_only)
        if bound is None:
            return None
        if name == "gamma" and "scale" in bound and "rate" in bound:
            self.report("gamma takes a scale or a rate, not both", call.span, None)
            return None
        required = set(_ARGUMENTS[name])
        if "rate" in bound:
            required = required - {"scale"} | {"rate"}
        if set(bound) != required:
            self.expr.arity_error(call, _SIGNATURES[name])
            return None
        values = {key: self.expr.constant(expr, scope) for key, expr in bound.items()}
        if any(v is None for v in values.values()):
            return None

        def positive(key: str, meaning: str) -> bool:
            if values[key] > 0:
                return True
            message = f"the {meaning} of {name} must be positive, got {values[key]:g}"
            self.report(message, bound[key].span, None)
            return False

        if name == "normal":
            ok = positive("sigma", "standard deviation")
            return Normal(values["mu"], values["sigma"]) if ok else None
        if name == "uniform":
            if values["low"] < values["high"]:
                return Uniform(values["low"], values["high"])
            low, high = values["low"], values["high"]
            self.report(f"uniform needs low < high, got {low:g} and {high:g}", call.span, None)
            return None
        if name == "gamma" and "rate" in bound:
            ok = positive("shape", "shape") & positive("rate", "rate")
            return Gamma(values["shape"], 1.0 / values["rate"]) if ok else None
        if name == "gamma":
            ok = positive("shape", "shape") & positive("scale", "scale")
            return Gamma(values["shape"], values["scale"]) if ok else None
        return Poisson(values["rate"]) if positive("rate", "rate") else None

    def _categorical(self, call: ast.Call, scope: Scope, colours: bool) -> Categorical | None:
        """``categorical(a, b)`` (equal weights) or ``categorical(a: 0.7, b: 0.3)``."""
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
        weights: list[float | None] = []
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
            if label.id in labels:
                self.report(f"`{label.id}` is listed twice", label.span, None)
                weights.append(None)
            elif colours and not self._is_colour(label, scope):
                weights.append(None)
            else:
                weights.append(1.0 if weight is None else self._weight(weight, scope))
            labels.append(label.id)
        if any(w is None for w in weights):
            return None
        if sum(weights) <= 0:
            self.report("the weights of categorical add up to zero", call.span, None)
            return None
        return Categorical(tuple(labels), tuple(weights))

    def _weight(self, expr: ast.Expr, scope: Scope) -> float | None:
        weight = self.expr.constant(expr, scope)
        if weight is not None and weight < 0:
            self.report(f"a weight must not be negative, got {weight:g}", expr.span, None)
            return None
        return weight

    def _is_colour(self, label: ast.Name, scope: Scope) -> bool:
        symbol = self.expr.resolve(label, scope, (COLOUR,), "colour")
        if symbol is not None and symbol.kind != COLOUR:
            self.report(f"`{label.id}` is a {symbol.kind}, not a palette colour", label.span, None)
            return False
        return symbol is not None

    def _domain_kind(self, node: ast.Name | ast.Call) -> str | None:
        ident = node.func if isinstance(node, ast.Call) else ast.Ident(node.id, node.span)
        if ident.text not in _DOMAINS:
            hint = did_you_mean(ident.text, _DOMAINS) or known("domains", _DOMAINS)
            self.report(f"unknown domain `{ident.text}`", ident.span, hint)
            return None
        return ident.text

    def _domain(
        self, node: ast.Name | ast.Call, kind: str, prior: Distribution, scope: Scope
    ) -> Domain | None:
        bounds = node.args if isinstance(node, ast.Call) else None
        if _DOMAINS[kind] == 0 and bounds is not None:
            self.report(f"the domain `{kind}` takes no arguments", node.span, None)
            return None
        if _DOMAINS[kind] and (bounds is None or len(bounds) != _DOMAINS[kind]):
            self.report(f"the domain `{kind}` needs bounds: {kind}(low, high)", node.span, None)
            return None
        if kind in _FINITE_DOMAINS:
            if isinstance(prior, Categorical):
                return Finite(prior.values)
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
        values = self.expr.positional(node)
        values = values and self.expr.constants(values, scope)
        if values is None:
            return None
        low, high = values
        if not low < high:
            message = f"the bounds of `{kind}` must increase, got {low:g} and {high:g}"
            self.report(message, node.span, None)
            return None
        return Interval(low, high) if kind == "interval" else Periodic(low, high)

    def _fits(self, prior: Distribution, domain: Domain, kind: str, call: ast.Call) -> bool:
        """Whether the prior's support lies in the domain, reporting it if not."""
        if isinstance(domain, Finite):
            return True  # its values are the prior's, by construction
        if isinstance(prior, Categorical):
            self.report(
                f"categorical draws names, which do not fit the domain {kind}",
                call.span,
                "use the domain `colour` or `categorical`",
            )
            return False
        low, high = prior.support()
        d_low, d_high = _bounds(domain)
        tol = _FIT_TOLERANCE * max([1.0] + [abs(b) for b in (d_low, d_high) if math.isfinite(b)])
        if low >= d_low - tol and high <= d_high + tol:
            return True
        self.report(
            f"the prior `{self._text(call.span)}` does not fit the domain {domain.describe()}",
            call.span,
            f"its values range from {low:g} to {high:g}",
        )
        return False

    def _text(self, span: Span) -> str:
        """The source text of a span on one line, as written (for quoting in messages)."""
        line = self.source.splitlines()[span.line - 1]
        end = span.end_column if span.end_line == span.line else len(line) + 1
        return line[span.column - 1 : end - 1]


def _bounds(domain: Domain) -> tuple[float, float]:
    if isinstance(domain, Real):
        return (-math.inf, math.inf)
    if isinstance(domain, Positive):
        return (0.0, math.inf)
    return (domain.low, domain.high)
