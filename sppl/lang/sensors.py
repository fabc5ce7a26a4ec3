"""Sensors: ``sensor image { ... }`` and ``sensor depth { ... }``, each with its likelihood.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. A sensor's
noise parameters are compiled like a class's (``declarations.py``); its likelihood is looked up
among those installed, third-party ones included, and says which noise parameters it needs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..errors import SpplError
from ..model.domains import Interval, Periodic, Positive
from . import ast
from .context import CompileContext, PendingSensor
from .declarations import compile_locals, declare_locals
from .expressions import did_you_mean, known

_SENSOR_KINDS = ("image", "depth")


class Sensors:
    """The sensors of one file, by kind."""

    def __init__(self, context: CompileContext) -> None:
        self.context = context
        self.expr = context.expr
        self.error = context.error
        self.by_kind: dict[str, PendingSensor] = {}

    def compile(self, node: ast.Sensor) -> None:
        kind = node.kind.text
        if kind not in _SENSOR_KINDS:
            self.error(
                f"unknown sensor `{kind}`",
                node.kind.span,
                did_you_mean(kind, _SENSOR_KINDS) or known("sensors", _SENSOR_KINDS),
            )
        pending = PendingSensor(kind)
        if kind in self.by_kind:
            self.error(f"sensor `{kind}` is already defined", node.kind.span)
        elif kind in _SENSOR_KINDS:
            self.by_kind[kind] = pending
        local, own = declare_locals(self.context, node.body, pending, f"sensor `{kind}`")
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
                elif self.context.first(("sensor", kind, item.key.text), item):
                    value = self._option(item.value)
                    if value is not None:
                        pending.options[item.key.text] = value
            elif item.name.text == "count":
                self.error("a sensor has no `count`; counts belong to classes", item.name.span)
            elif item.domain is None:
                self.context.no_domain(item, "positive")
        compile_locals(self.context, own, local, pending, parameters_allowed=False)
        if likelihood is None:
            self.error(
                f"sensor `{kind}` has no likelihood",
                node.kind.span,
                "add a line such as `likelihood gaussian`",
            )
        else:
            self._likelihood(likelihood, pending, own, kind)

    def _likelihood(
        self, node: ast.Likelihood, pending: PendingSensor, own: Mapping[str, Any], kind: str
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
        if isinstance(value, ast.Name) and value.id not in self.context.symbols:
            return value.id
        return self.expr.constant(value, self.context.global_scope())


def _domain_within(domain, low: float, high: float) -> bool:
    """Whether every value of a (continuous) domain lies in [low, high]."""
    if isinstance(domain, Positive):
        return low <= 0.0 and high == math.inf
    if isinstance(domain, (Interval, Periodic)):
        return low <= domain.low and domain.high <= high
    return False
