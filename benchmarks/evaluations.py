"""Likelihood evaluations per second: sppl's fast path against the reference path and the
thesis's renderer (Panda3D), and the memory floor.

    python benchmarks/evaluations.py              # the full grid: K x cameras x pixels
    python benchmarks/evaluations.py --quick      # 128x128, 2 cameras, K=3 only

Scenes are the cubes, cones and spheres of models/shapes.scn on a grid, seen by cameras on a
circle, every camera recording RGB and depth (Gaussian likelihood over every pixel). Paths:
- reference: render each camera, read colour and depth back, score in numpy (ReferenceScorer);
- fast: sppl's Scorer, per-pixel terms on the GL side, one whole hypothesis per call;
- batch: the same, 16 hypotheses in one call (Scorer.evaluate_many);
- panda3d: the thesis's renderer, Panda3D offscreen through EGL, colour and depth read back
  and scored in numpy (skipped with a message when panda3d cannot be imported); on Mesa's
  llvmpipe twice, as llvmpipe runs by default (a rasteriser thread per core) and as sppl runs
  it (``panda3d, LP 0``: LP_NUM_THREADS=0, rasterising on the calling thread), so that
  neither renderer is compared at a setting the other does not get;
- incremental: a single-object parameter move scored from the current state
  (Scorer.evaluate with the parent trace), against full rescoring by each path.
Then, at the same setting, the fast path with each sensor likelihood (``likelihoods``): the
Gaussian, the inlier/outlier mixture and Student-t on both sensors (sppl/model/robust.py), a whole
scene and a single-object move each, interleaved, and each robust one's time against the
Gaussian's; and a noise move, which for the robust ones re-runs the terms pass over the whole
scene (for the Gaussian it costs nothing: its statistics are sufficient).
The memory floor is the time to read the observation arrays once (a sum over each).

Every rate is the median of --repeats runs of at least --seconds each. The paths run
interleaved within a repeat, and each ratio is the median over the repeats of the ratio
measured within one repeat (its range is printed too): on a shared machine whose speed drifts
by tens of percent from one second to the next, that compares like with like. The GL renderer
in use is printed first: on a machine with a GPU the same command gives the GPU figure. So is
whether the fast path's compiled kernels run (``SPPL_PURE_PYTHON=1`` runs their Python twins).
"""

from __future__ import annotations

import argparse
import itertools
import math
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import panda3d_path  # noqa: E402

from sppl.data.camera import Camera, focal_from_fov, look_at  # noqa: E402
from sppl.data.observations import CameraSpec, Observations  # noqa: E402
from sppl.infer.chain import Sampler  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.model.distributions import Beta, Gamma  # noqa: E402
from sppl.model.domains import Interval, Positive  # noqa: E402
from sppl.model.simulate import render_observations  # noqa: E402
from sppl.model.trace import make_object  # noqa: E402
from sppl.model.types import Parameter, Sensor  # noqa: E402
from sppl.render import Renderer, kernels, renderer_string  # noqa: E402
from sppl.scoring.scorer import ReferenceScorer, Scorer  # noqa: E402

NOISE = {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}}
# The robust likelihoods compared with the Gaussian: (model file's likelihood, options, the
# extra noise parameters' (domain, prior), noise values).
LIKELIHOODS = {
    "gaussian": ("gaussian", {}, {}, {"sigma": 0.05}),
    "mixture": ("mixture", {}, {"outlier": (Interval(0.0, 1.0), Beta(1.0, 20.0))},
                {"sigma": 0.05, "outlier": 0.05}),
    "student_t": ("student_t", {}, {"nu": (Positive(), Gamma(4.0, 1.0))},
                  {"sigma": 0.05, "nu": 3.0}),
}
BATCH = 16
MOVES = 32


def scene(model, k: int, rng):
    """k objects (cube, cone, sphere in turn) on a grid 1.2 m apart, centred on the origin."""
    side = math.ceil(math.sqrt(k))
    objects = []
    palette = ("red", "green", "blue")
    for i in range(k):
        cls = model.classes[i % 3]
        x, y = (i % side - (side - 1) / 2) * 1.2, (i // side - (side - 1) / 2) * 1.2
        values = {"x": x + rng.uniform(-0.1, 0.1), "y": y + rng.uniform(-0.1, 0.1),
                  "c": palette[i % 3]}
        for p in cls.parameters:
            if p.name not in values:
                values[p.name] = {"a": 0.3, "s": 0.6, "r": 0.35, "h": 0.8}[p.name]
        objects.append(make_object(model, cls, values))
    return tuple(objects), side * 1.2


def cameras(n: int, size: int, extent: float):
    f = focal_from_fov(size, 55)
    radius = 2.0 + 1.3 * extent
    out = []
    for i in range(n):
        angle = 2 * math.pi * i / n + 0.4
        eye = (radius * math.cos(angle), radius * math.sin(angle), 0.8 * radius)
        out.append(Camera(f"c{i}", size, size, f, f, size / 2, size / 2,
                          look_at(eye, (0, 0, 0.3)), depth_max=3 * radius))
    return out


def rate(fn, per_call: int, seconds: float) -> float:
    """Evaluations per second of one run lasting at least ``seconds``."""
    calls, start = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return calls * per_call / elapsed


class Rates(dict):
    """Median rate per path, with every repeat's rates kept for the ratios."""

    def __init__(self, runs: dict[str, list[float]]) -> None:
        super().__init__({name: statistics.median(r) for name, r in runs.items()})
        self.runs = runs

    def ratio(self, a: str, b: str) -> tuple[float, float, float]:
        """How many times faster a is than b: the median over the repeats of the ratio within
        each repeat, and the smallest and largest of those."""
        within = [x / y for x, y in zip(self.runs[a], self.runs[b])]
        return statistics.median(within), min(within), max(within)


def measure(paths: dict, repeats: int, seconds: float) -> Rates:
    """Rates of each path; a path given as (None, remote) is measured by ``remote(seconds)``."""
    for fn, per in paths.values():  # warm up: shaders, buffers, caches
        for _ in range(3 if fn is not None else 0):
            fn()
    runs = {name: [] for name in paths}
    for _ in range(repeats):
        for name, (fn, per) in paths.items():
            runs[name].append(rate(fn, per, seconds) if fn is not None else per(seconds))
    return Rates(runs)


def times(ratio: tuple[float, float, float]) -> str:
    median, low, high = ratio
    return f"{median:.2f}x, {low:.2f} to {high:.2f}"


def setting(model, renderer, k, n_cameras, size, rng):
    objects, extent = scene(model, k, rng)
    cams = cameras(n_cameras, size, extent)
    frames = render_observations(model, objects, NOISE, [CameraSpec(c) for c in cams],
                                 renderer, rng)
    return objects, cams, Observations(ROOT, frames)


def scorers(model, renderer, cams, obs, pandas):
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    assert fast.pixels is not None
    for panda in pandas.values():
        panda.setup(model.render, cams, [(f.rgb, f.depth) for f in obs.frames])
    return fast, ref


def remote(panda, hypotheses):
    return None, lambda seconds: panda.rate(hypotheses, seconds)


def full_paths(model, renderer, objects, cams, obs, pandas):
    fast, ref = scorers(model, renderer, cams, obs, pandas)
    batch = [objects] * BATCH
    paths = {
        "reference": (lambda: ref.evaluate(objects), 1),
        "fast": (lambda: fast.evaluate(objects), 1),
        f"batch {BATCH}": (lambda: fast.evaluate_many(batch), BATCH),
    }
    parts = fast.parts(objects)
    for name, panda in pandas.items():
        paths[name] = remote(panda, [parts])
    return paths


def move_sequence(model, objects, rng):
    """MOVES single-object parameter moves of object 0, as a chain's drift would make them."""
    obj = objects[0]
    out = []
    for _ in range(MOVES):
        values = dict(obj.values)
        values["x"] += rng.normal(0, 0.05)
        values["y"] += rng.normal(0, 0.05)
        out.append((make_object(model, obj.cls, values),) + objects[1:])
    return out


def anew(objects):
    """The objects, the first with what sppl worked out from it forgotten (as for a new
    object: a chain proposes one at every move), without the cost of making one."""
    objects[0].cache.clear()
    return objects


def with_likelihood(model, name):
    """The model with both sensors' likelihood replaced by LIKELIHOODS[name], and its noise."""
    likelihood, options, extra, values = LIKELIHOODS[name]
    sensors = {}
    for kind, sensor in model.sensors.items():
        noise = (*sensor.noise, *(Parameter(p, d, prior, 0.05) for p, (d, prior) in extra.items()))
        sensors[kind] = Sensor(kind, likelihood, noise, options)
    return replace(model, sensors=sensors), {kind: dict(values) for kind in sensors}


def likelihood_paths(model, renderer, objects, obs, moves):
    """Per likelihood: a whole scene, a single-object move and a noise move on the fast
    path, as (paths, scorers)."""
    paths = {}
    for name in LIKELIHOODS:
        variant, noise = with_likelihood(model, name)
        fast = Scorer(variant, obs, renderer)
        assert fast.pixels is not None
        state = Sampler(variant, fast, np.random.default_rng(1)).make_trace(objects, noise)
        other = {k: {p: v * 1.01 for p, v in n.items()} for k, n in noise.items()}
        paths[f"whole scene ({name})"] = (
            lambda f=fast, n=noise: f.evaluate(anew(objects), noise=n), 1)
        paths[f"move ({name})"] = (
            lambda f=fast, s=state: [f.evaluate(anew(m), parent=s) for m in moves], MOVES)
        paths[f"noise move ({name})"] = (lambda f=fast, s=state, o=other: f.rescore(s, o), 1)
    return paths


def memory_floor(obs) -> float:
    arrays = [a for f in obs.frames for a in (f.rgb, f.depth) if a is not None]
    return lambda: [a.sum() for a in arrays]


def table(title, header, rows):
    print(f"\n### {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---:" if i else "---" for i in range(len(header))) + "|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only 128x128, 2 cameras, K=3")
    ap.add_argument("--objects", type=int, nargs="+", default=[1, 3, 10, 30])
    ap.add_argument("--cameras", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--pixels", type=int, nargs="+", default=[64, 128, 256])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=0.3, help="length of one run")
    args = ap.parse_args(argv)
    if args.quick:
        args.objects, args.cameras, args.pixels = [3], [2], [128]

    # The Gaussian on both sensors, as the paths above describe (the shipped shapes.scn scores
    # depth with a mixture, which the likelihood table below compares).
    model, _ = with_likelihood(load_model(ROOT / "models" / "shapes.scn"), "gaussian")
    renderer = Renderer(model.render)
    print(f"GL renderer: {renderer_string()}")
    print(f"Per-move code: {kernels.describe()}")
    why_not = panda3d_path.available()
    pandas = {}
    if why_not is None:
        pandas["panda3d"] = panda3d_path.Worker()
        if "llvmpipe" in renderer_string():
            pandas["panda3d, LP 0"] = panda3d_path.Worker(lp_threads="0")
    else:
        print(f"panda3d path skipped: {why_not}")
    rng = np.random.default_rng(0)

    # -- full-scene scoring over the grid -----------------------------------------------------
    names = ["reference", "fast", f"batch {BATCH}", *pandas]
    rows, focus = [], None
    for k, n_cam, size in itertools.product(args.objects, args.cameras, args.pixels):
        objects, cams, obs = setting(model, renderer, k, n_cam, size, rng)
        paths = full_paths(model, renderer, objects, cams, obs, pandas)
        r = measure(paths, args.repeats, args.seconds)
        row = [str(k), str(n_cam), f"{size}"]
        for name in names:
            ratio = "" if name == "fast" else f" ({times(r.ratio('fast', name))})"
            row.append(f"{r[name]:,.0f}{ratio}")
        rows.append(row)
        if (k, n_cam, size) == (3, 2, 128) or focus is None:
            focus = (k, n_cam, size, objects, cams, obs, r)
    table("Full-scene scoring: evaluations per second (fast path's speed-up over each path)",
          ["K", "cameras", "pixels", *names], rows)

    # -- incremental single-object moves and the memory floor, at the focus setting -----------
    k, n_cam, size, objects, cams, obs, full = focus
    fast, ref = scorers(model, renderer, cams, obs, pandas)
    sampler = Sampler(model, fast, np.random.default_rng(1))
    state = sampler.make_trace(objects, NOISE)
    moves = move_sequence(model, objects, rng)
    move_parts = [fast.parts(m) for m in moves]
    # Every evaluation works the moved object out anew, as for the new object a chain proposes
    # at every move: what sppl derives per object (its instance rows and screen rectangles)
    # is part of the evaluation, as setting its node's matrix is part of Panda3D's.
    paths = {
        "incremental (fast)": (lambda: [fast.evaluate(anew(m), parent=state) for m in moves],
                               MOVES),
        "full (fast)": (lambda: [fast.evaluate(anew(m)) for m in moves], MOVES),
        "reference": (lambda: [ref.evaluate(m) for m in moves], MOVES),
        **{name: remote(panda, move_parts) for name, panda in pandas.items()},
        "memory floor": (memory_floor(obs), 1),
    }
    r = measure(paths, args.repeats, args.seconds)
    table(f"Single-object parameter moves, K={k}, {n_cam} cameras, {size}x{size}: "
          "evaluations per second (incremental path's speed-up over each: the median of the "
          "repeats' ratios, and their range)",
          ["path", "evals/s", "incremental is"],
          [[name, f"{v:,.0f}",
            "" if name.startswith("incremental") else times(r.ratio("incremental (fast)", name))]
           for name, v in r.items()])
    # -- each likelihood on the fast path, same setting ---------------------------------------
    lr = measure(likelihood_paths(model, renderer, objects, obs, moves), args.repeats,
                 args.seconds)
    rows = []
    for what in ("whole scene", "move", "noise move"):
        for name in LIKELIHOODS:
            path = f"{what} ({name})"
            # Time per evaluation relative to the Gaussian's: the Gaussian's rate over this.
            vs = "" if name == "gaussian" or what == "noise move" else \
                times(lr.ratio(f"{what} (gaussian)", path))
            rows.append([what, name, f"{lr[path]:,.0f}", vs])
    table(f"Each likelihood on the fast path, K={k}, {n_cam} cameras, {size}x{size}: "
          "evaluations per second, and the time of one against the Gaussian's (median of the "
          "repeats' ratios, and their range)", ["evaluation", "likelihood", "evals/s",
                                                "time vs Gaussian"], rows)
    floor = r["memory floor"]
    print(f"\nMemory floor (reading the observations once): {floor:,.0f} per second; "
          f"the fast path is {floor / full['fast']:.1f}x from it on full scenes, "
          f"{floor / full[f'batch {BATCH}']:.1f}x batched and "
          f"{r.ratio('memory floor', 'incremental (fast)')[0]:.1f}x incrementally.")
    for panda in pandas.values():
        panda.close()


if __name__ == "__main__":
    main()
