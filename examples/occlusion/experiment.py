"""Occlusion: one camera, three objects, one of them almost hidden behind another.

    python examples/occlusion/experiment.py            # about 4 minutes on two CPU cores
    python examples/occlusion/experiment.py --quick    # a smoke test: a few hundred sweeps

A red cube stands in front of a green cone, so that one RGB camera sees only the cone's tip
(14 of its 108 pixels); a blue sphere stands in the open. The script simulates the observation
(examples/occlusion/cameras.json and scene.json), samples the posterior with models/shapes.scn,
and asks how much mass the posterior puts on an object in the cube's shadow (the ground the
cube hides from the camera: behind it, within SHADOW_DEGREES of the ray through the hidden
cone and the camera's depth range), against the prior's mass there, and compares the log joint
of the MAP scene with that of the true scene. It prints that table and writes
docs/images/occlusion_views.png (observation, MAP render, residual) and
docs/images/occlusion_occupancy.png (the top-down occupancy map with the truth drawn over it).
See docs/occlusion.md.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

from sppl import experiment

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent

SHADOW_DEGREES = 6.0  # how far from the ray through the hidden object still counts as behind
PRIOR_DRAWS = 20000


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=8000, help="sweeps per chain (default 8000)")
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true",
                   help="300 sweeps and fewer prior draws: checks the script runs")
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "occlusion",
                   help="where the observation and the run go (default runs/occlusion)")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images",
                   help="where the figures go (default docs/images)")
    args = p.parse_args(argv)
    steps = 300 if args.quick else args.steps
    prior_draws = PRIOR_DRAWS // 10 if args.quick else PRIOR_DRAWS
    model_path = ROOT / "models" / "shapes.scn"

    obs = experiment.simulate(model_path, HERE / "cameras.json", HERE / "scene.json",
                              args.work / "obs", seed=1)
    truth = experiment.load_objects(obs / "scene.json")
    run = args.work / "run"
    print(f"sampling: {args.chains} chains of {steps} sweeps ...", file=sys.stderr, flush=True)
    summary = experiment.sample(model_path, obs, run, steps=steps, seed=args.seed,
                                chains=args.chains)

    from sppl import (
        load_model,
        load_observations,
        load_run,
        pooled_samples,
        sample_objects,
        write_report,
    )

    page = write_report(run)
    model = load_model(model_path)
    camera = load_observations(obs).cameras[0]
    front, hidden = truth[0], truth[1]
    shadow = Shadow(camera.position[:2], front, hidden, camera.depth_max)

    samples = pooled_samples(load_run(run))
    behind = [shadow.objects_in(s["objects"]) for s in samples]
    rng = np.random.default_rng(0)
    prior = [shadow.objects_in([o.as_dict() for o in sample_objects(model, rng)])
             for _ in range(prior_draws)]
    mp = summary["map"]["objects"]

    def row(label, sets, note=""):
        n = max(len(sets), 1)
        present = sum(bool(b) for b in sets) / n
        cone = sum(any(o["class"] == "cone" for o in b) for b in sets) / n
        green_cone = sum(any(o["class"] == "cone" and o["params"].get("c") == "green" for o in b)
                         for b in sets) / n
        print(f"{label:<26} {present:>12.3f} {cone:>10.3f} {green_cone:>16.3f}  {note}")

    print(f"the cube's shadow: the ground behind the red cube, seen from the camera, within "
          f"{SHADOW_DEGREES:g} degrees of the ray through the hidden cone and "
          f"{shadow.far:g} m of the camera")
    print(f"{'':<26} {'P(object in':>12} {'P(a cone':>10} {'P(a green cone':>16}")
    print(f"{'':<26} {'the shadow)':>12} {'there)':>10} {'there)':>16}")
    row("prior", prior, f"({prior_draws} draws from the model's prior)")
    row("posterior", behind, f"({len(samples)} samples, {args.chains} chains after burn-in)")
    row("MAP scene", [shadow.objects_in(mp)])
    cones = [o for b in behind for o in b if o["class"] == "cone"]
    if cones:
        d = np.array([shadow.distance(o) for o in cones])
        print(f"distance from the camera of the cone in the shadow: posterior mean "
              f"{d.mean():.2f} m, sd {d.std():.2f} m (true {shadow.distance(hidden):.2f} m)")
    print("posterior over the number of objects: "
          + ", ".join(f"{k}: {v:.2f}" for k, v in summary["n_objects"].items()))
    true_lj = experiment.log_joint(model_path, obs, json.loads((obs / "scene.json").read_text()))
    print(f"log joint: MAP scene {summary['map']['score']:.1f}, true scene {true_lj:.1f}"
          + ("  (the truth scores higher: the chains did not reach the posterior's mode)"
             if true_lj > summary["map"]["score"] else ""))

    args.images.mkdir(parents=True, exist_ok=True)
    shutil.copy(page.parent / "camera_rgb.png", args.images / "occlusion_views.png")
    occupancy_figure(model, samples, mp, truth, [camera], shadow,
                     args.images / "occlusion_occupancy.png")
    print(f"report: {page}")
    print(f"figures: {args.images}/occlusion_{{views,occupancy}}.png")
    return 0


class Shadow:
    """The ground behind ``front`` as seen from ``eye`` (x, y), near the ray to ``hidden``."""

    def __init__(self, eye, front, hidden, far: float) -> None:
        self.eye = np.asarray(eye, dtype=float)
        self.far = far
        self.ray = self._xy(hidden) - self.eye
        self.ray /= np.linalg.norm(self.ray)
        self.beyond = float(np.linalg.norm(self._xy(front) - self.eye)) + 0.3

    @staticmethod
    def _xy(o) -> np.ndarray:
        return np.array([o["params"]["x"], o["params"]["y"]], dtype=float)

    def distance(self, o) -> float:
        return float(np.linalg.norm(self._xy(o) - self.eye))

    def contains(self, o) -> bool:
        v = self._xy(o) - self.eye
        d = float(np.linalg.norm(v))
        angle = np.degrees(np.arccos(np.clip(v @ self.ray / max(d, 1e-9), -1, 1)))
        return self.beyond < d < self.far and angle <= SHADOW_DEGREES

    def objects_in(self, objects) -> list:
        return [o for o in objects if self.contains(o)]


def occupancy_figure(model, samples, map_objects, truth, cameras, shadow, path) -> None:
    from matplotlib.figure import Figure

    from sppl import evenly, plot_occupancy

    fig = Figure(figsize=(7.0, 4.8), layout="constrained")
    ax = fig.subplots()
    im = plot_occupancy(ax, model, evenly(samples, 400), map_objects, truth, cameras,
                        extent=(-4.5, 4.0, -3.0, 3.0))
    # The shadow wedge the table counts in.
    for sign in (-1, 1):
        t = np.radians(sign * SHADOW_DEGREES)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        r = rot @ shadow.ray
        a, b = shadow.eye + shadow.beyond * r, shadow.eye + shadow.far * r
        ax.plot([a[0], b[0]], [a[1], b[1]], color="#9467bd", lw=1, ls="-.")
    ax.set_xlim(-4.5, 4.0)
    ax.set_ylim(-3.0, 3.0)
    fig.colorbar(im, ax=ax, label="P(covered)", shrink=0.8)
    fig.savefig(path, dpi=80)


if __name__ == "__main__":
    raise SystemExit(main())
