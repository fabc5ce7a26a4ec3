"""Recovery on the test bed: each scene of benchmarks/testbed/, rendered by Blender's Cycles and
by sppl itself, sampled with its shipped model by one chain.

    python benchmarks/testbed.py                       # every scene, both renderers, 20,000 sweeps
    python benchmarks/testbed.py --steps 4000          # a bounded run (benchmarks/README.md)
    python benchmarks/testbed.py --quick               # two scenes, 300 sweeps: a smoke test
    python benchmarks/testbed.py --scenes blocks_metal --renderers cycles --json out.json

Per scene and renderer it prints whether the scene was recovered, when the MAP was first
right, and the inferred noise scales against the sensors' true ones (0.02 in RGB, 0.02 m in
depth; ``scene.json``'s ``noise``). Recovered: the MAP scene the run reports at its end has
the true number of objects, and its objects, matched to the true ones by ground position
(an optimal assignment, ``sppl.output.compare``), have the true classes and categorical values
(colours, sizes and materials) and every position within --tolerance (0.15 m). shapes.scn's
sizes are continuous, and only the positions, classes and colours of its objects are checked.
"First right" is the first MAP check (every --check-every sweeps) that was right, with the
seconds since the chain started: CPU seconds of this process (``time.process_time``; the
scorer renders on the calling thread), so that a machine shared with other work, or several
of these scripts run side by side, do not inflate them. The inferred noise is the posterior mean after burn-in.
The chain runs every sweep (``time_to_solution.solve`` with ``full``), and stops early only
after --limit seconds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from time_to_solution import Check, solve

from sppl.data.observations import load_observations
from sppl.lang import load_model

TESTBED = HERE / "testbed"
RENDERERS = ("cycles", "sppl")
QUICK_SCENES = ("blocks_prior1", "shapes_prior0")


def scenes(names=None) -> list[dict]:
    index = json.loads((TESTBED / "scenes.json").read_text())
    if names:
        unknown = set(names) - {e["name"] for e in index}
        if unknown:
            raise SystemExit(f"no scene {', '.join(sorted(unknown))} in {TESTBED / 'scenes.json'}")
        index = [e for e in index if e["name"] in names]
    return index


def run_one(entry: dict, renderer: str, args) -> dict:
    folder = TESTBED / entry["name"] / renderer
    model = load_model(args.model or ROOT / entry["model"])
    truth_file = json.loads((folder / "scene.json").read_text())
    truth = truth_file["objects"]
    r = solve(model, load_observations(folder), Check(truth, args.tolerance), args.seed,
              args.steps, args.limit, args.check_every, full=True, clock=time.process_time)
    final = r["final"]
    row = {
        "scene": entry["name"], "renderer": renderer, "objects": len(truth),
        "recovered": final.correct(args.tolerance),
        "first_right_step": r["solved_at"], "first_right_seconds": r["seconds"],
        "steps": r["steps_run"], "seconds": r["total_seconds"],
        "map_objects": final.n_estimated, "wrong_class": final.wrong_class,
        "wrong_category": final.wrong_category, "max_position_error": final.max_position_error,
        "map": r["map"],
    }
    for kind in ("image", "depth"):
        row[f"{kind}_sigma"] = r["noise"].get(kind, {}).get("sigma", {}).get("mean")
        row[f"{kind}_sigma_true"] = truth_file.get("noise", {}).get(kind, {}).get("sigma")
    return row


def _fmt(v, spec):
    return format(v, spec) if v is not None else format("-", spec.split(".")[0].rstrip("f"))


def print_header() -> None:
    print(f"{'scene':<18} {'render':<7} {'recovered':>9} {'first':>7} {'first s':>7} "
          f"{'count':>6} {'class':>5} {'categ':>6} {'pos err':>7} {'image σ':>8} "
          f"{'depth σ':>8} {'total s':>7}")


def print_row(row: dict) -> None:
    print(f"{row['scene']:<18} {row['renderer']:<7} {('yes' if row['recovered'] else 'no'):>9} "
          f"{_fmt(row['first_right_step'], '>7')} {_fmt(row['first_right_seconds'], '>7.1f')} "
          f"{str(row['map_objects']) + '/' + str(row['objects']):>6} {row['wrong_class']:>5} "
          f"{row['wrong_category']:>6} {row['max_position_error']:>7.3f} "
          f"{_fmt(row['image_sigma'], '>8.3f')} {_fmt(row['depth_sigma'], '>8.3f')} "
          f"{row['seconds']:>7.1f}", flush=True)


def print_totals(rows: list[dict], renderers) -> None:
    print("\n| renderer | recovered | first right: median s (of recovered) | "
          "image sigma: median (true 0.02) | depth sigma: median (true 0.02 m) | "
          "depth sigma within 3x of true, among recovered |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in renderers:
        rs = [r for r in rows if r["renderer"] == name]
        if not rs:
            continue
        ok = [r for r in rs if r["recovered"]]
        firsts = [r["first_right_seconds"] for r in ok if r["first_right_seconds"] is not None]
        within = [r for r in ok if r["depth_sigma"] is not None and r["depth_sigma_true"]
                  and r["depth_sigma_true"] / 3 <= r["depth_sigma"] <= 3 * r["depth_sigma_true"]]
        med = lambda vs: f"{statistics.median(vs):.3f}" if vs else "-"
        print(f"| {name} | {len(ok)}/{len(rs)} | "
              f"{(f'{statistics.median(firsts):.1f}' if firsts else '-')} | "
              f"{med([r['image_sigma'] for r in rs if r['image_sigma'] is not None])} | "
              f"{med([r['depth_sigma'] for r in rs if r['depth_sigma'] is not None])} | "
              f"{len(within)}/{len(ok)} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="+", help="scene names (default: every one)")
    p.add_argument("--renderers", nargs="+", choices=RENDERERS, default=list(RENDERERS))
    p.add_argument("--steps", type=int, default=None, help="sweeps per chain (default 20,000)")
    p.add_argument("--quick", action="store_true",
                   help=f"only {' and '.join(QUICK_SCENES)}, 300 sweeps (unless --steps)")
    p.add_argument("--model", type=Path, default=None,
                   help="sample with this model file instead of each scene's shipped one (to "
                   "measure other settings; give scenes of that model only)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--limit", type=float, default=3600.0, help="seconds per chain at most")
    p.add_argument("--check-every", type=int, default=100)
    p.add_argument("--tolerance", type=float, default=0.15, help="metres")
    p.add_argument("--json", type=Path, help="write every row (with its MAP scene) here")
    p.add_argument("--report", type=Path, nargs="+", metavar="JSON",
                   help="run nothing: print the rows and totals of earlier --json files (runs "
                   "split over several processes, say)")
    args = p.parse_args(argv)
    if args.report:
        rows = [row for path in args.report for row in json.loads(path.read_text())]
        print_header()
        for row in rows:
            print_row(row)
        print_totals(rows, RENDERERS)
        return 0
    args.steps = args.steps or (300 if args.quick else 20_000)
    index = scenes(args.scenes or (QUICK_SCENES if args.quick else None))
    print(f"{len(index)} scenes, renderers {', '.join(args.renderers)}, one chain of "
          f"{args.steps} sweeps each (seed {args.seed}); noise: posterior means")
    print_header()
    rows = []
    for entry in index:
        for renderer in args.renderers:
            rows.append(run_one(entry, renderer, args))
            print_row(rows[-1])
            if args.json:
                args.json.write_text(json.dumps(rows, indent=1) + "\n")
    print_totals(rows, args.renderers)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
