"""Time to a correct scene: run `sppl sample`'s chain with default settings on a shipped example
for several seeds, and report when the MAP scene first has the right number of objects, the
right classes and colours, and every position within 0.15 m of the truth.

    python benchmarks/time_to_solution.py                      # examples/three_shapes, seeds 0-4
    python benchmarks/time_to_solution.py --seeds 0 1 --steps 5000

The MAP is checked every --check-every sweeps (the best sample so far, pruned as `sppl sample`
reports it); the time of the first correct check is the time to solution. With --full each
seed runs all its sweeps, as `sppl sample` does, and the table also says whether the MAP that
run reports at its end is correct; otherwise a seed stops at its solution. A seed always stops
after --limit seconds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sppl.compare import compare_scenes  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.observations import load_observations  # noqa: E402
from sppl.run import run_chain  # noqa: E402


def solve(model, obs, truth, seed, steps, limit, check_every, tolerance, full=False):
    state = {"solved_at": None, "seconds": None, "errors": None, "last_best": None}
    t0 = time.monotonic()

    def check(step, trace, best, sampler):
        elapsed = time.monotonic() - t0
        if step % check_every and step != steps:
            return elapsed > limit
        if best is not state["last_best"]:
            state["last_best"] = best
            pruned = sampler.prune(best)
            errors = compare_scenes([o.as_dict() for o in pruned.objects], truth)
            state["errors"] = errors
            if errors.correct(tolerance) and state["solved_at"] is None:
                state["solved_at"], state["seconds"] = step, time.monotonic() - t0
                if not full:
                    return True
        return elapsed > limit

    with tempfile.TemporaryDirectory() as tmp:
        result = run_chain(model, obs, Path(tmp), steps=steps, seed=seed, progress=False, callback=check)
    state["total_seconds"] = time.monotonic() - t0
    state["steps_run"] = result.summary["steps_done"]
    state["final"] = compare_scenes(result.summary["map"]["objects"], truth)
    return state


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", type=Path, default=ROOT / "models" / "shapes.scn")
    p.add_argument("--obs", type=Path, default=ROOT / "examples" / "three_shapes" / "obs")
    p.add_argument("--truth", type=Path, default=None, help="scene file (default: OBS/scene.json)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--steps", type=int, default=None, help="default: sppl sample's default")
    p.add_argument("--limit", type=float, default=300.0, help="seconds per seed (default 300)")
    p.add_argument("--check-every", type=int, default=100)
    p.add_argument("--tolerance", type=float, default=0.15, help="metres")
    p.add_argument("--full", action="store_true",
                   help="run every sweep and check the MAP reported at the end too")
    args = p.parse_args(argv)

    from sppl.cli import DEFAULT_STEPS

    steps = args.steps or DEFAULT_STEPS
    model = load_model(args.model)
    obs = load_observations(args.obs)
    truth = json.loads((args.truth or args.obs / "scene.json").read_text())["objects"]
    print(f"model {args.model.name}, observations {args.obs}, {len(truth)} true objects, "
          f"up to {steps} sweeps or {args.limit:.0f} s per seed")
    print("solved: the first MAP check that was right; errors: of the MAP "
          + ("reported at the end of the run" if args.full else "at the last check"))
    print(f"{'seed':>4} {'solved':>6} {'steps':>7} {'seconds':>8} {'count':>7} {'class':>5} "
          f"{'colour':>6} {'max pos err (m)':>15}"
          + (f" {'final MAP':>9} {'all steps':>9} {'total s':>8}" if args.full else ""))
    rows = []
    for seed in args.seeds:
        r = solve(model, obs, truth, seed, steps, args.limit, args.check_every, args.tolerance,
                  args.full)
        e = r["final"] if args.full else r["errors"]
        solved = r["solved_at"] is not None
        rows.append(r)
        line = (f"{seed:>4} {('yes' if solved else 'no'):>6} "
                f"{(r['solved_at'] if solved else r['steps_run']):>7} "
                f"{(r['seconds'] if solved else r['total_seconds']):>8.1f} "
                f"{f'{e.n_estimated}/{e.n_true}':>7} {e.wrong_class:>5} {e.wrong_category:>6} "
                f"{e.max_position_error:>15.3f}")
        if args.full:
            ok = "right" if e.correct(args.tolerance) else "wrong"
            line += f" {ok:>9} {r['steps_run']:>9} {r['total_seconds']:>8.1f}"
        print(line, flush=True)
    solved = [r for r in rows if r["solved_at"] is not None]
    print(f"solved {len(solved)} of {len(rows)} seeds", end="")
    if solved:
        secs = [r["seconds"] for r in solved]
        print(f"; seconds to solution: median {statistics.median(secs):.1f}, worst {max(secs):.1f}")
    else:
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
