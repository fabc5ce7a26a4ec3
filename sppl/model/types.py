"""A compiled scene model: what the engine, the renderer and the commands work from.

The language front end (``sppl.lang``) turns a ``.scn`` file into a ``Model``; nothing
downstream looks at the parse tree or knows the name of any concrete class. Everything the
engine needs to derive its moves is here: each class's parameters with their domains, priors and
proposal scales, its Poisson rate, how to build its geometry from parameter values, and each
sensor's likelihood with the priors on its noise parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .distributions import Distribution
from .domains import Domain, is_continuous
from .geometry import Part, footprint_of
from .jumps import default_weights

Values = Mapping[str, Any]

# The most objects a scene may hold: each sweep moves every object, and every move renders the
# scene, so a chain over scenes of thousands of objects would not finish. A model whose prior
# puts more than SCENE_TAIL of its mass on bigger scenes is refused when it is compiled.
MAX_SCENE_OBJECTS = 1000
SCENE_TAIL = 1e-6
_COUNT_TRIES = 1000  # Poisson draws tried for a truncated count before drawing it exactly


def count_log_pmf(rate: float, upto: int) -> np.ndarray:
    """log P(N = n) for n = 0..upto, N ~ Poisson(rate) truncated to at most ``upto``."""
    n = np.arange(upto + 1, dtype=float)
    from scipy.special import gammaln

    log_p = n * math.log(rate) - rate - gammaln(n + 1) if rate > 0 else np.where(n == 0, 0.0,
                                                                                  -np.inf)
    return log_p - np.logaddexp.reduce(log_p)


def probability_of_more_objects(classes: Sequence[ObjectClass], limit: int) -> float:
    """P(the classes' counts add up to more than ``limit``) under their priors (fixed, Poisson,
    or Poisson truncated at ``max_count``), ignoring every other constraint."""
    from scipy.stats import poisson

    total = np.zeros(limit + 2)  # P(total = 0..limit), and in the last entry P(total > limit)
    total[0] = 1.0
    for cls in classes:
        if cls.count is not None:
            pmf = np.zeros(limit + 2)
            pmf[min(cls.count, limit + 1)] = 1.0
        elif cls.max_count is not None:
            pmf = np.zeros(limit + 2)
            top = min(cls.max_count, limit)
            pmf[: top + 1] = np.exp(count_log_pmf(cls.rate, cls.max_count)[: top + 1])
            if cls.max_count > limit:
                pmf[limit + 1] = max(0.0, 1.0 - pmf[: limit + 1].sum())
        else:
            pmf = np.append(poisson.pmf(np.arange(limit + 1), cls.rate),
                            poisson.sf(limit, cls.rate))
        both = np.convolve(total, pmf)
        total = np.append(both[: limit + 1], both[limit + 1 :].sum())
    return float(min(1.0, max(0.0, total[limit + 1])))


@dataclass(frozen=True)
class Parameter:
    """One random choice of an object (or of a sensor's noise): its domain, prior and step.

    A prior may depend on other values of the same object (``h ~ uniform(r, 2 * r)``): then
    ``prior_fn`` makes the distribution from the object's values, ``depends_on`` names the
    parameters it reads, and ``prior`` is only a ``Dependent`` placeholder with its text.
    ``sample`` and ``log_prob`` take those values; for an independent prior they may be left
    out, and ``prior`` is the distribution itself.
    """

    name: str
    domain: Domain
    prior: Distribution
    proposal_scale: float = 0.1
    prior_fn: Callable[[Values], Distribution] | None = None
    depends_on: tuple[str, ...] = ()

    @property
    def continuous(self) -> bool:
        return is_continuous(self.domain)

    def distribution(self, values: Values | None = None) -> Distribution:
        """The prior, given the object's other values when it depends on them."""
        if self.prior_fn is None:
            return self.prior
        if values is None:
            raise TypeError(
                f"the prior of `{self.name}` depends on {', '.join(self.depends_on)}: "
                "pass the object's values"
            )
        return self.prior_fn(values)

    def sample(self, rng: np.random.Generator, values: Values | None = None) -> Any:
        return self.distribution(values).sample(rng)

    def log_prob(self, value: Any, values: Values | None = None) -> float:
        if not self.domain.contains(value):
            return -math.inf
        return self.distribution(values).log_prob(value)


@dataclass(frozen=True, eq=False)
class ObjectClass:
    """A class of object that may appear in a scene any number of times.

    ``build`` maps a dict of parameter values to the posed, coloured parts that are rendered;
    ``footprint`` (optional) maps them to the convex polygon, an (M, 2) array of ground-plane
    points, used by the no-overlap constraint. Without it the footprint is the convex hull of
    the parts seen from above.
    """

    name: str
    rate: float
    parameters: tuple[Parameter, ...]
    build: Callable[[Values], tuple[Part, ...]]
    footprint_fn: Callable[[Values], np.ndarray] | None = None
    # The two parameters that place the object on the ground plane, if it has them.
    position: tuple[str, str] | None = None
    # A fixed number of objects of this class in every scene, instead of Poisson(rate) many;
    # and an upper bound on the number (a Poisson count truncated to at most max_count).
    count: int | None = None
    max_count: int | None = None
    # A floating object does not rest on the ground: the no-overlap constraint leaves it out.
    floating: bool = False
    # Declared change-of-class correspondences: {other class: {parameter here: parameter
    # there}}, carried as-is by a change between the two classes (sppl.infer.moves).
    correspondences: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    # Of those, the ones carried scaled: {other class: {parameter here: factor}}, where the
    # value here is the factor times the value there (sppl.infer.moves.carried_scales).
    correspondence_scales: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    # The model's region restricting the position prior (``sppl.model.region.Restriction``), if any.
    restriction: Any = None

    def parameter(self, name: str) -> Parameter | None:
        for p in self.parameters:
            if p.name == name:
                return p
        return None

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def sample_prior(
        self, rng: np.random.Generator, given: Values | None = None
    ) -> dict[str, Any]:
        """Values drawn from the prior; those in ``given`` are kept and the others drawn
        conditionally on them. ``parameters`` is in dependency order, so each prior's
        arguments are known when it is drawn."""
        given = given or {}
        values = dict(given)
        r = self.restriction
        for p in self.parameters:
            if p.name not in values and (r is None or p.name not in r.names):
                values[p.name] = p.sample(rng, values)
        if r is not None:
            # Nothing depends on the position (``position``), so it may come last: a draw of
            # the prior restricted to the region, given a coordinate ``given`` fixes.
            r.sample(rng, values, given)
        return values

    def log_prior(self, values: Values, only: Collection[str] | None = None) -> float:
        """log p(values), or, with ``only``, the log density of those parameters given the
        others (the density of drawing them with ``sample_prior(rng, given=the others)``)."""
        total = 0.0
        for p in self.parameters:
            if only is not None and p.name not in only:
                continue
            total += p.log_prob(values[p.name], values)
            if total == -math.inf:
                return total  # a dependent prior must not see values outside their domains
        if self.restriction is not None:
            total += self.restriction.log_correction(values, only)
        return total

    def sample_count(self, rng: np.random.Generator) -> int:
        """A draw of the number of objects of this class, ignoring any other constraint."""
        if self.count is not None:
            return self.count
        for _ in range(_COUNT_TRIES):
            n = int(rng.poisson(self.rate))
            if self.max_count is None or n <= self.max_count:
                return n
        # A bound far below the rate: rejection would take forever, so draw from the
        # truncated Poisson itself. Exact either way: both draw from Poisson given n <= max.
        log_p = count_log_pmf(self.rate, self.max_count)
        p = np.exp(log_p - log_p.max())
        return int(rng.choice(len(p), p=p / p.sum()))

    def parts(self, values: Values) -> tuple[Part, ...]:
        return tuple(self.build(values))

    def footprint(self, values: Values, parts: Sequence[Part] | None = None) -> np.ndarray:
        """The footprint polygon, an (M, 2) array; ``parts``, if given, are ``values``'
        parts (which the derived footprint is made from)."""
        if self.footprint_fn is not None:
            return np.asarray(self.footprint_fn(values), dtype=float)
        return footprint_of(self.parts(values) if parts is None else parts)


@dataclass(frozen=True)
class Sensor:
    """A sensor modality ('image' or 'depth'): its likelihood by name and its noise choices."""

    kind: str
    likelihood: str
    noise: tuple[Parameter, ...]
    options: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class InferenceSettings:
    """Knobs of the derived sampler (thesis Algorithms 1, 2 and 7)."""

    p_jump: float = 1.0 / 20.0
    # Chance that a birth places its object near unexplained observations rather than at a
    # draw from the prior (sppl/infer/birth.py), and the spread of that placement in metres.
    data_birth: float = 0.5
    data_birth_spread: float = 0.25
    # The refit's choice of object: the share of it that follows the pixels the state gets
    # wrong (sppl/infer/misfit.py; 0: uniform), and the share of fitted proposals (refits,
    # merges, splits, fitted births) drawn as a birth instead of around the fit
    # (sppl/infer/fit.py).
    refit_focus: float = 0.0
    fit_births: float = 0.5
    # How much further a merge's fit searches (sppl/infer/merge.py): from this many seeds of
    # the scene without the merged objects besides their values, and this many evaluations of
    # Powell's method after it (0: the refit's search alone).
    merge_seeds: int = 0
    merge_polish: int = 0
    # Evaluations of anchored steps after a merge's pattern search (sppl/infer/fit.py: a size
    # or angle moved with the place so that one corner stays put); 0: none.
    merge_anchor: int = 0
    # The share of a merge's choice of the object it takes away that follows how little the
    # state loses without it (sppl/infer/redundant.py; 0: uniform).
    merge_focus: float = 0.0
    # Face moves per face parameter of each object in a sweep (sppl/infer/faces.py: a size
    # stepped with the place so that one side stays put); 0: none.
    face_steps: int = 0
    # Relative weights of the model jumps, by default each registered jump's own
    # (sppl.model.jumps). The thesis has birth, death and change, equally weighted; replace
    # (sppl.infer.moves.propose_replace) is sppl's addition. refit (sppl.infer.fit), merge and
    # split (sppl.infer.merge), fitted_birth and fitted_death (sppl.infer.fitted_birth) are off
    # unless a model weighs them (sppl.infer.jumps registers them all).
    jump_weights: Mapping[str, float] = field(default_factory=default_weights)
    # The warm-up (sppl/infer/warmup.py): sweeps of proposal-scale adaptation, and of an annealed
    # likelihood rising from the power anneal_from to 1; both are burned and then stop.
    adapt: int = 0
    anneal: int = 0
    anneal_from: float = 0.01
    # Candidates a birth, death or replace weighs at once (sppl/infer/tries.py); 1: single tries.
    tries: int = 1
    # Parallel tempering (sppl/infer/tempering.py): chains in the ladder, the posterior's included
    # (1: none), and the hottest one's power of the likelihood.
    tempered: int = 1
    tempered_from: float = 0.05


# The render block's parameters a model may leave uncertain, each a latent choice with a prior
# (``ambient : unit ~ beta(4, 6)``), and the domain each must have.
LIGHTING = ("ambient", "intensity", "sheen", "azimuth", "elevation", "gain", "red", "blue")
RENDER_GROUP = "render"  # the name under which a trace keeps their values, beside the sensors'


@dataclass(frozen=True)
class RenderSettings:
    """How a hypothesis is drawn. A part of colour c, lit at a surface whose normal makes the
    lambert term lambert with the light, shows

        balance * gain * (c * (ambient + intensity * (1 - ambient) * lambert * lit) + sheen)

    where lit is 0 in the shadow of another part (``shadows``) and 1 elsewhere, and balance is
    the white balance (red, 1, blue); the background shows balance * gain * background.
    ``sheen`` is a grey that every part shows whatever its colour and its orientation: a
    rough surface mirrors a little of a grey sky, which a colour factor cannot draw (on a
    dark or saturated colour, or a side turned from the sun, it is much of what is seen)."""

    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ambient: float = 0.35
    # Direction *towards* the light, in world coordinates.
    light: tuple[float, float, float] = (0.4, -0.3, 1.0)
    intensity: float = 1.0
    sheen: float = 0.0
    gain: float = 1.0
    red: float = 1.0
    blue: float = 1.0
    # Whether parts cast shadows from the light (on the ground and on one another).
    shadows: bool = False
    # The lighting parameters the model leaves uncertain, with their priors (LIGHTING).
    latent: tuple[Parameter, ...] = ()

    def with_values(self, values: Mapping[str, float] | None) -> RenderSettings:
        """These settings with the latent parameters at the given values. ``azimuth`` and
        ``elevation`` (radians; azimuth from +x towards +y, elevation above the ground) set
        the light's direction, each of the two not given taken from ``light``."""
        if not values:
            return self
        changes = {k: float(v) for k, v in values.items() if k not in ("azimuth", "elevation")}
        if "azimuth" in values or "elevation" in values:
            x, y, z = np.asarray(self.light, dtype=float) / np.linalg.norm(self.light)
            azimuth = float(values.get("azimuth", math.atan2(y, x)))
            elevation = float(values.get("elevation", math.asin(max(-1.0, min(1.0, z)))))
            changes["light"] = (math.cos(elevation) * math.cos(azimuth),
                                math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
        return replace(self, **changes)

    @property
    def direction(self) -> tuple[float, float, float]:
        """The unit vector towards the light."""
        light = np.asarray(self.light, dtype=float)
        return tuple(float(x) for x in light / np.linalg.norm(light))

    @property
    def balance(self) -> tuple[float, float, float]:
        """What each channel of the image is multiplied by: gain times the white balance."""
        return (self.gain * self.red, self.gain, self.gain * self.blue)

    def shaded(self) -> tuple:
        """What the shaders read of these settings, for telling two apart cheaply."""
        return (self.direction, float(self.ambient), float(self.intensity), float(self.sheen),
                self.balance)


@dataclass(frozen=True, eq=False)
class Model:
    classes: tuple[ObjectClass, ...]
    sensors: Mapping[str, Sensor]
    inference: InferenceSettings = field(default_factory=InferenceSettings)
    render: RenderSettings = field(default_factory=RenderSettings)
    colours: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    # The hard constraint of thesis 3.1.3: no two objects' footprints share area.
    no_overlap: bool = False
    # An upper bound on the total number of objects in a scene, if any.
    max_objects: int | None = None
    # Where objects may be (``sppl.model.region``): a Region the classes' positions are restricted
    # to, or, for ``region cameras``, a CamerasRegion until the cameras are known.
    region: Any = None
    # Fixed parts every hypothesis renders: the ground plane, a table that is always there.
    static_parts: tuple[Part, ...] = ()
    path: Path | None = None
    source: str = ""

    def object_class(self, name: str) -> ObjectClass:
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def class_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.classes)

    @property
    def noise_groups(self) -> tuple[tuple[str, tuple[Parameter, ...]], ...]:
        """The latent parameters that are not objects', by group: each sensor's noise
        parameters, then the render block's lighting (RENDER_GROUP) if it has any. A trace
        keeps their values as ``noise[group][name]``."""
        groups = tuple((kind, s.noise) for kind, s in self.sensors.items())
        if self.render.latent:
            groups += ((RENDER_GROUP, self.render.latent),)
        return groups

