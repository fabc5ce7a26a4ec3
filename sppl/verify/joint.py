"""Geweke's (2004) joint-distribution test, with the renderer and the likelihoods in the loop."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats

from ..infer.chain import Sampler
from ..model.simulate import sample_noise, sample_objects
from ..model.types import Model
from .report import ALPHA, NEEDED_MOVES, Report, Row, acceptance_rows
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
from .statistics import chisquare_two_sample, mean_sd, seed_sequence


def geweke(
    model: Model,
    *,
    chains: int = 100,
    length: int = 20,
    seed=0,
    size: int = 8,
    mc_draws: int = 5000,
    renderer=None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    p_jump: float | None = 1.0,
    quantities: Sequence[Quantity] | None = None,
    alpha: float = ALPHA,
) -> Report:
    """Marginal-conditional against successive-conditional simulation (Geweke 2004).

    Each of ``chains`` independent successive-conditional chains starts from an exact draw of
    (scene, noise, observations) and alternates one sweep of the sampler with observations
    simulated afresh from the new state, ``length`` times. If every move leaves the posterior
    invariant, every state of every chain is a draw from the prior; so the chains' final
    states, which are independent, are compared with independent prior draws by two-sample
    tests (Kolmogorov-Smirnov, chi-square for discrete quantities), whose false-alarm rate is
    then exact. A wrong move makes the chains drift from the prior, furthest at their end.
    """
    model = for_checks(model)
    m = with_jumps(model, p_jump)
    if not m.sensors:
        return Report([], alpha, ["geweke: the model has no sensors, so there is nothing to test."])
    if renderer is None:
        from ..render import Renderer

        renderer = Renderer(m.render)
    quantities = list(quantities or scene_quantities(m))
    sim = Simulator(m, verify_cameras(m, size), renderer)
    mc_seq, sc_seq = seed_sequence(seed).spawn(2)

    mc_rng = np.random.default_rng(mc_seq)
    mc = np.empty((mc_draws, len(quantities)))
    for i in range(mc_draws):
        objs, noise = sample_objects(m, mc_rng), sample_noise(m, mc_rng)
        mc[i] = [f(objs, noise) for _, f, _ in quantities]

    sc = np.empty((chains, len(quantities)))
    stats_ = None
    warmup = finished_warmup(m, np.random.default_rng(mc_seq.spawn(1)[0]))
    data_births = [0, 0]
    for r, chain_seq in enumerate(sc_seq.spawn(chains)):
        rng = np.random.default_rng(chain_seq)
        objs, noise = prior_scene(m, rng)
        renders = sim.render(objs, noise)
        sampler = sim.sampler(sim.observe(renders, noise, rng), rng, sampler_factory, stats_,
                              warmup)
        stats_ = sampler.stats
        trace = trace_with(sampler, objs, noise, renders)
        for t in range(length):
            if t:
                sampler = sim.sampler(sim.observe(trace.renders, trace.noise, rng), rng,
                                      sampler_factory, stats_, warmup)
                trace = trace_with(sampler, trace.objects, trace.noise, trace.renders,
                                    trace.log_prior)
            count_data_births(sampler, data_births)
            trace = sampler.sweep(trace)
        sc[r] = [f(trace.objects, trace.noise) for _, f, _ in quantities]

    rows = []
    for j, (name, _, discrete) in enumerate(quantities):
        a, b = mc[:, j], sc[:, j]
        if discrete:
            p = chisquare_two_sample(list(a), list(b))[1]
        else:
            p = float(stats.ks_2samp(a, b).pvalue)
        rows.append(Row("geweke", name, f"{mean_sd(a)} (prior, n={len(a)})",
                        f"{mean_sd(b)} (chains, n={len(b)})", p))
    accepted, rare = acceptance_rows("geweke", stats_.by_move(), NEEDED_MOVES) if stats_ \
        else ([], [])
    rows += accepted
    notes = rare + [
        (
            f"geweke: {chains} chains of {length} sweeps on {size}x{size} images "
            f"({', '.join(s.camera.name for s in sim.specs)}), {mc_draws} prior draws; "
            f"{data_births[1]} of {data_births[0]} birth proposals could use unexplained pixels."
        )
    ]
    return Report(rows, alpha, notes)


def count_data_births(sampler: Sampler, counter: list[int]) -> None:
    """Count birth proposals, and those made where the data-driven mixture is active."""
    birth = sampler.birth
    if getattr(birth, "_verify_counting", False):
        return
    original = birth.sample

    def sample(cls, trace, rng):
        counter[0] += 1
        if cls.position and len(birth.points(trace)):
            counter[1] += 1
        return original(cls, trace, rng)

    birth.sample = sample
    birth._verify_counting = True
