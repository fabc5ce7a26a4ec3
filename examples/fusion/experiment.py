"""Sensor fusion: what each camera alone recovers, and both together.

    python examples/fusion/experiment.py            # about 10 minutes on two CPU cores
    python examples/fusion/experiment.py --quick    # a smoke test: a few hundred sweeps

Four objects, two cameras of different modalities (the thesis's multi-modal experiment
in miniature). The RGB camera looks along -x and a red cube hides all but the top of a blue
sphere from it (16 of its 113 pixels), so it sees the sphere's colour and little of where it
is; the depth camera looks along +y and a green cube hides a red cone from it, and a depth
camera sees no colour at all. The depth camera alone cannot get the colours or the hidden
cone; together the cameras have what it takes: the depth camera places the sphere, the RGB
camera gives its colour and shows the cone. The script simulates the observations (examples/fusion/cameras.json and
scene.json), samples the posterior three times, with the RGB camera alone, the depth camera
alone and both, prints a table of what each MAP scene got right, and draws the occupancy maps
side by side into docs/images/fusion_occupancy.png and the two views into
docs/images/fusion_cameras.png. See docs/fusion.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import sppl
from sppl import experiment

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent

CONFIGS = [("RGB camera alone", ["rgb_front"]), ("depth camera alone", ["depth_side"]),
           ("both (fusion)", ["rgb_front", "depth_side"])]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=8000, help="sweeps per chain (default 8000)")
    p.add_argument("--chains", type=int, default=2, help="chains per run (default 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="300 sweeps: checks the script runs")
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "fusion",
                   help="where observations and runs go (default runs/fusion)")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images",
                   help="where the figures go (default docs/images)")
    args = p.parse_args(argv)
    steps = 300 if args.quick else args.steps
    model = ROOT / "models" / "shapes.scn"

    obs = experiment.simulate(model, HERE / "cameras.json", HERE / "scene.json",
                              args.work / "obs", seed=1)
    truth = experiment.load_objects(obs / "scene.json")
    scene = json.loads((obs / "scene.json").read_text())
    rows, runs = [], []
    for label, cameras in CONFIGS:
        sub = experiment.camera_subset(obs, cameras, args.work / f"obs_{'_'.join(cameras)}")
        run = args.work / f"run_{'_'.join(cameras)}"
        print(f"sampling with {label}: {args.chains} chains of {steps} sweeps ...", flush=True,
              file=sys.stderr)
        summary = experiment.sample(model, sub, run, steps=steps, seed=args.seed,
                                    chains=args.chains)
        mp = summary["map"]["objects"]
        r = experiment.recovery(mp, truth, pixels=experiment.pixels_seen(model, sub, mp))
        gap = summary["map"]["score"] - experiment.log_joint(model, sub, scene)
        rows.append((label, r, gap, posterior_recovery(run, truth)))
        runs.append((label, run, sub))

    print(f"{len(truth)} true objects; an object is recovered when the MAP has one of the same "
          "class and colour within 0.15 m of it")
    header = (f"{'cameras':<20} {'recovered':>9} {'MAP count':>9} {'extra in view':>13} "
              f"{'wrong class':>11} {'wrong colour':>12} {'max pos err (m)':>15} "
              f"{'MAP - truth':>11} {'P(all)':>6} {'all':>4}")
    print(header)
    print("-" * len(header))
    for label, r, gap, p_all in rows:
        verdict = r.all_found and p_all > 0.5
        print(f"{label:<20} {f'{r.found}/{r.n_true}':>9} {r.n_estimated:>9} "
              f"{r.extra_in_view:>13} {r.wrong_class:>11} {r.wrong_category:>12} "
              f"{r.max_position_error:>15.3f} {gap:>11.1f} {p_all:>6.2f} "
              f"{'yes' if verdict else 'no':>4}")
    print(f"extra in view: MAP objects matched to no true one that the run's cameras see in "
          f"{experiment.MIN_PIXELS} pixels or more (the others stand where no camera looks, or "
          "all but a sliver hidden; the posterior keeps the prior's belief there); pixels each "
          "extra object shows in:")
    for label, r, _, _ in rows:
        print(f"  {label}: {', '.join(map(str, r.extra_pixels)) or 'none'}")
    print("P(all): the share of the samples after burn-in, all chains, that recover every true "
          "object (a MAP can land near the truth by luck where the posterior is wide)")
    print("all: the MAP recovers every true object with no extra object in view, and so do most "
          "samples (P(all) above 0.5)")
    print("MAP - truth: the MAP scene's log joint minus the true scene's, under that run's "
          "cameras (negative: the chains did not reach the mode)")
    figures(model, runs, truth, args.images, obs)
    return 0


def posterior_recovery(run: Path, truth, draws: int = 400) -> float:
    """The share of the run's samples after burn-in (pooled chains, ``draws`` evenly spaced)
    in which every true object has an estimated one of its class and colour within 0.15 m:
    how much of the posterior, not just its MAP, has the scene right."""
    from sppl import evenly, load_run, pooled_samples

    samples = evenly(pooled_samples(load_run(run)), draws)
    found = [experiment.recovery(s["objects"], truth).found == len(truth) for s in samples]
    return sum(found) / len(found) if found else 0.0


def figures(model_path, runs, truth, images: Path, obs) -> None:
    from matplotlib.figure import Figure

    from sppl import evenly, load_model, load_observations, load_run, plot_occupancy, pooled_samples

    images.mkdir(parents=True, exist_ok=True)
    model = load_model(model_path)
    cameras = load_observations(obs).cameras
    fig = Figure(figsize=(13.5, 4.6), layout="constrained")
    axes = fig.subplots(1, len(runs))
    extent = (-2.3, 3.9, -3.9, 2.3)  # the objects and both cameras
    for ax, (label, run, _) in zip(axes, runs):
        r = load_run(run)
        used = {c.name for c in load_observations(Path(r.meta["observations"])).cameras}
        im = plot_occupancy(ax, model, evenly(pooled_samples(r), 300), r.summary["map"]["objects"],
                            truth, [c for c in cameras if c.name in used], extent=extent)
        ax.set_title(label)
    fig.colorbar(im, ax=axes, label="P(covered)", shrink=0.8)
    fig.savefig(images / "fusion_occupancy.png", dpi=80)
    # The two views, observed and as the fused MAP renders them.
    label, run, sub = runs[-1]
    r = load_run(run)
    tmp = run / "figures"
    tmp.mkdir(exist_ok=True)
    views = sppl.camera_figures(model, load_observations(sub), r.summary["map"]["objects"], tmp)
    from PIL import Image

    tiles = [Image.open(tmp / v.file).convert("RGB") for v in views]
    sheet = Image.new("RGB", (max(t.width for t in tiles), sum(t.height for t in tiles)), "white")
    y = 0
    for t in tiles:
        sheet.paste(t, (0, y))
        y += t.height
    sheet = sheet.resize((sheet.width * 2 // 3, sheet.height * 2 // 3), Image.LANCZOS)
    sheet.save(images / "fusion_cameras.png")
    print(f"figures: {images / 'fusion_occupancy.png'}, {images / 'fusion_cameras.png'}")


if __name__ == "__main__":
    raise SystemExit(main())
