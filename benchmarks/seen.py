"""What marking each written sample's objects seen or unseen costs a run of the three shapes.

    python benchmarks/seen.py              # 300 sweeps from the true scene
    python benchmarks/seen.py --sweeps 100

A chain of models/shapes.scn on examples/three_shapes/obs, started at the true scene, is timed
sweep by sweep; after each sweep its objects are marked the way a run marks every sample it
writes (``sppl.render.seen.SeenCache``: an id render per camera, reused while the objects are the
same ones), and, separately, by the id pass with no reuse. Printed: the median sweep, the
median mark with and without reuse, the share of samples that needed a render, and the run's
overhead (total marking time over total sweep time), all from this one run.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweeps", type=int, default=300)
    args = parser.parse_args(argv)

    from sppl.data.observations import load_observations
    from sppl.infer.chain import Sampler
    from sppl.lang import load_model
    from sppl.model.simulate import load_scene
    from sppl.render import Renderer
    from sppl.render.seen import SeenCache, SeenPass
    from sppl.scoring.scorer import Scorer

    model = load_model(ROOT / "models" / "shapes.scn")
    obs = load_observations(ROOT / "examples" / "three_shapes" / "obs")
    sampler = Sampler(model, Scorer(model, obs, Renderer(model.render)), np.random.default_rng(0))
    objects, noise = load_scene(sampler.model, ROOT / "examples" / "three_shapes" / "scene.json")
    trace = sampler.make_trace(tuple(objects), noise)
    cache, fresh = SeenCache(model, obs.cameras), SeenPass(model, obs.cameras)
    sweeps, marks, renders, reused = [], [], [], 0
    for _ in range(args.sweeps):
        t0 = time.perf_counter()
        trace = sampler.sweep(trace)
        t1 = time.perf_counter()
        before = cache.last[0]
        cache(trace.objects)
        t2 = time.perf_counter()
        fresh(trace.objects)
        t3 = time.perf_counter()
        reused += cache.last[0] is before
        sweeps.append(t1 - t0)
        marks.append(t2 - t1)
        renders.append(t3 - t2)
    ms = 1e3
    print(f"{args.sweeps} sweeps of shapes.scn on three_shapes (2 cameras, 96x96), GL: "
          f"{sampler.scorer.renderer.ctx.info['GL_RENDERER']}")
    print(f"sweep: median {statistics.median(sweeps) * ms:.2f} ms")
    print(f"marking a sample, as a run does (reusing the last answer when the objects are the "
          f"same): median {statistics.median(marks) * ms:.3f} ms; rendered for "
          f"{1 - reused / args.sweeps:.0%} of samples")
    print(f"marking a sample with no reuse (an id render per camera): median "
          f"{statistics.median(renders) * ms:.2f} ms")
    print(f"overhead of a run that writes every sweep: {sum(marks) / sum(sweeps):.1%} "
          f"(with no reuse {sum(renders) / sum(sweeps):.1%})")


if __name__ == "__main__":
    main()
