"""What cast shadows and latent lighting cost on the fast path.

    python benchmarks/shadows.py              # 128x128, 2 cameras, 6 blocks
    python benchmarks/shadows.py --size 96 --objects 8

The scene: models/blocks.scn's cubes, spheres and cylinders on its floor, seen by cameras on a
circle with RGB and depth. Four timings, each the median of --repeats runs of at least
--seconds each, with shadows off and on interleaved within a repeat (ratios are the median
of the per-repeat ratios, so a machine whose speed drifts compares like with like):
- whole: a whole hypothesis scored (``Scorer.evaluate`` with no parent);
- move: a single-object position move scored from its parent (incremental);
- relight: a hypothesis whose lighting differs from its parent's (a "render" move: whole).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sppl.data.camera import Camera, focal_from_fov, look_at
from sppl.data.observations import CameraSpec, Observations
from sppl.infer.chain import Sampler
from sppl.lang import load_model
from sppl.model.distributions import Gamma
from sppl.model.domains import Positive
from sppl.model.simulate import render_observations, sample_objects
from sppl.model.types import RENDER_GROUP, Parameter
from sppl.render import Renderer, renderer_string
from sppl.scoring.scorer import Scorer

NOISE = {"image": {"sigma": 0.05, "outlier": 0.01}, "depth": {"sigma": 0.05, "outlier": 0.01}}  # blocks.scn: mixtures


def cameras(n: int, size: int) -> list[CameraSpec]:
    f = focal_from_fov(size, 50)
    out = []
    for k in range(n):
        angle = 2 * math.pi * k / n - 0.6
        eye = (7.0 * math.cos(angle), 7.0 * math.sin(angle), 5.0)
        out.append(CameraSpec(Camera(f"c{k}", size, size, f, f, size / 2, size / 2,
                                     look_at(eye, (0.0, 0.0, 0.0)), 15.0), ("rgb", "depth")))
    return out


def setting(shadows: bool, size: int, n_cameras: int, n_objects: int, seed: int):
    model = load_model(ROOT / "models" / "blocks.scn")
    # Latent gain, so that a relight is a move of the model's own kind.
    gain = Parameter("gain", Positive(), Gamma(50.0, 0.02), 0.03)
    model = replace(model, render=replace(model.render, shadows=shadows, latent=(gain,)))
    rng = np.random.default_rng(seed)
    objects = sample_objects(model, rng)
    while len(objects) != n_objects:
        objects = sample_objects(model, rng)
    noise = {**NOISE, RENDER_GROUP: {"gain": 1.0}}
    renderer = Renderer(model.render)
    frames = render_observations(model, objects, noise, cameras(n_cameras, size), renderer, rng)
    scorer = Scorer(model, Observations(ROOT, frames), renderer)
    sampler = Sampler(model, scorer, np.random.default_rng(seed))
    trace = sampler.make_trace(objects, noise)
    return model, scorer, trace, rng


def rate(fn, seconds: float) -> float:
    """Seconds per call, over at least ``seconds``."""
    n, start = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return elapsed / n


def timings(model, scorer, trace, rng, seconds):
    from sppl.model.trace import make_object

    def whole():
        scorer.evaluate(trace.objects, None, trace.noise)

    def move():
        k = int(rng.integers(len(trace.objects)))
        o = trace.objects[k]
        values = dict(o.values, x=o.values["x"] + 0.05 * rng.standard_normal())
        moved = make_object(model, o.cls, values)
        objects = trace.objects[:k] + (moved,) + trace.objects[k + 1:]
        scorer.evaluate(objects, trace, trace.noise)

    def relight():
        noise = {**trace.noise, RENDER_GROUP: {"gain": 1.0 + 0.01 * rng.standard_normal()}}
        scorer.evaluate(trace.objects, trace, noise)

    return {name: rate(fn, seconds) for name, fn in
            (("whole", whole), ("move", move), ("relight", relight))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--cameras", type=int, default=2)
    parser.add_argument("--objects", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(f"GL renderer: {renderer_string()}")
    print(f"{args.objects} objects of blocks.scn, {args.cameras} cameras of "
          f"{args.size}x{args.size}, RGB and depth")
    paths = {s: setting(s, args.size, args.cameras, args.objects, args.seed) for s in (False, True)}
    runs = {s: [] for s in paths}
    for _ in range(args.repeats):
        for s, (model, scorer, trace, rng) in paths.items():
            runs[s].append(timings(model, scorer, trace, rng, args.seconds))
    print(f"{'':10}{'shadows off':>14}{'shadows on':>14}{'on / off':>10}  (median of "
          f"{args.repeats} repeats; ratio range)")
    for name in ("whole", "move", "relight"):
        off = statistics.median(r[name] for r in runs[False])
        on = statistics.median(r[name] for r in runs[True])
        ratios = [b[name] / a[name] for a, b in zip(runs[False], runs[True])]
        print(f"{name:10}{off * 1e3:>11.2f} ms{on * 1e3:>11.2f} ms"
              f"{statistics.median(ratios):>9.2f}x  ({min(ratios):.2f}-{max(ratios):.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
