"""What the checks that need a likelihood run on: tiny cameras, observations simulated from prior
scenes, and the model variants the checks sample."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..data.camera import Camera, focal_from_fov, look_at
from ..data.observations import CameraSpec, Frame, Observations
from ..infer.chain import Sampler
from ..infer.warmup import Warmup, warmup_sweeps
from ..model.domains import Finite
from ..model.likelihoods import get_likelihood, sample_observation
from ..model.region import CamerasRegion, bind_region
from ..model.simulate import sample_noise, sample_objects
from ..model.trace import Trace
from ..model.types import RENDER_GROUP, Model
from ..scoring.scorer import PriorScorer, Scorer
from .statistics import seed_sequence

# name, f(objects, noise), whether its values are discrete
Quantity = tuple[str, Callable[[Sequence[Any], Any], float], bool]


def for_checks(model: Model) -> Model:
    """``model`` with a ``region cameras`` taken as the ground the verify cameras see (sized
    by the unrestricted prior): the checks need a region before any observation is made. Any
    other model is returned as it is, its prior not drawn from here (a broken prior is the
    checks' to report, row by row)."""
    if not isinstance(model.region, CamerasRegion):
        return model
    return bind_region(model, [spec.camera for spec in verify_cameras(model)])


def verify_cameras(model: Model, size: int = 8, seed: int = 0) -> list[CameraSpec]:
    """Two tiny cameras, one RGB and one depth, looking at the region where the prior puts
    objects (90% of prior positions lie within the radius they frame)."""
    rng = np.random.default_rng(seed)
    radii = [
        math.hypot(v[cls.position[0]], v[cls.position[1]])
        for cls in model.classes
        if cls.position
        for v in (cls.sample_prior(rng) for _ in range(400))
    ]
    r = max(1.0, float(np.quantile(radii, 0.9))) if radii else 2.0
    f = focal_from_fov(size, 60.0)

    def camera(name, eye):
        eye = np.asarray(eye, dtype=float) * r
        return Camera(name, size, size, f, f, size / 2, size / 2, look_at(eye, (0.0, 0.0, 0.0)),
                      depth_max=4.0 * r)

    specs = []
    if "image" in model.sensors:
        specs.append(CameraSpec(camera("verify-rgb", (1.2, -1.3, 1.1)), ("rgb",)))
    if "depth" in model.sensors:
        specs.append(CameraSpec(camera("verify-depth", (-1.3, -1.0, 1.2)), ("depth",)))
    return specs


class Simulator:
    """Renders scenes for the verify cameras and draws observations from the model's own
    likelihoods, without the clipping ``sppl simulate`` applies to write valid image files:
    the checks need observations distributed exactly as the likelihood says."""

    def __init__(self, model: Model, specs: Sequence[CameraSpec], renderer) -> None:
        self.model = model
        self.specs = list(specs)
        self.renderer = renderer
        self.likelihoods = {k: get_likelihood(s.likelihood, s.options) for k, s in model.sensors.items()}

    def render(self, objects, noise=None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Every verify camera's render of the objects, lit as ``noise``'s render group (if
        the model has lighting parameters) says."""
        parts = [*self.model.static_parts, *(p for o in objects for p in o.parts)]
        settings = self.model.render.with_values((noise or {}).get(RENDER_GROUP))
        return {i: self.renderer.render(parts, s.camera, settings)
                for i, s in enumerate(self.specs)}

    def observe(self, renders, noise, rng) -> Observations:
        frames = []
        for i, spec in enumerate(self.specs):
            rgb, depth = renders[i]
            frame = Frame(camera=spec.camera)
            high = spec.camera.depth_max
            if "rgb" in spec.modalities:
                frame.rgb = sample_observation(self.likelihoods["image"], rgb, noise["image"],
                                               rng, high)
            if "depth" in spec.modalities:
                frame.depth = sample_observation(self.likelihoods["depth"], depth,
                                                 noise["depth"], rng, high)
                frame.depth_valid = np.isfinite(frame.depth)  # NaN: no return
            frames.append(frame)
        return Observations(Path("."), frames)

    def sampler(self, observations, rng, factory, stats=None, warmup=None) -> Sampler:
        sampler = factory(self.model, Scorer(self.model, observations, self.renderer), rng)
        if stats is not None:
            sampler.stats = stats
        if warmup is not None:
            sampler.warmup = warmup
        return sampler


def finished_warmup(model: Model, rng) -> Warmup | None:
    """The state a chain's warm-up leaves (its adapted steps, annealing over), for checks that
    test the kernel after it: the warm-up run on a chain without observations. None when the
    model has no warm-up."""
    n = warmup_sweeps(model.inference)
    if not n:
        return None
    sampler = Sampler(model, PriorScorer(), rng)
    trace = sampler.initial_trace(sample_objects(model, rng))
    for _ in range(n):
        trace = sampler.sweep(trace)
    return sampler.warmup


def prior_scene(model: Model, rng: np.random.Generator):
    """(objects, noise) drawn from the prior, the objects in a random order. ``sample_objects``
    lists them class by class, and chains started only from such tuples would never test a
    move on another order: one that depended on it (a death or a change choosing by position)
    could pass. The scene is a set, so any order is as good a start."""
    objects = sample_objects(model, rng)
    objects = tuple(objects[i] for i in rng.permutation(len(objects)))
    return objects, sample_noise(model, rng)


def trace_with(sampler: Sampler, objects, noise, renders, log_prior=None) -> Trace:
    """The trace of these objects under the sampler's observations, from renders already
    made (so a change of observations costs no rendering)."""
    from ..model.trace import noise_log_prior, objects_log_prior

    scorer = sampler.scorer
    stats = {(t.frame, t.kind): scorer.term_statistics(t, scorer.rendered(renders, t), noise)
             for t in scorer.terms}
    if log_prior is None:
        log_prior = objects_log_prior(sampler.model, objects) + noise_log_prior(sampler.model, noise)
    return Trace(sampler.model, tuple(objects), noise, stats, log_prior,
                 scorer.log_likelihood(stats, noise), renders)


def scene_quantities(model: Model) -> list[Quantity]:
    """Functions of a scene that the Geweke test and SBC compare, each with whether it is
    discrete: the object count, per class its count, per parameter the sum over the class's
    objects (0 when there are none), per categorical value the number of objects with it, and
    each noise parameter."""
    out: list[Quantity] = []
    if len(model.classes) > 1:
        out.append(("object count", lambda objs, noise: float(len(objs)), True))
    for cls in model.classes:
        out.append((f"count of {cls.name}",
                    lambda objs, noise, c=cls: float(sum(o.cls is c for o in objs)), True))
        for par in cls.parameters:
            name = f"{cls.name}.{par.name}"
            if not isinstance(par.domain, Finite):
                out.append((f"sum of {name}", lambda objs, noise, c=cls, n=par.name:
                            float(sum(o.values[n] for o in objs if o.cls is c)),
                            not par.continuous))
            else:
                for v in par.domain.values:
                    out.append((f"{name} = {v}", lambda objs, noise, c=cls, n=par.name, v=v:
                                float(sum(o.values[n] == v for o in objs if o.cls is c)), True))
    for kind, parameters in model.noise_groups:
        for par in parameters:
            out.append((f"{kind}.{par.name}", lambda objs, noise, k=kind, n=par.name:
                        float(noise[k][n]), False))
    return out


def with_jumps(model: Model, p_jump: float | None) -> Model:
    """The model with another chance of a model jump per sweep. Each move leaves the target
    invariant whatever this weight is, so a check may raise it to 1 to mix faster."""
    if p_jump is None:
        return model
    return replace(model, inference=replace(model.inference, p_jump=p_jump))


def with_prior_noise_steps(model: Model, *, draws: int = 2000, seed=0) -> Model:
    """The model with each sensor noise parameter's random-walk step widened to the spread of
    its prior (the standard deviation of ``draws`` prior draws) where its own is smaller.

    A model's noise steps are tuned for the posterior, where the noise is known far better
    than a priori: from the prior such a step needs about (prior sd / step)^2 sweeps to move
    one standard deviation (some hundreds for the shipped models), and prior recovery would
    need a run hundreds of times longer to test it. The random walk leaves the target invariant
    whatever its scale (as ``with_jumps`` says of the jump chance), so the move checked is the
    same; only its tuning differs."""
    rng = np.random.default_rng(seed_sequence(seed))

    def widened(parameters):
        out = []
        for p in parameters:
            if p.continuous:
                spread = float(np.std([p.prior.sample(rng) for _ in range(draws)]))
                if spread > p.proposal_scale:
                    p = replace(p, proposal_scale=spread)
            out.append(p)
        return tuple(out)

    sensors = {kind: replace(sensor, noise=widened(sensor.noise))
               for kind, sensor in model.sensors.items()}
    # The render block's lighting parameters are random walks of the same kind.
    render = replace(model.render, latent=widened(model.render.latent))
    return replace(model, sensors=sensors, render=render)
