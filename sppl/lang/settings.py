"""The render and inference blocks: how scenes are drawn, and how the sampler runs.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. The render
block's lighting may be latent: its parameters are compiled like a sensor's noise
(``declarations.py``). The inference block's steps are kept for ``steps.py``, which needs every
parameter of the model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..model.domains import Finite
from ..model.jumps import jump_names, reverse_pairs
from ..model.types import LIGHTING, RENDER_GROUP, InferenceSettings, RenderSettings
from . import ast
from .context import CompileContext, PendingSensor
from .declarations import compile_locals, declare_locals
from .expressions import Scope, did_you_mean, known

_RENDER_KEYS = ("background", "ambient", "light", "intensity", "sheen", "gain", "red", "blue",
                "shadows")
# Lighting parameters whose values must be at least 0, and those of them also at most 1 (a
# share of the light, a grey level).
_NONNEGATIVE = ("ambient", "intensity", "sheen", "gain", "red", "blue")
_UNIT = ("ambient", "sheen")
_INFERENCE_KEYS = ("p_jump", "data_birth", "data_birth_spread", "refit_focus", "fit_births",
                   "merge_seeds", "merge_polish", "merge_anchor", "merge_focus", "face_steps",
                   "adapt", "anneal", "anneal_from", "tries", "tempered", "tempered_from")
# Inference settings that count something, at least 0: what each counts, and the hint of its
# error.
_COUNTS = {"adapt": ("sweeps", "0 switches it off"), "anneal": ("sweeps", "0 switches it off"),
           "merge_seeds": ("seeds", "0 searches from the merged objects alone"),
           "merge_polish": ("evaluations", "0 switches it off"),
           "merge_anchor": ("evaluations", "0 switches it off"),
           "face_steps": ("steps", "0 switches face moves off")}


class Settings:
    """The render and inference settings of one file."""

    def __init__(self, context: CompileContext) -> None:
        self.context = context
        self.expr = context.expr
        self.error = context.error
        # What the file sets, by key: the settings' defaults stand for the rest.
        self.render_values: dict[str, object] = {}
        # The render block's latent lighting parameters, stepped like a sensor's noise.
        self.lighting = PendingSensor(RENDER_GROUP)
        self.inference_values: dict[str, object] = {}
        self.jump_weights: dict[str, float] = {}
        # Applied once the parameters of every class and sensor are known (steps.py).
        self.steps: list[ast.Step] = []

    def render(self, node: ast.Render) -> None:
        scope = self.context.global_scope()
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
                self.context.no_domain(item, "positive")
            elif name in self.lighting.declared:
                self.error(f"the lighting parameter `{name}` is already declared", item.name.span)
            else:
                choices.append(item)
        before = len(self.lighting.parameters)
        local, own = declare_locals(self.context, choices, self.lighting, "the render block")
        compile_locals(self.context, own, local, self.lighting, parameters_allowed=False)
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
            elif self.context.first(("render", key), setting):
                value = self._render_value(key, setting.value, scope)
                if value is not None:
                    self.render_values[key] = value

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

    def inference(self, node: ast.Inference) -> None:
        scope = self.context.global_scope()
        for item in node.body:
            if isinstance(item, ast.Step):
                self.steps.append(item)
            elif isinstance(item, ast.JumpWeights):
                self._jump_weight_settings(item, scope)
            elif item.key.text not in _INFERENCE_KEYS:
                hint = did_you_mean(item.key.text, _INFERENCE_KEYS + ("step", "jump_weights"))
                self._unknown_setting(item, "inference", _INFERENCE_KEYS, hint)
            elif self.context.first(("inference", item.key.text), item):
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
                elif key in ("refit_focus", "merge_focus") and not 0.0 <= value <= 1.0:
                    what = "to refit" if key == "refit_focus" else "a merge takes away"
                    self.error(f"`{key}` is a share in [0, 1], got {value:g}", item.value.span,
                               f"0 chooses the object {what} uniformly")
                elif key == "fit_births" and not 0.0 < value < 1.0:
                    self.error(
                        f"`fit_births` is a share strictly between 0 and 1, got {value:g}",
                        item.value.span,
                        "without births a fitted proposal could not leave a state far from "
                        "every fit; without fits it is a replace")
                elif key in _COUNTS and not (value >= 0 and value == int(value)):
                    counted, hint = _COUNTS[key]
                    self.error(f"`{key}` is a number of {counted}, got {value:g}",
                               item.value.span, hint)
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
                    if key in _COUNTS or key in ("tries", "tempered"):
                        value = int(value)
                    self.inference_values[key] = value

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
            elif self.context.first(("jump_weights", key), setting):
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

    def render_settings(self) -> RenderSettings:
        return RenderSettings(**self.render_values, latent=tuple(self.lighting.parameters))

    def inference_settings(self) -> InferenceSettings:
        return InferenceSettings(**self.inference_values, **self._jump_weights())

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
