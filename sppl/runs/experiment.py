"""Small building blocks for scripted experiments (the ones in ``examples/``): simulate a
known scene, sample it, split an observation folder by camera, and score the result against
the truth.

Each function does what the command of the same name does, from Python, without printing.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..output.compare import TOLERANCE, compare_scenes, match_objects


def simulate(model_path: str | Path, cameras: str | Path, scene: str | Path, out: str | Path,
             *, seed: int = 0) -> Path:
    """``sppl simulate MODEL --cameras CAMERAS --scene SCENE --out OUT --seed SEED --force``."""
    from ..data.observations import load_cameras, write_observations
    from ..lang import load_model
    from ..model.simulate import load_scene, render_observations, sample_noise, scene_dict
    from ..render import Renderer

    model = load_model(model_path)
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    objects, noise = load_scene(model, scene)
    noise = noise or sample_noise(model, rng)
    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    renderer = Renderer(model.render)
    try:
        frames = render_observations(model, objects, noise, load_cameras(cameras), renderer, rng)
    finally:
        renderer.release()
    write_observations(out, frames)
    (out / "scene.json").write_text(json.dumps(scene_dict(objects, noise), indent=2) + "\n")
    return out


def camera_subset(obs: str | Path, names: Sequence[str], out: str | Path) -> Path:
    """A copy of an observation folder with only the named cameras (and its scene.json)."""
    from ..data.observations import load_observations, write_observations

    observations = load_observations(obs)
    frames = [f for f in observations.frames if f.name in names]
    missing = set(names) - {f.name for f in frames}
    if missing:
        raise ValueError(f"{obs} has no camera {', '.join(sorted(missing))}")
    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    write_observations(out, frames)
    truth = Path(obs) / "scene.json"
    if truth.exists():
        shutil.copy(truth, out / "scene.json")
    return out


def sample(model_path: str | Path, obs: str | Path, out: str | Path, *, steps: int,
           seed: int = 0, chains: int = 1) -> dict[str, Any]:
    """``sppl sample MODEL --obs OBS --out OUT --steps STEPS --seed SEED --chains N --force``,
    without a progress bar; returns the run's summary."""
    from ..data.observations import load_observations
    from ..lang import load_model
    from ..output.posterior import write_posterior
    from .chains import run_chains

    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    result = run_chains(load_model(model_path), load_observations(obs), out, chains=chains,
                        steps=steps, seed=seed, progress=False)
    write_posterior(out)
    return result.summary


@dataclass(frozen=True)
class Recovery:
    """How many true objects a scene estimate recovered: matched (optimal assignment by ground
    position) within ``tolerance`` metres, with the right class and categories (colours).
    ``extra_in_view``: estimated objects matched to no true one that some camera sees, in
    at least ``MIN_PIXELS`` pixels (all of them when the estimate was not checked against
    cameras); ``extra_pixels``: how many pixels each extra object shows in."""

    found: int
    n_true: int
    n_estimated: int
    wrong_class: int
    wrong_category: int
    max_position_error: float
    extra_in_view: int
    extra_pixels: tuple[int, ...] = ()

    @property
    def all_found(self) -> bool:
        """Every true object recovered, and nothing more that a camera could see. Objects
        no camera sees (out of every view, or hidden behind others but for a sliver of a few
        pixels) are left out: the observations say next to nothing about them, so the
        posterior keeps the prior's belief there."""
        return self.found == self.n_true and self.extra_in_view == 0


MIN_PIXELS = 10  # an object showing in fewer pixels than this counts as unseen


def recovery(estimate: Sequence[dict], truth: Sequence[dict], tolerance: float = TOLERANCE,
             *, pixels: Sequence[int] | None = None) -> Recovery:
    """``pixels``: for each estimated object, how many pixels it shows in (``pixels_seen``);
    without it every extra object counts as seen."""
    errors = compare_scenes(estimate, truth)
    found = 0
    matched = set()
    for e, t, _ in match_objects(estimate, truth, max_distance=tolerance):
        matched.add(e)
        est, true = estimate[e], truth[t]
        cats = {k: v for k, v in true["params"].items() if isinstance(v, str)}
        same_categories = all(est["params"].get(k) == v for k, v in cats.items())
        if est["class"] == true["class"] and same_categories:
            found += 1
    extra = [e for e in range(len(estimate)) if e not in matched]
    in_view = sum(1 for e in extra if pixels is None or pixels[e] >= MIN_PIXELS)
    return Recovery(found, errors.n_true, errors.n_estimated, errors.wrong_class,
                    errors.wrong_category, errors.max_position_error, in_view,
                    tuple(pixels[e] for e in extra) if pixels is not None else ())


def pixels_seen(model_path: str | Path, obs: str | Path, objects: Sequence[dict]) -> list[int]:
    """For each object of a scene, the number of pixels of the observation folder's cameras
    (RGB and depth alike) whose rendering changes when that object is taken out of the scene:
    0 for an object out of every view or hidden behind the others."""
    from ..data.observations import load_observations
    from ..lang import load_model
    from ..model.simulate import objects_from_dict
    from ..render import Renderer

    model = load_model(model_path)
    cameras = load_observations(obs).cameras
    scene = objects_from_dict(model, {"objects": list(objects)})
    renderer = Renderer(model.render)
    try:
        def draw(kept):
            parts = [*model.static_parts, *(p for o in kept for p in o.parts)]
            return [renderer.render(parts, camera) for camera in cameras]

        full = draw(scene)
        counts = []
        for i in range(len(scene)):
            without = draw(scene[:i] + scene[i + 1:])
            changed = 0
            for (rgb, depth), (rgb2, depth2) in zip(full, without):
                diff = np.any(np.abs(rgb - rgb2) > 1e-6, axis=-1) | (np.abs(depth - depth2) > 1e-6)
                changed += int(diff.sum())
            counts.append(changed)
        return counts
    finally:
        renderer.release()


def load_objects(path: str | Path) -> list[dict[str, Any]]:
    return json.loads(Path(path).read_text())["objects"]


def log_joint(model_path: str | Path, obs: str | Path, scene: dict[str, Any]) -> float:
    """The log joint (a trace's score) of a scene, ``{"objects": [...], "noise": {...}}``,
    given an observation folder: what a chain's MAP should at least reach when the scene is
    the truth (if the truth scores higher, the chains have not found the posterior's mode)."""
    from ..data.observations import load_observations
    from ..infer.chain import Sampler
    from ..lang import load_model
    from ..model.simulate import objects_from_dict
    from ..render import Renderer
    from ..scoring.scorer import Scorer

    model = load_model(model_path)
    renderer = Renderer(model.render)
    try:
        sampler = Sampler(model, Scorer(model, load_observations(obs), renderer),
                          np.random.default_rng(0))
        return float(sampler.make_trace(objects_from_dict(model, scene), scene["noise"]).score)
    finally:
        renderer.release()
