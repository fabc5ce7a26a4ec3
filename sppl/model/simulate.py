"""Forward simulation: a scene from the prior (or a given one), rendered and made noisy.

This is the model's generative story run forwards (thesis chapter 3), and what ``sppl simulate``
and the statistical tests use to make observations whose truth is known.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..data.observations import CameraSpec, Frame
from ..errors import SpplError
from .trace import SceneObject, counts_allowed, make_object, scene_is_valid
from .types import MAX_SCENE_OBJECTS, RENDER_GROUP, Model

PROGRESS_SECONDS = 5.0  # how often a long rejection sampling says it is still at work


def sample_objects(model: Model, rng: np.random.Generator, max_tries: int = 10_000,
                   progress=None):
    """Objects drawn from the prior: Poisson (or fixed) counts per class, parameters from each
    class's prior, and, under the no-overlap constraint or a bound on the total, whole scenes
    redrawn until they keep it (rejection sampling, which is exactly the constrained prior).
    ``progress(tries, seconds)``, if given, is called every ``PROGRESS_SECONDS`` while it
    draws, so that a long search is never silent."""
    t0 = last = time.monotonic()
    for tries in range(max_tries):
        objects = _draw_scene(model, rng)
        if objects is not None and counts_allowed(model, objects) and scene_is_valid(objects):
            return tuple(objects)
        if progress is not None and time.monotonic() - last >= PROGRESS_SECONDS:
            last = time.monotonic()
            progress(tries + 1, last - t0)
    bound = "" if model.max_objects is None else f" and at most {model.max_objects} objects"
    raise SpplError(
        f"no scene without overlapping objects{bound} in {max_tries} draws from the prior; "
        "lower the classes' rates or widen the position priors"
    )


def _draw_scene(model: Model, rng: np.random.Generator) -> list[SceneObject] | None:
    """One draw of every class's objects, or None as soon as the total is past both the bound
    on it and what a scene can hold (a scene the constraints reject anyway: not worth making
    a million objects to find that out)."""
    objects: list[SceneObject] = []
    for cls in model.classes:
        n = cls.sample_count(rng)
        if len(objects) + n > MAX_SCENE_OBJECTS and model.max_objects is not None \
                and len(objects) + n > model.max_objects:
            return None
        objects += [make_object(model, cls, cls.sample_prior(rng)) for _ in range(n)]
    return objects


def fixed_objects(model: Model, rng: np.random.Generator, max_tries: int = 10_000):
    """A starting scene for a chain: the objects of the classes with a fixed count, drawn from
    their priors (an empty scene has no prior density when a class must have objects)."""
    fixed = [c for c in model.classes if c.count]
    for _ in range(max_tries):
        objects = [
            make_object(model, cls, cls.sample_prior(rng)) for cls in fixed for _ in range(cls.count)
        ]
        if counts_allowed(model, objects) and scene_is_valid(objects):
            return tuple(objects)
    raise SpplError(
        f"no arrangement of the fixed-count objects keeps the model's constraints in {max_tries}"
        " draws from the prior"
    )


def sample_noise(model: Model, rng: np.random.Generator) -> dict[str, dict[str, float]]:
    return {k: {p.name: p.prior.sample(rng) for p in ps} for k, ps in model.noise_groups}


def objects_from_dict(model: Model, scene: Mapping[str, Any], where: str = "scene") -> tuple[SceneObject, ...]:
    """Objects of a scene file: ``{"objects": [{"class": ..., "params": {...}}, ...]}``."""
    objects = []
    for i, o in enumerate(scene.get("objects", [])):
        try:
            cls = model.object_class(o["class"])
        except KeyError:
            raise SpplError(
                f"{where}: object {i} has unknown class {o.get('class')!r}; "
                f"the model's classes are {', '.join(model.class_names)}"
            ) from None
        params = dict(o.get("params", {}))
        missing = [n for n in cls.parameter_names if n not in params]
        if missing:
            raise SpplError(f"{where}: object {i} ({cls.name}) lacks parameters {', '.join(missing)}")
        obj = make_object(model, cls, {n: params[n] for n in cls.parameter_names})
        if not np.isfinite(obj.log_prior):
            raise SpplError(f"{where}: object {i} ({cls.name}) has a value outside its domain")
        objects.append(obj)
    return tuple(objects)


def load_scene(model: Model, path: str | Path):
    """A scene file's objects and noise scales (the noise may be absent: then None)."""
    try:
        scene = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise SpplError(f"{path}: no such scene file") from None
    except json.JSONDecodeError as e:
        raise SpplError(f"{path}:{e.lineno}:{e.colno}: not valid JSON: {e.msg}") from None
    return objects_from_dict(model, scene, str(path)), scene.get("noise")


def render_observations(
    model: Model,
    objects: Sequence[SceneObject],
    noise: Mapping[str, Mapping[str, float]],
    cameras: Sequence[CameraSpec],
    renderer,
    rng: np.random.Generator,
) -> list[Frame]:
    """Render each camera and add each modality's noise from the model's likelihoods."""
    from .likelihoods import get_likelihood, sample_observation

    parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
    # Lit as the scene's lighting values say, where the model leaves the lighting latent.
    lit = () if not model.render.latent else (model.render.with_values(noise[RENDER_GROUP]),)
    frames = []
    for spec in cameras:
        cam, modalities = spec.camera, spec.modalities
        rgb, depth = renderer.render(parts, cam, *lit)
        frame_rgb = frame_depth = valid = None
        if "rgb" in modalities:
            s = model.sensors.get("image")
            frame_rgb = rgb if s is None else sample_observation(
                get_likelihood(s.likelihood, s.options), rgb, noise["image"], rng, cam.depth_max)
            frame_rgb = np.clip(frame_rgb, 0.0, 1.0).astype(np.float32)
        if "depth" in modalities:
            s = model.sensors.get("depth")
            frame_depth = depth if s is None else sample_observation(
                get_likelihood(s.likelihood, s.options), depth, noise["depth"], rng, cam.depth_max)
            # A likelihood with a missing-return term marks the pixels with no return NaN.
            valid = np.isfinite(frame_depth)
            frame_depth = np.clip(frame_depth, 0.0, cam.depth_max).astype(np.float32)
        frames.append(Frame(camera=cam, rgb=frame_rgb, depth=frame_depth, depth_valid=valid))
    return frames


def scene_dict(objects, noise) -> dict[str, Any]:
    return {
        "objects": [o.as_dict() for o in objects],
        "noise": {k: {n: float(v) for n, v in p.items()} for k, p in noise.items()},
    }
