"""One object, one RGB camera: sampling, the MAP against the truth, and what one view leaves open.

    python examples/single_object/experiment.py            # about 4 minutes on two CPU cores
    python examples/single_object/experiment.py --quick    # a smoke test: a few hundred sweeps

The thesis's first experiment: a red cube seen by a single RGB camera (32x32 pixels, low and
looking almost level, so that where the cube stands on the ground says little about how far
away it is). The script simulates the observation (examples/single_object/cameras.json and
scene.json), samples the posterior with the full three-class model (models/shapes.scn, with
smaller random-walk steps: fine.scn), prints the MAP scene against the truth, how the
posterior spreads along and across the camera's line of sight, and the acceptance rate of each
move, and writes four figures to docs/images/: single_object_views.png (observation, MAP
render, residual), single_object_traces.png (the chains' log joint, number of objects and
noise scale, sweep by sweep), single_object_ambiguity.png (size against distance along the
viewing ray) and single_object_acceptance.png.
See docs/single_object.md.
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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=6000, help="sweeps per chain (default 6000)")
    p.add_argument("--chains", type=int, default=4, help="chains (default 4)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="300 sweeps: checks the script runs")
    p.add_argument("--model", type=Path, default=HERE / "fine.scn",
                   help="the model to sample with (default: shapes.scn with smaller steps, "
                   "examples/single_object/fine.scn)")
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "single_object",
                   help="where the observation and the run go (default runs/single_object)")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images",
                   help="where the figures go (default docs/images)")
    args = p.parse_args(argv)
    steps = 300 if args.quick else args.steps
    model_path = args.model

    obs = experiment.simulate(ROOT / "models" / "shapes.scn", HERE / "cameras.json",
                              HERE / "scene.json", args.work / "obs", seed=1)
    truth = experiment.load_objects(obs / "scene.json")
    run = args.work / "run"
    print(f"sampling: {args.chains} chains of {steps} sweeps ...", file=sys.stderr, flush=True)
    summary = experiment.sample(model_path, obs, run, steps=steps, seed=args.seed,
                                chains=args.chains)

    from sppl import load_observations, load_run, write_report

    page = write_report(run)
    camera = load_observations(obs).cameras[0]
    true_obj = truth[0]
    mp = summary["map"]["objects"]

    # The MAP against the truth.
    r = experiment.recovery(mp, truth)
    print(f"MAP scene: {len(mp)} object(s): "
          + "; ".join(f"{o['class']} {fmt(o['params'])}" for o in mp))
    print(f"truth:     1 object:   {true_obj['class']} {fmt(true_obj['params'])}")
    print(f"recovered {r.found}/{r.n_true} (class, colour and position within 0.15 m); "
          f"position error {r.max_position_error:.3f} m", end="")
    if mp and mp[0]["class"] == true_obj["class"]:
        print(f"; size error {mp[0]['params']['s'] - true_obj['params']['s']:+.3f} m")
    else:
        print()
    print("posterior over the number of objects: "
          + ", ".join(f"{k}: {v:.2f}" for k, v in summary["n_objects"].items()))

    # What one view leaves open: distance along the ray against size, chain by chain (a chain
    # stuck in a worse explanation would otherwise pass for posterior spread).
    centre = camera.position
    forward = -camera.c2w[:3, 2]
    side = np.cross(forward, [0, 0, 1.0])
    side /= np.linalg.norm(side)

    def along_across(o):
        q = o["params"]
        c = np.array([q["x"], q["y"], q["s"] / 2]) - centre
        return float(np.linalg.norm(c)), float(c @ side)

    runfiles = load_run(run)
    burn = runfiles.burn
    best = max(chain.summary["map"]["score"] for chain in runfiles.chains)
    chains = []
    for i, chain in enumerate(runfiles.chains):
        kept = [x for x in chain.samples if x["step"] >= burn]
        matched = on_the_ray(kept, true_obj, centre)
        chains.append({
            "index": i, "score": chain.summary["map"]["score"], "samples": len(kept),
            "d": np.array([along_across(o)[0] for _, o in matched]),
            "lateral": np.array([along_across(o)[1] for _, o in matched]),
            "size": np.array([o["params"]["s"] for _, o in matched]),
            # A sample is in the main mode when its log joint is near the best any chain found.
            "main": np.array([score > best - MODE_NATS for score, _ in matched], dtype=bool),
        })
    d_true = along_across(true_obj)[0]
    print(f"per chain, after burn-in: the cube on the camera's ray through the true one (within "
          f"{RAY_DEGREES:g} degrees); true distance {d_true:.3f} m, side {true_obj['params']['s']}")
    print(f"{'chain':>5} {'MAP log joint':>13} {'in main mode':>12} {'distance (m)':>15} "
          f"{'across sd':>9} {'side s (m)':>15} {'corr(s, dist)':>13}")
    for c in chains:
        share = f"{c['main'].mean():.1%}" if len(c["main"]) else "-"
        head = f"{c['index']:>5} {c['score']:>13.1f} {share:>12}"
        m = c["main"]
        if m.sum() > 2:
            print(f"{head} {c['d'][m].mean():>7.3f} ± {c['d'][m].std():.3f} "
                  f"{c['lateral'][m].std():>9.3f} {c['size'][m].mean():>7.3f} ± "
                  f"{c['size'][m].std():.3f} {np.corrcoef(c['size'][m], c['d'][m])[0, 1]:>+13.2f}")
        elif len(c["d"]):
            print(f"{head}   elsewhere: {c['d'].mean():.3f} m away, side {c['size'].mean():.3f} m")
        else:
            print(f"{head}   no cube on that ray")
    true_lj = experiment.log_joint(model_path, obs, json.loads((obs / "scene.json").read_text()))
    print(f"main mode: samples whose log joint is within {MODE_NATS:g} nats of the best MAP "
          f"({best:.1f}); the columns after it are over those samples; the true scene's log "
          f"joint is {true_lj:.1f}")

    print("acceptance rate per move (all chains): "
          + ", ".join(f"{m}: {a['rate']:.3f}" for m, a in summary["acceptance"].items()))

    args.images.mkdir(parents=True, exist_ok=True)
    shutil.copy(page.parent / "camera_rgb.png", args.images / "single_object_views.png")
    shutil.copy(page.parent / "acceptance.png", args.images / "single_object_acceptance.png")
    shutil.copy(page.parent / "traces.png", args.images / "single_object_traces.png")
    ambiguity_figure(args.images / "single_object_ambiguity.png", chains, d_true, true_obj)
    print(f"report: {page}")
    print(f"figures: {args.images}/single_object_{{views,traces,ambiguity,acceptance}}.png")
    return 0


MODE_NATS = 50.0
RAY_DEGREES = 3.0


def _direction(o, centre):
    q = o["params"]
    v = np.array([q["x"], q["y"], q["s"] / 2]) - centre
    return v / np.linalg.norm(v)


def on_the_ray(samples, true_obj, centre):
    """Each sample's cube seen in the direction of the true cube, whatever its distance: the
    nearest to the camera of its cubes within RAY_DEGREES of that direction (one farther
    along the ray would be hidden behind it)."""
    ray = _direction(true_obj, centre)
    out = []  # (the sample's log joint, the cube)
    for s in samples:
        best, best_distance = None, np.inf
        for o in s["objects"]:
            if o["class"] != true_obj["class"]:
                continue
            angle = np.degrees(np.arccos(np.clip(_direction(o, centre) @ ray, -1, 1)))
            q = o["params"]
            distance = np.linalg.norm(np.array([q["x"], q["y"], q["s"] / 2]) - centre)
            if angle <= RAY_DEGREES and distance < best_distance:
                best, best_distance = o, distance
        if best is not None:
            out.append((s["score"], best))
    return out


def fmt(params) -> str:
    return ", ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in params.items())


def ambiguity_figure(path, chains, d_true, true_obj) -> None:
    from matplotlib.figure import Figure

    from sppl import CHAIN_COLOURS

    fig = Figure(figsize=(9.5, 3.8), layout="constrained")
    ax0, ax1 = fig.subplots(1, 2)
    s_true = true_obj["params"]["s"]
    main = [c for c in chains if c["main"].any()]
    for c in main:
        m = c["main"]
        ax0.scatter(c["d"][m], c["size"][m], s=3, alpha=0.3, color=CHAIN_COLOURS[c["index"]],
                    label=f"chain {c['index']}")
    if main:
        d_all = np.concatenate([c["d"][c["main"]] for c in main])
        ds = np.linspace(min(d_all.min(), d_true) - 0.02, max(d_all.max(), d_true) + 0.02, 20)
        ax0.plot(ds, s_true * ds / d_true, color="grey", ls=":", label="same size in the image")
    ax0.plot(d_true, s_true, "*", color="#d62728", ms=12, label="truth")
    ax0.set_xlabel("distance from the camera along its ray (m)")
    ax0.set_ylabel("cube side s (m)")
    ax0.set_title("samples in the main mode, every chain", fontsize=10)
    _legend(ax0)
    for c in chains:
        if len(c["d"]):
            ax1.scatter(c["lateral"], c["d"], s=3, alpha=0.3, color=CHAIN_COLOURS[c["index"]],
                        label=f"chain {c['index']} (MAP {c['score']:.0f}; "
                        f"{c['main'].mean():.0%} in the main mode)")
    ax1.plot(0.0, d_true, "*", color="#d62728", ms=12)
    ax1.set_xlabel("across the ray (m)")
    ax1.set_ylabel("along the ray (m)")
    ax1.set_title("every chain: the cube's centre from above, after burn-in", fontsize=10)
    _legend(ax1, loc="upper left")
    fig.savefig(path, dpi=80)


def _legend(ax, loc: str = "best") -> None:
    """A legend whose scatter dots are big enough to see the colour (the star stays as is)."""
    legend = ax.legend(fontsize=7, frameon=False, loc=loc)
    for handle in legend.legend_handles:
        if hasattr(handle, "set_sizes"):
            handle.set_sizes([16])
            handle.set_alpha(1)


if __name__ == "__main__":
    raise SystemExit(main())
