"""Prior recovery: with no observations the chain must draw the prior, which is known exactly;
and each prior must draw what its density scores."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import stats

from ..infer.chain import Sampler
from ..infer.warmup import warmup_sweeps
from ..model.domains import Finite, Integer
from ..model.simulate import sample_objects
from ..model.types import Model
from ..scoring.scorer import PriorScorer
from .report import ALPHA, Report, Row, acceptance_rows
from .simulated import for_checks, with_jumps
from .statistics import (
    chisquare_gof,
    chisquare_two_sample,
    integrated_time,
    mean_sd,
    poisson_gof,
    seed_sequence,
    shares,
)

# Prior recovery keeps one draw every THIN * tau sweeps, tau a quantity's integrated
# autocorrelation time: what correlation remains between kept draws is then about 1e-3.
THIN = 3.0


# A quantity is tested only when the run is at least this many of its autocorrelation times
# long: below that the estimate of tau itself is unreliable (too low), and so would be the test.
MIN_TAUS = 200


def prior_recovery(
    model: Model,
    *,
    sweeps: int = 20_000,
    seed=0,
    reference_draws: int = 5000,
    sampler_factory: Callable[..., Sampler] = Sampler,
    p_jump: float | None = 1.0,
    alpha: float = ALPHA,
) -> Report:
    """Run the chain with no observations and compare what it visits with the prior.

    The chain starts from an exact prior draw, so a right sampler needs no burn-in. Model
    jumps are tried every sweep (``p_jump``) for faster mixing; the moves are the model's own.
    Counts are compared with Poisson(lambda_c) and parameters with their priors exactly where
    the prior is known in closed form; under the no-overlap constraint, bounded or fixed
    counts, or a prior that depends on other parameters, with ``reference_draws`` independent
    scenes drawn from the prior by ``sample_objects`` (rejection sampling where constrained).
    """
    model = for_checks(model)
    m = with_jumps(model, p_jump)
    chain_seq, ref_seq, pick_seq = seed_sequence(seed).spawn(3)
    rng = np.random.default_rng(chain_seq)
    sampler = sampler_factory(m, PriorScorer(), rng)
    trace = sampler.initial_trace(sample_objects(m, rng))
    # The model's warm-up (adapted steps) runs first and is not recorded: what is checked is
    # the kernel the chain keeps after it, with the scales it adapted.
    for _ in range(warmup_sweeps(m.inference)):
        trace = sampler.sweep(trace)
    states = []
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
        states.append((trace.objects, trace.noise))
    ref_rng = np.random.default_rng(ref_seq)
    reference = [sample_objects(m, ref_rng) for _ in range(reference_draws)]
    pick = np.random.default_rng(pick_seq)
    # Objects of one scene are independent given the counts only without interactions.
    independent = not m.no_overlap and m.max_objects is None
    poisson = independent and all(c.count is None and c.max_count is None for c in m.classes)
    where_ref = "rejection" if m.no_overlap or m.max_objects is not None else "prior draws"

    rows: list[Row] = []
    notes: list[str] = []
    counts = np.array([[sum(o.cls is c for o in objs) for c in m.classes] for objs, _ in states])

    def thinned(series, at_least: int = 1) -> tuple[np.ndarray, int]:
        step = max(at_least, math.ceil(THIN * integrated_time(series)))
        return np.arange(0, len(series), step), step

    untested: list[str] = []

    def too_short(name: str, step: int) -> bool:
        taus = len(states) * THIN / step
        if taus >= MIN_TAUS:
            return False
        rows.append(Row("prior", name, "-", f"untested: the run is {taus:.0f} autocorrelation "
                        f"times long (< {MIN_TAUS})", None, True, tested=False))
        untested.append(name)
        return True

    # Counts, per class and in all.
    count_rows = [(f"count of {c.name}", counts[:, i], c.rate, c) for i, c in enumerate(m.classes)]
    if len(m.classes) > 1:
        count_rows.append(("object count", counts.sum(axis=1), sum(c.rate for c in m.classes), None))
    class_step = {}
    for name, series, rate, cls in count_rows:
        keep, step = thinned(series)
        if cls is not None:
            class_step[cls] = step
        if too_short(name, step):
            continue
        draws = series[keep]
        observed = f"mean {draws.mean():.3f} (n={len(draws)}, every {step})"
        if poisson:
            _, p = poisson_gof(draws, rate)
            rows.append(Row("prior", name, f"Poisson({rate:g}): mean {rate:.3f}", observed, p))
        else:
            ref = np.array([len(objs) if cls is None else sum(o.cls is cls for o in objs)
                            for objs in reference])
            _, p = chisquare_two_sample(list(draws), list(ref))
            rows.append(Row("prior", name, f"mean {ref.mean():.3f} ({where_ref}, n={len(ref)})",
                            observed, p))

    # Parameter marginals.
    for cls in m.classes:
        for par in cls.parameters:
            name = f"{cls.name}.{par.name}"
            values_at = [[o.values[par.name] for o in objs if o.cls is cls] for objs, _ in states]
            if isinstance(par.domain, Finite):
                first = par.domain.values[0]
                series = [sum(x == first for x in v) for v in values_at]
            else:
                series = [float(sum(v)) for v in values_at]
            # A parameter's draws also need its class's count to have moved on: its values
            # are refreshed by births and deaths.
            keep, step = thinned(series, class_step[cls])
            if too_short(name, step):
                continue
            ref_values = [[o.values[par.name] for o in objs if o.cls is cls] for objs in reference]
            if independent:
                draws = [x for t in keep for x in values_at[t]]
                ref = [x for v in ref_values for x in v]
            else:  # one object per scene: objects of one scene are dependent
                draws = [_one(values_at[t], pick) for t in keep if values_at[t]]
                ref = [_one(v, pick) for v in ref_values if v]
            observed = f"{_describe(draws, par)} (n={len(draws)}, every {step})"
            if not draws:
                rows.append(Row("prior", name, str(par.prior), "no draws", None, False))
                continue
            restricted = cls.restriction is not None and par.name in cls.restriction.names
            exact = (_exact_test(draws, par, pick)
                     if independent and par.prior_fn is None and not restricted else None)
            if exact is not None:
                expected, p = exact
            elif restricted and independent:
                # The prior restricted to the region, by rejection from the unrestricted one.
                ref = list(cls.restriction.rejection_draws(reference_draws, pick)[
                    :, cls.restriction.names.index(par.name)])
                expected = f"{_describe(ref, par)} (rejection, n={len(ref)})"
                p = float(stats.ks_2samp(draws, ref).pvalue)
            else:
                expected = f"{_describe(ref, par)} ({where_ref}, n={len(ref)})"
                if par.continuous:
                    p = float(stats.ks_2samp(draws, ref).pvalue)
                else:
                    p = chisquare_two_sample(draws, ref)[1]
            rows.append(Row("prior", name, expected, observed, p))

    # Noise and lighting parameters: their priors are untouched by any constraint.
    for kind, parameters in m.noise_groups:
        for par in parameters:
            series = np.array([noise[kind][par.name] for _, noise in states])
            keep, step = thinned(series)
            if too_short(f"{kind}.{par.name}", step):
                continue
            draws = list(series[keep])
            exact = _exact_test(draws, par, pick)
            if exact is None:
                ref = [par.prior.sample(pick) for _ in range(reference_draws)]
                exact = (f"{_describe(ref, par)} (prior draws, n={len(ref)})",
                         float(stats.ks_2samp(draws, ref).pvalue))
            rows.append(Row("prior", f"{kind}.{par.name}", exact[0],
                            f"{_describe(draws, par)} (n={len(draws)}, every {step})", exact[1]))

    rows += acceptance_rows("prior", sampler.stats.by_move())[0]
    if untested:
        notes.append(
            f"prior recovery: {', '.join(untested)} mixed too slowly to be tested in "
            f"{sweeps} sweeps (more --steps would test them; the Geweke test and the move "
            "checks cover them too)."
        )
    return Report(rows, alpha, notes)


def prior_declarations(model: Model, *, draws: int = 4000, seed=0, alpha: float = ALPHA) -> Report:
    """Does each prior draw what its density scores? Births and changes propose from a
    class's ``sample_prior`` and assume its density is ``log_prior``; a prior (a plugin's, or
    a class built in Python) whose two disagree gives a wrong sampler, and rejection samples
    from the same ``sample_prior`` would share the mistake. So: draw objects from each class's
    prior and test each parameter's probability integral transform, F(value | the object's
    other values), for uniformity (KS; randomised between F(x - 1) and F(x) for integers),
    and each categorical parameter's draws against its probabilities (chi-square). Priors
    without a ``cdf`` are left out."""
    model = for_checks(model)
    rng = np.random.default_rng(seed_sequence(seed))
    rows = []
    owners = [(cls.name, cls.parameters, lambda c=cls: c.sample_prior(rng)) for cls in model.classes]
    owners += [(kind, ps, lambda ps=ps: {p.name: p.prior.sample(rng) for p in ps})
               for kind, ps in model.noise_groups]
    for owner, parameters, draw in owners:
        samples = [draw() for _ in range(draws)]
        restricted = next((c.restriction for c in model.classes if c.name == owner), None)
        if restricted is not None:
            rows += _restriction_rows(owner, restricted, samples, rng)
        for par in parameters:
            if restricted is not None and par.name in restricted.names:
                continue  # its marginal is the restricted prior's: _restriction_rows
            name = f"{owner}.{par.name}: draws match density"
            # Where the density is zero at a draw, the prior the sampler targets (truncated
            # to the domain, renormalised per object) is not the one that births draw from.
            outside = sum(not math.isfinite(par.log_prob(v[par.name], v)) for v in samples)
            if outside:
                rows.append(Row("prior", name, f"every draw inside {par.domain.describe()}",
                                f"{outside}/{len(samples)} draws where the density is 0",
                                None, False))
                continue
            if isinstance(par.domain, Finite):
                if par.prior_fn is not None or not hasattr(par.prior, "probs"):
                    continue
                values = [v[par.name] for v in samples]
                expected, p = _exact_test(values, par, rng)
                rows.append(Row("prior", name, expected, _describe(values, par), p))
                continue
            u = []
            for v in samples:
                dist = par.distribution(v)
                if not hasattr(dist, "cdf"):
                    break
                x = v[par.name]
                if par.continuous:
                    u.append(float(dist.cdf(x)))
                else:
                    lo, hi = float(dist.cdf(x - 1)), float(dist.cdf(x))
                    u.append(lo + rng.random() * (hi - lo))
            if len(u) < len(samples):
                continue
            p = float(stats.kstest(u, "uniform").pvalue)
            rows.append(Row("prior", name, "F(draw) uniform: mean 0.500, sd 0.289",
                            f"{mean_sd(u)} (n={len(u)})", p))
    return Report(rows, alpha)


def _restriction_rows(owner: str, r, samples, rng) -> list[Row]:
    """A class's position draws, restricted to the model's region, against rejection sampling
    from the unrestricted priors (KS on each coordinate), and the normaliser Z against the
    share of those draws that land inside (binomial)."""
    ref = r.rejection_draws(len(samples), rng)
    rows = []
    for i, name in enumerate(r.names):
        draws = [v[name] for v in samples]
        p = float(stats.ks_2samp(draws, ref[:, i]).pvalue)
        rows.append(Row("prior", f"{owner}.{name}: draws match the region's prior",
                        f"rejection: {mean_sd(ref[:, i])}", mean_sd(draws), p))
    z, tries = math.exp(r.log_mass), 2 * len(samples)
    inside = r.inside(tries, rng)
    p = float(stats.binomtest(inside, tries, z).pvalue)
    rows.append(Row("prior", f"{owner}: the region's normaliser", f"Z = {z:.4f}",
                    f"{inside}/{tries} = {inside / tries:.4f} inside", p))
    return rows


def _one(values, rng):
    return values[int(rng.integers(len(values)))] if values else None


def _describe(draws, par) -> str:
    if isinstance(par.domain, Finite):
        return shares(list(draws), par.domain.values)
    return mean_sd(draws)


def _exact_test(draws, par, rng) -> tuple[str, float] | None:
    """The expected description and p-value of independent draws of a parameter against its
    prior in closed form: KS against the cdf of a continuous prior, chi-square against the
    probabilities of a categorical one; None where neither is available."""
    prior = par.prior
    if par.continuous and hasattr(prior, "cdf"):
        p = float(stats.kstest(np.asarray(draws, dtype=float), prior.cdf).pvalue)
        return f"{prior}: {mean_sd([prior.sample(rng) for _ in range(4000)])}", p
    if isinstance(par.domain, Integer) and hasattr(prior, "cdf") and len(draws):
        # Bins lo, ..., hi of the values seen, the outer two taking the tails.
        d = np.asarray(draws, dtype=int)
        lo, hi = int(d.min()), int(d.max())
        cdf = np.array([float(prior.cdf(v)) for v in range(lo - 1, hi + 1)])
        probs = np.diff(cdf)
        probs[0] += cdf[0]
        probs[-1] += 1.0 - cdf[-1]
        return str(prior), chisquare_gof(np.bincount(d - lo, minlength=hi - lo + 1), probs)[1]
    if isinstance(par.domain, Finite) and hasattr(prior, "probs"):
        labels = par.domain.values
        observed = [sum(1 for x in draws if x == v) for v in labels]
        probs = [prior.probs[prior.values.index(v)] if v in prior.values else 0.0 for v in labels]
        return str(prior), chisquare_gof(observed, probs)[1]
    return None
