"""Two checkouts of sppl running the same chain: its CPU time in each, and whether they drew the
same chain.

    git worktree add /tmp/before HEAD~1
    python benchmarks/chain_versions.py /tmp/before . --model blocks --scene 8
    python benchmarks/chain_versions.py /tmp/before . --model tabletop --scene 7 --sweeps 200

The scene is scene --scene of ``prior_scenes.py`` (the benchmark of scenes nobody tuned for),
rendered once by this checkout; each checkout then runs one chain on it (chain seed 0, from an
empty scene, --sweeps sweeps) in a process of its own, the checkouts alternating for --rounds
rounds so that a shared machine's drift falls on both alike. It prints each round's CPU
seconds, their medians and the median of the rounds' ratios, and a digest of every sweep's
state: where the digests agree, the change is a pure speed-up (the chain is the same, step for
step), and a chain that solves a scene at t seconds before solves it at t / ratio after.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def child(tree: Path, model_name: str, observations: Path, sweeps: int) -> None:
    """Print 'cpu_seconds digest compiled' of the chain run by the checkout at tree (compiled:
    whether its kernels are built, docs/scoring.md)."""
    sys.path[:0] = [str(tree)]
    import time

    import numpy as np

    from sppl.data.observations import load_observations
    from sppl.infer.chain import Sampler
    from sppl.lang import load_model
    from sppl.render import Renderer, kernels
    from sppl.scoring.scorer import Scorer

    model = load_model(tree / "models" / f"{model_name}.scn")
    obs = load_observations(observations)
    sampler = Sampler(model, Scorer(model, obs, Renderer(model.render)),
                      np.random.default_rng(0))
    trace = sampler.initial_trace()
    digest = hashlib.sha1()
    start = time.process_time()
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
        digest.update(repr((trace.score, [o.values for o in trace.objects])).encode())
    print(f"{time.process_time() - start:.3f} {digest.hexdigest()[:16]} {kernels.compiled is not None}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("before", type=Path)
    p.add_argument("after", type=Path)
    p.add_argument("--model", default="blocks")
    p.add_argument("--scene", type=int, default=8)
    p.add_argument("--sweeps", type=int, default=300)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        child(Path(args.child[0]), args.model, Path(args.child[1]), int(args.child[2]))
        return 0
    sys.path[:0] = [str(HERE)]
    import prior_scenes as ps

    from sppl.runs.experiment import simulate

    trees = [args.before.resolve(), args.after.resolve()]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        scene = ps.scenes_of(args.model, args.scene + 1, ps.SEED)[args.scene]
        (work / "scene.json").write_text(json.dumps(scene))
        obs = simulate(ps.ROOT / "models" / f"{args.model}.scn",
                       ps.ROOT / "examples" / "models" / args.model / "cameras.json",
                       work / "scene.json", work / "obs", seed=ps.SEED + args.scene)
        seconds = {t: [] for t in trees}
        digests = {t: set() for t in trees}
        compiled = {}
        print(f"{args.model} scene {args.scene}, {args.sweeps} sweeps, chain seed 0")
        for r in range(args.rounds):
            for tree in trees:
                out = subprocess.run(
                    [sys.executable, __file__, str(tree), str(tree), "--model", args.model,
                     "--child", str(tree), str(obs), str(args.sweeps)],
                    check=True, capture_output=True, text=True).stdout.split()
                seconds[tree].append(float(out[0]))
                digests[tree].add(out[1])
                compiled[tree] = out[2] == "True"
            print(f"round {r + 1}: before {seconds[trees[0]][-1]:.2f} s, "
                  f"after {seconds[trees[1]][-1]:.2f} s", flush=True)
    ratios = [b / a for b, a in zip(seconds[trees[0]], seconds[trees[1]])]
    print(f"median CPU s: before {statistics.median(seconds[trees[0]]):.2f}, after "
          f"{statistics.median(seconds[trees[1]]):.2f}; after is {statistics.median(ratios):.2f}x "
          f"as fast (rounds {min(ratios):.2f} to {max(ratios):.2f})")
    if compiled[trees[0]] != compiled[trees[1]]:
        print("warning: the kernels are compiled in one checkout only (copy "
              "sppl/render/_kernels*.so into the other): the times do not compare")
    same = len(digests[trees[0]]) == 1 and digests[trees[0]] == digests[trees[1]]
    print("the same chain, step for step" if same else
          f"different chains: before {sorted(digests[trees[0]])}, after {sorted(digests[trees[1]])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
