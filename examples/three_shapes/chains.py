"""Four chains on the shipped example, their report, and whether they agree.

    python examples/three_shapes/chains.py                 # 4 chains x 20,000 sweeps: ~16 min
    python examples/three_shapes/chains.py --steps 300     # a smoke test

Runs what a user would type,

    sppl sample models/shapes.scn --obs examples/three_shapes/obs --chains 4 --out RUN
    sppl report RUN

then prints R-hat and bulk/tail ESS of the label-invariant quantities (the number of objects
first), each chain's own posterior over the number of objects and its MAP log joint, and
copies the report's trace plot and occupancy map to docs/images/three_shapes_traces.png and
three_shapes_occupancy.png. See docs/three_shapes.md.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from sppl.cli import DEFAULT_STEPS
from sppl.cli import main as sppl

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                   help=f"sweeps per chain (default: sppl sample's, {DEFAULT_STEPS})")
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "three_shapes_chains",
                   help="the run folder (default runs/three_shapes_chains)")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images",
                   help="where the figures go (default docs/images)")
    args = p.parse_args(argv)

    code = sppl(["sample", str(ROOT / "models" / "shapes.scn"), "--obs",
                 str(HERE / "obs"), "--chains", str(args.chains), "--steps", str(args.steps),
                 "--seed", str(args.seed), "--out", str(args.out), "--force", "-q"])
    if code:
        return code
    if sppl(["report", str(args.out)]):
        return 1
    summary = json.loads((args.out / "summary.json").read_text())
    print()
    print(f"{args.chains} chains of {args.steps} sweeps, seed {args.seed}: convergence after "
          f"{summary['burn']} sweeps of burn-in")
    print(f"{'quantity':<18} {'R-hat':>7} {'bulk ESS':>9} {'tail ESS':>9} {'mean':>10}")
    for name, d in summary["diagnostics"].items():
        rhat = "n/a" if d["rhat"] is None else f"{d['rhat']:.3f}"
        bulk = "n/a" if d["ess_bulk"] is None else f"{d['ess_bulk']:.0f}"
        tail = "n/a" if d["ess_tail"] is None else f"{d['ess_tail']:.0f}"
        print(f"{name:<18} {rhat:>7} {bulk:>9} {tail:>9} {d['mean']:>10.4g}")
    print("each chain:")
    for i in range(args.chains):
        s = json.loads((args.out / f"chain_{i}" / "summary.json").read_text())
        counts = ", ".join(f"{k}: {v:.2f}" for k, v in s["n_objects"].items())
        classes = " + ".join(sorted(o["class"] for o in s["map"]["objects"]))
        print(f"  chain {i}: MAP log joint {s['map']['score']:.0f} ({classes}); "
              f"number of objects {counts}")
    args.images.mkdir(parents=True, exist_ok=True)
    shutil.copy(args.out / "report" / "traces.png", args.images / "three_shapes_traces.png")
    shutil.copy(args.out / "report" / "occupancy.png", args.images / "three_shapes_occupancy.png")
    print(f"report: {args.out / 'report' / 'index.html'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
