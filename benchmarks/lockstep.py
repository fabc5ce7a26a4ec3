"""Chains in lockstep against chains one after another, and against chains in processes.

    python benchmarks/lockstep.py                 # 4 chains on examples/three_shapes
    python benchmarks/lockstep.py --sweeps 50 --repeats 3

Sweeps per second of --chains chains of models/shapes.scn on the three shapes, two ways in one
process, from the same states: in lockstep (``sppl.runs.lockstep.sweep_together``: each round's
evaluations of every chain in one ``Scorer.evaluate_batch`` call) and one chain after another
(each chain's own ``Sampler.sweep``). The chains are first run --warm sweeps, so that they
hold objects; each repeat then restarts every chain from that state and generator, so both
ways draw the same sweeps. Figures are medians of --repeats; the two ways run in turn within a
repeat (in alternating order), so the ratio compares like with like on a shared machine.

Then whole runs, as ``sppl sample --chains N`` makes them (start-up, checkpoints and summaries
included): in lockstep, in N processes, and one ``run_chain`` after another, once each for
--run-steps sweeps.
"""

from __future__ import annotations

import argparse
import copy
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sppl.data.observations import load_observations  # noqa: E402
from sppl.infer.chain import Sampler  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.render import Renderer, renderer_string  # noqa: E402
from sppl.runs.chains import run_chains
from sppl.runs.lockstep import sweep_together  # noqa: E402
from sppl.runs.run import run_chain  # noqa: E402
from sppl.scoring.scorer import Scorer  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--warm", type=int, default=200, help="sweeps before measuring")
    p.add_argument("--sweeps", type=int, default=100, help="sweeps per chain per repeat")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--run-steps", type=int, default=300, help="sweeps per chain, whole runs")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)

    model = load_model(ROOT / "models" / "shapes.scn")
    obs = load_observations(ROOT / "examples" / "three_shapes" / "obs")
    print(f"GL renderer: {renderer_string()}")
    scorer = Scorer(model, obs, Renderer(model.render))
    seeds = np.random.SeedSequence(args.seed).spawn(args.chains)
    samplers = [Sampler(model, scorer, np.random.default_rng(s)) for s in seeds]
    traces = [s.initial_trace() for s in samplers]
    for _ in range(args.warm):
        traces = sweep_together(samplers, traces)
    print(f"{args.chains} chains after {args.warm} sweeps hold "
          f"{[t.n_objects for t in traces]} objects")
    saved = [(copy.deepcopy(s.rng.bit_generator.state), s.state_dict()) for s in samplers]

    def restart():
        for s, (rng_state, state) in zip(samplers, saved):
            s.rng.bit_generator.state = copy.deepcopy(rng_state)
            s.load_state_dict(copy.deepcopy(state))

    def lockstep():
        ts = traces
        for _ in range(args.sweeps):
            ts = sweep_together(samplers, ts)
        return ts

    def one_after_another():
        out = []
        for s, t in zip(samplers, traces):
            for _ in range(args.sweeps):
                t = s.sweep(t)
            out.append(t)
        return out

    rates = {"lockstep": [], "one after another": []}
    ratios = []
    ways = [("lockstep", lockstep), ("one after another", one_after_another)]
    for repeat in range(args.repeats):
        seconds, ends = {}, {}
        for name, fn in ways if repeat % 2 == 0 else ways[::-1]:  # neither always goes first
            restart()
            t0 = time.perf_counter()
            ends[name] = [t.score for t in fn()]
            seconds[name] = time.perf_counter() - t0
            rates[name].append(args.chains * args.sweeps / seconds[name])
        assert ends["lockstep"] == ends["one after another"]  # the same sweeps, both ways
        ratios.append(seconds["one after another"] / seconds["lockstep"])
    print(f"\nsweeps per second, {args.chains} chains in one process "
          f"(median of {args.repeats} repeats of {args.sweeps} sweeps per chain):")
    for name, r in rates.items():
        print(f"  {name:18s} {statistics.median(r):8.1f}")
    print(f"  lockstep is {statistics.median(ratios):.2f}x one after another "
          f"(per-repeat ratios {', '.join(f'{x:.2f}' for x in ratios)})")

    print(f"\nwhole runs of {args.chains} chains x {args.run_steps} sweeps (seconds, one each):")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        timings = {}
        t0 = time.perf_counter()
        run_chains(model, obs, tmp / "lockstep", chains=args.chains, steps=args.run_steps,
                   seed=args.seed, progress=False, lockstep=True)
        timings["lockstep, one process"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_chains(model, obs, tmp / "processes", chains=args.chains, steps=args.run_steps,
                   seed=args.seed, progress=False)
        timings[f"{args.chains} processes"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for i, s in enumerate(np.random.SeedSequence(args.seed).spawn(args.chains)):
            run_chain(model, obs, tmp / f"alone_{i}", steps=args.run_steps, seed=s,
                      progress=False)
        timings["one after another"] = time.perf_counter() - t0
        same = all((tmp / "lockstep" / f"chain_{i}" / "samples.jsonl").read_bytes()
                   == (tmp / "processes" / f"chain_{i}" / "samples.jsonl").read_bytes()
                   for i in range(args.chains))
        shutil.rmtree(tmp, ignore_errors=True)
    for name, s in timings.items():
        print(f"  {name:24s} {s:7.1f} s  ({args.chains * args.run_steps / s:6.1f} sweeps/s)")
    print(f"  lockstep and processes drew the same samples: {same}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
