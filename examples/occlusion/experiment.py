"""Occlusion: one camera, three objects, one of them almost hidden behind another.

    python examples/occlusion/experiment.py            # about ten minutes on two shared cores
    python examples/occlusion/experiment.py --tempered 1 --steps 8000   # shapes.scn as shipped
    python examples/occlusion/experiment.py --quick    # a smoke test: a few hundred sweeps

A red cube stands in front of a green cone, so that one RGB camera sees only the cone's tip
(14 of its 110 pixels); a blue sphere stands in the open. The script simulates the observation
(examples/occlusion/cameras.json and scene.json), samples the posterior with models/shapes.scn,
by default with parallel tempering added to its inference block (--tempered, --tempered-from),
and asks how much mass the posterior puts on an object in the cube's shadow (the ground the
cube hides from the camera: behind it, within SHADOW_DEGREES of the ray through the hidden
cone and the camera's depth range), against the prior's mass there; where along the camera's
ray the posterior puts the hidden cone; and, from a likelihood profile, which distances the
image allows: the log joint of the MAP scene, and of the true scene, with the hidden cone
replaced by cones that show the same tip from farther or nearer (shadow.py). It compares the
log joint of the MAP scene with that of the true scene, prints all that, and writes
docs/images/occlusion_views.png (observation, MAP render, residual),
docs/images/occlusion_occupancy.png (the top-down occupancy map with the truth drawn over it)
and docs/images/occlusion_profile.png (the profile and the posterior's distances).
See docs/occlusion.md.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

import numpy as np
from shadow import (
    ALLOWED_NATS,
    SHADOW_DEGREES,
    Shadow,
    allowed,
    along_ray,
    profile,
    profile_distances,
)

from sppl import experiment

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent

PRIOR_DRAWS = 20000
PRINT_EVERY = 25  # the printed profile shows every 25th distance the figure draws (50 cm)
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)


def tempered_model(model_path: Path, rungs: int, hottest: float, out: Path) -> Path:
    """A copy of the model file with parallel tempering set in its inference block (every
    other setting as in the file), written to ``out``; the chains, which compile the model in
    their own processes, read it from there."""
    source = model_path.read_text()
    block = re.compile(r"^inference\s*\{[^\S\n]*$", re.M)
    if len(block.findall(source)) != 1 or re.search(r"^\s*tempered", source, re.M):
        raise SystemExit(f"error: {model_path} needs one inference block, without tempering, "
                         "for --tempered to add it")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(block.sub(lambda m: f"{m[0]}\n    tempered = {rungs}\n"
                             f"    tempered_from = {hottest:g}", source))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=4000, help="sweeps per chain (default 4000)")
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tempered", type=int, default=3,
                   help="chains in each chain's tempered ladder (default 3; 1: no tempering, "
                   "models/shapes.scn as shipped)")
    p.add_argument("--tempered-from", type=float, default=0.3,
                   help="the hottest rung's power of the likelihood (default 0.3)")
    p.add_argument("--quick", action="store_true",
                   help="300 sweeps and fewer prior draws: checks the script runs")
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "occlusion",
                   help="where the observation and the run go (default runs/occlusion)")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images",
                   help="where the figures go (default docs/images)")
    args = p.parse_args(argv)
    if args.tempered < 1:
        p.error(f"--tempered is a number of chains, at least 1, got {args.tempered}")
    if not 0.0 < args.tempered_from <= 1.0:
        p.error(f"--tempered-from is a power of the likelihood in (0, 1], "
                f"got {args.tempered_from:g}")
    steps = 300 if args.quick else args.steps
    prior_draws = PRIOR_DRAWS // 10 if args.quick else PRIOR_DRAWS
    model_path = ROOT / "models" / "shapes.scn"
    sampled_with = model_path
    if args.tempered > 1:
        sampled_with = tempered_model(model_path, args.tempered, args.tempered_from,
                                      args.work / "shapes_tempered.scn")

    obs = experiment.simulate(model_path, HERE / "cameras.json", HERE / "scene.json",
                              args.work / "obs", seed=1)
    truth = experiment.load_objects(obs / "scene.json")
    run = args.work / "run"
    ladder = (f", each the coldest of a tempered ladder of {args.tempered} (hottest power "
              f"{args.tempered_from:g})" if args.tempered > 1 else "")
    print(f"sampling: {args.chains} chains of {steps} sweeps{ladder} ...", file=sys.stderr,
          flush=True)
    summary = experiment.sample(sampled_with, obs, run, steps=steps, seed=args.seed,
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
    observations = load_observations(obs)
    camera = observations.cameras[0]
    front, hidden = truth[0], truth[1]
    shadow = Shadow(camera.position, front, hidden, camera.depth_max)

    print(f"sampler: {args.chains} chains of {steps} sweeps"
          + (f", each with a tempered ladder of {args.tempered} rungs, powers of the likelihood "
             f"down to {args.tempered_from:g}" if args.tempered > 1 else ", no tempering"))
    if args.tempered > 1:
        swap = summary["acceptance"].get("swap", {"accepted": 0, "proposed": 0})
        print(f"swaps between neighbouring rungs accepted: {swap['accepted']} of "
              f"{swap['proposed']}")
    runs = load_run(run)
    samples = pooled_samples(runs)
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

    # The hidden cone's distance from the camera: that of the green cone in the shadow, in
    # each sample that has one (the nearest to the truth's ray where there are several).
    per_chain = []
    for chain in runs.chains:
        d = [shadow.distance(c) for s in chain.samples if s["step"] >= runs.burn
             and (c := _green_cone(shadow, s["objects"], hidden)) is not None]
        per_chain.append(np.array(d))
    every = np.concatenate(per_chain) if per_chain else np.array([])
    true_distance = shadow.distance(hidden)
    if every.size:
        q = np.quantile(every, QUANTILES)
        print(f"distance from the camera of the green cone in the shadow ({every.size} samples): "
              f"mean {every.mean():.2f} m, sd {every.std():.2f} m; quantiles "
              + ", ".join(f"{100 * a:g}%: {v:.2f}" for a, v in zip(QUANTILES, q))
              + f" (true {true_distance:.2f} m)")
        print("per chain: " + ", ".join(
            f"chain {i}: mean {d.mean():.2f} m, sd {d.std():.2f} m" if d.size else
            f"chain {i}: none" for i, d in enumerate(per_chain)))
    else:
        print("distance from the camera of the green cone in the shadow: no sample has one")

    # The likelihood profile along the ray through the hidden cone's tip.
    distances = profile_distances(shadow)
    map_scene = {"objects": mp, "noise": summary["map"]["noise"]}
    map_cone = _green_cone(shadow, mp, hidden)
    map_rows = profile(model, observations, map_scene,
                       mp.index(map_cone) if map_cone is not None else None,
                       camera.position, hidden, distances)
    true_scene = json.loads((obs / "scene.json").read_text())
    true_rows = profile(model, observations, true_scene, 1, camera.position, hidden, distances)
    map_best = max(lp + ll for _, lp, ll in map_rows)
    true_best = max(lp + ll for _, lp, ll in true_rows)
    print(f"likelihood profile: the log joint with the hidden cone replaced by the cone that "
          f"shows the true one's tip from d metres away (apex on the camera's ray through the "
          f"true apex, radius / height {hidden['params']['r'] / hidden['params']['h']:.2f}), "
          f"against each profile's best (MAP scene {map_best:.1f}, true scene {true_best:.1f})")
    print(f"{'d (m)':>7} {'cone h (m)':>10} {'MAP scene':>10} {'true scene':>11} "
          f"{'true scene, likelihood alone':>29}")
    true_lik = max(ll for _, _, ll in true_rows)
    true_at = {round(d, 6): (lp, ll) for d, lp, ll in true_rows}
    for i, (d, lp, ll) in enumerate(map_rows):
        if i % PRINT_EVERY:
            continue
        tlp, tll = true_at[round(d, 6)]
        h = along_ray(camera.position, hidden, d)["params"]["h"]
        print(f"{d:>7.2f} {h:>10.2f} {lp + ll - map_best:>10.1f} {tlp + tll - true_best:>11.1f} "
              f"{tll - true_lik:>29.1f}")
    print("(-inf: the cone's footprint overlaps the cube's, which the model rules out; the last "
          "column is the image's say alone)")
    lo, hi = allowed(map_rows)
    tlo, thi = allowed(true_rows)
    print(f"allowed by the image (within {ALLOWED_NATS:g} nats of the profile's best): "
          f"MAP scene {lo:.2f} to {hi:.2f} m, true scene {tlo:.2f} to {thi:.2f} m from the camera")
    if every.size:
        inside = np.mean((every >= min(lo, tlo)) & (every <= max(hi, thi)))
        print(f"posterior samples whose green cone stands in that range: {inside:.3f}")

    print("posterior over the number of objects: "
          + ", ".join(f"{k}: {v:.2f}" for k, v in summary["n_objects"].items()))
    true_lj = experiment.log_joint(model_path, obs, true_scene)
    print(f"log joint: MAP scene {summary['map']['score']:.1f}, true scene {true_lj:.1f}"
          + ("  (the truth scores higher: the chains did not reach the posterior's mode)"
             if true_lj > summary["map"]["score"] else ""))

    args.images.mkdir(parents=True, exist_ok=True)
    shutil.copy(page.parent / "camera_rgb.png", args.images / "occlusion_views.png")
    occupancy_figure(model, samples, mp, truth, [camera], shadow,
                     args.images / "occlusion_occupancy.png")
    profile_figure(map_rows, true_rows, per_chain, true_distance,
                   args.images / "occlusion_profile.png")
    print(f"report: {page}")
    print(f"figures: {args.images}/occlusion_{{views,occupancy,profile}}.png")
    return 0


def _green_cone(shadow: Shadow, objects, hidden):
    """The object in the shadow of the hidden one's class and colour, the nearest to the ray
    through it where there are several; None where there is none."""
    like = [o for o in shadow.objects_in(objects) if o["class"] == hidden["class"]
            and o["params"].get("c") == hidden["params"]["c"]]
    if not like:
        return None

    def off_ray(o):
        v = np.array([o["params"]["x"], o["params"]["y"]]) - shadow.eye
        return abs(v[0] * shadow.ray[1] - v[1] * shadow.ray[0])

    return min(like, key=off_ray)


def profile_figure(map_rows, true_rows, per_chain, true_distance, path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 5.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    for rows, label, style in ((map_rows, "MAP scene", "-"), (true_rows, "true scene", "--")):
        d = np.array([r[0] for r in rows])
        joint = np.array([r[1] + r[2] for r in rows])
        top.plot(d, np.maximum(joint - joint.max(), -400), style, label=label)
    for rows in (map_rows, true_rows):
        lo, hi = allowed(rows)
        top.axvspan(lo, hi, color="#2ca02c", alpha=0.08, lw=0)
    top.axvline(true_distance, color="#d62728", lw=1, label="true cone")
    top.set_ylabel("log joint - best (nats)")
    top.set_ylim(-410, 20)
    top.legend(loc="lower left", fontsize=8)
    top.set_title("the hidden cone replaced by one showing the same tip from d metres",
                  fontsize=9)
    bins = np.arange(map_rows[0][0], map_rows[-1][0] + 0.1, 0.1)
    for i, d in enumerate(per_chain):
        if d.size:
            bottom.hist(d, bins=bins, histtype="step", density=True, label=f"chain {i}")
    bottom.axvline(true_distance, color="#d62728", lw=1)
    bottom.set_xlabel("distance of the cone from the camera, on the ground (m)")
    bottom.set_ylabel("posterior density")
    bottom.legend(loc="upper left", fontsize=8)
    fig.savefig(path, dpi=80)


def occupancy_figure(model, samples, map_objects, truth, cameras, shadow, path) -> None:
    from matplotlib.figure import Figure

    from sppl import evenly, plot_occupancy

    fig = Figure(figsize=(7.0, 4.8), layout="constrained")
    ax = fig.subplots()
    im = plot_occupancy(ax, model, evenly(samples, 400), map_objects, truth, cameras,
                        extent=(-4.5, 4.0, -3.0, 3.0))
    # The shadow wedge the table counts in.
    for sign in (-1, 1):
        t = np.radians(sign * shadow.degrees)
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
