"""Simulation-based calibration: the rank of a true value among posterior draws is uniform."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..infer.chain import Sampler
from ..model.types import Model
from .report import ALPHA, Report, Row
from .simulated import (
    Quantity,
    Simulator,
    finished_warmup,
    for_checks,
    prior_scene,
    scene_quantities,
    trace_with,
    verify_cameras,
    with_jumps,
)
from .statistics import chisquare_gof, seed_sequence


def sbc(
    model: Model,
    *,
    replicates: int = 100,
    draws: int = 9,
    thin: int = 2,
    seed=0,
    size: int = 8,
    renderer=None,
    quantities: Sequence[Quantity] | None = None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    p_jump: float | None = None,
    alpha: float = ALPHA,
) -> Report:
    """Simulation-based calibration (Talts et al. 2018): ranks of the truth among posterior
    draws are uniform on 0..``draws``.

    Each replicate draws a scene, noise and observations from the model, places the truth at
    a uniformly chosen position J of a chain of ``draws + 1`` states, and runs the sampler
    forwards (``sweep``) from it for the states after J and backwards (``adjoint_sweep``) for
    those before, ``thin`` sweeps apart. That chain is stationary, so the truth's rank is
    exactly uniform however short the chain; a wrong move breaks the uniformity.
    """
    model = for_checks(model)
    m = with_jumps(model, p_jump)
    if renderer is None:
        from ..render import Renderer

        renderer = Renderer(m.render)
    quantities = list(quantities or scene_quantities(m))
    sim = Simulator(m, verify_cameras(m, size), renderer)
    ranks = np.empty((replicates, len(quantities)), dtype=int)
    *replicate_seqs, warmup_seq = seed_sequence(seed).spawn(replicates + 1)
    warmup = finished_warmup(m, np.random.default_rng(warmup_seq))
    for r, rep_seq in enumerate(replicate_seqs):
        rng = np.random.default_rng(rep_seq)
        objs, noise = prior_scene(m, rng)
        renders = sim.render(objs, noise)
        sampler = sim.sampler(sim.observe(renders, noise, rng), rng, sampler_factory,
                              warmup=warmup)
        truth = trace_with(sampler, objs, noise, renders)
        j = int(rng.integers(draws + 1))
        values = [[f(truth.objects, truth.noise) for _, f, _ in quantities]]
        for direction, n in ((sampler.sweep, draws - j), (sampler.adjoint_sweep, j)):
            trace = truth
            for _ in range(n):
                for _ in range(thin):
                    trace = direction(trace)
                values.append([f(trace.objects, trace.noise) for _, f, _ in quantities])
        values = np.array(values)
        for q in range(len(quantities)):
            v = values[:, q]
            below = int(np.sum(v[1:] < v[0]))
            ties = int(np.sum(v[1:] == v[0]))
            ranks[r, q] = below + int(rng.integers(ties + 1))
    rows = []
    for q, (name, _, _) in enumerate(quantities):
        observed = np.bincount(ranks[:, q], minlength=draws + 1)
        p = chisquare_gof(observed, np.full(draws + 1, 1.0 / (draws + 1)))[1]
        rows.append(Row("sbc", f"rank of {name}", f"uniform on 0..{draws}: mean {draws / 2:.2f}",
                        f"mean {ranks[:, q].mean():.2f} (n={replicates})", p))
    return Report(rows, alpha)
