"""Two checkouts of sppl timed against each other: a whole hypothesis and a single-object move.

    git worktree add /tmp/before 02fff69
    python benchmarks/versions.py /tmp/before .            # before, then this checkout
    python benchmarks/versions.py /tmp/before . --rounds 9

Each checkout is timed in a process of its own, with its own sppl and its own
benchmarks/evaluations.py scene (K=3, 2 cameras, 128x128), and the processes alternate for
--rounds rounds, so that a shared machine's drift falls on both alike; the medians and the
median of the rounds' ratios are printed. Every evaluation gets its moved object as a new
copy (``dataclasses.replace``, which every version has), so per-object work counts; the copy's
own time is measured and taken off.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path


def child(tree: Path) -> None:
    """Print 'whole_us move_us' for the checkout at tree."""
    import dataclasses

    sys.path[:0] = [str(tree / "benchmarks"), str(tree)]
    import evaluations as e
    import numpy as np

    from sppl.infer.chain import Sampler
    from sppl.lang import load_model
    from sppl.render import Renderer
    from sppl.scoring.scorer import Scorer

    model = load_model(tree / "models" / "shapes.scn")
    renderer = Renderer(model.render)
    rng = np.random.default_rng(0)
    objects, _, obs = e.setting(model, renderer, 3, 2, 128, rng)
    fast = Scorer(model, obs, renderer)
    state = Sampler(model, fast, np.random.default_rng(1)).make_trace(objects, e.NOISE)
    moves = e.move_sequence(model, objects, rng)

    def fresh(m):
        return (dataclasses.replace(m[0]),) + m[1:]

    def per_move(fn) -> float:
        """Median µs per evaluation over 7 runs of ``evaluations.rate`` (every version has it)."""
        fn()
        return statistics.median(1e6 / e.rate(fn, len(moves), 0.2) for _ in range(7))

    copy = per_move(lambda: [fresh(m) for m in moves])
    whole = per_move(lambda: [fast.evaluate(fresh(m)) for m in moves]) - copy
    move = per_move(lambda: [fast.evaluate(fresh(m), parent=state) for m in moves]) - copy
    print(f"{whole} {move}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    trees = [args.before.resolve(), args.after.resolve()]
    times = {tree: [] for tree in trees}
    for _ in range(args.rounds):
        for tree in trees:
            out = subprocess.run([sys.executable, __file__, "--child", str(tree)], check=True,
                                 capture_output=True, text=True).stdout.split()
            times[tree].append(tuple(float(x) for x in out[-2:]))
    before, after = times[trees[0]], times[trees[1]]
    print("| | before µs | after µs | speed-up (median of rounds) |")
    print("|---|---:|---:|---:|")
    for i, what in enumerate(["whole hypothesis", "single-object move"]):
        b = statistics.median(t[i] for t in before)
        a = statistics.median(t[i] for t in after)
        ratio = statistics.median(x[i] / y[i] for x, y in zip(before, after))
        print(f"| {what} | {b:.0f} | {a:.0f} | {ratio:.2f}x |")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        child(Path(sys.argv[2]))
    else:
        main()
