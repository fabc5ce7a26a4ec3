"""Verified inference: does the sampler derived from a model leave its posterior invariant?

A sampler that is subtly wrong gives confident, wrong answers that look like right ones. These
checks catch it, on the shipped models in the test suite and on a user's own model through
``sppl verify model.scn`` (``verify_model``):

- ``prior_declarations``: each prior draws what its density scores (births propose from one
  and the ratios assume the other), by the probability integral transform.
- ``prior_recovery``: with no observations the chain targets the prior, which is known exactly.
  Its per-class counts must be Poisson(lambda_c) (chi-square, tail bins pooled so that every
  expected count is at least 5), every parameter's marginal its prior (Kolmogorov-Smirnov for
  continuous parameters, chi-square for discrete ones), and under ``constraint no_overlap``
  (or bounded counts, or dependent priors) both must match independent samples from the prior
  (two-sample tests; rejection sampling where constrained).
- ``geweke``: Geweke's (2004) joint-distribution test with the renderer and the likelihoods in
  the loop, on tiny images. The marginal-conditional simulator draws scenes from the prior;
  the successive-conditional one alternates a sweep of the sampler given simulated
  observations with fresh observations simulated from the new state. If the sampler is right,
  both have the prior as their marginal over scenes.
- ``move_checks``: every move and its reverse (``sppl.moves.reverse``): applying a proposal
  and then its reverse gives back the same trace, and the two log acceptance ratios are
  negatives of each other.
- ``sbc``: simulation-based calibration: the rank of a true value among posterior draws is
  uniform.

Statistics. MCMC draws are autocorrelated, and a test that treats them as independent raises
false alarms. The prior-recovery chain thins each quantity's draws to one every 3 tau sweeps,
tau being that quantity's integrated autocorrelation time (Geyer's initial monotone sequence
estimate), and tests a quantity only when the run is at least 200 tau long. The Geweke test
avoids the question: it runs many short independent chains, each started from an exact draw
of the joint distribution, so every chain is stationary from its first step if the sampler is
right, and compares their final states, which are independent, with independent prior draws.
SBC runs each replicate's chain forwards and (with the time-reversed sweep) backwards from the
true state, which makes the ranks exactly uniform at any chain length.

Every statistical row has a p-value; a ``Report`` decides pass or fail for all of them
together with Holm's step-down correction, so that the chance of *any* false alarm in a whole
report is at most ``alpha`` (default 0.01). Rows without a p-value are exact checks.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from . import moves
from .camera import Camera, focal_from_fov, look_at
from .chain import Sampler
from .domains import Finite, Integer
from .errors import SpplError
from .likelihoods import get_likelihood, sample_observation
from .model import RENDER_GROUP, Model
from .observations import CameraSpec, Frame, Observations
from .region import CamerasRegion, bind_region
from .scoring import PriorScorer, Scorer
from .simulate import sample_noise, sample_objects
from .trace import Trace
from .warmup import Warmup, warmup_sweeps

ALPHA = 0.01
# Prior recovery keeps one draw every THIN * tau sweeps, tau a quantity's integrated
# autocorrelation time: what correlation remains between kept draws is then about 1e-3.
THIN = 3.0
# A quantity is tested only when the run is at least this many of its autocorrelation times
# long: below that the estimate of tau itself is unreliable (too low), and so would be the test.
MIN_TAUS = 200
# Exact checks: how far apart log alpha(forward) and -log alpha(reverse) may be.
RATIO_TOLERANCE = 1e-6

# name, f(objects, noise), whether its values are discrete
Quantity = tuple[str, Callable[[Sequence[Any], Any], float], bool]


# ---------------------------------------------------------------------------------------------
# Reports


@dataclass(frozen=True)
class Row:
    """One line of a report. ``p_value`` is None for an exact (non-statistical) check, whose
    verdict is ``ok``; statistical rows are decided by their ``Report``."""

    check: str  # "prior", "geweke", "moves", "sbc"
    quantity: str
    expected: str
    observed: str
    p_value: float | None = None
    ok: bool = True
    # False for a row that could not be tested (a run too short for how slowly its quantity
    # mixes): it fails nothing, says nothing, and is shown as untested, never as a pass.
    tested: bool = True


@dataclass
class Report:
    rows: list[Row]
    alpha: float = ALPHA
    notes: list[str] = field(default_factory=list)

    @property
    def verdicts(self) -> list[bool]:
        """Pass (True) or fail per row, statistical rows by Holm's procedure at ``alpha``."""
        stat = [i for i, r in enumerate(self.rows) if r.p_value is not None]
        rejected = holm([self.rows[i].p_value for i in stat], self.alpha)
        out = [r.ok for r in self.rows]
        for i, rej in zip(stat, rejected):
            out[i] = not rej
        return out

    @property
    def passed(self) -> bool:
        return all(self.verdicts)

    @property
    def untested(self) -> list[str]:
        """The quantities a check left untested (a run too short for how slowly they mix):
        such a row fails nothing, but says nothing either (``strict`` fails on it)."""
        return [r.quantity for r in self.rows if not r.tested]

    @property
    def passed_strict(self) -> bool:
        """Every check passed and none was left untested (``sppl verify --strict``)."""
        return self.passed and not self.untested

    @property
    def failures(self) -> list[Row]:
        return [r for r, ok in zip(self.rows, self.verdicts) if not ok]

    def row(self, quantity: str, check: str | None = None) -> Row:
        for r in self.rows:
            if r.quantity == quantity and (check is None or r.check == check):
                return r
        raise KeyError(quantity)

    def table(self, strict: bool = False) -> str:
        """The report as a table and a verdict; with ``strict`` an untested row fails it."""
        head = ("check", "quantity", "expected", "observed", "p-value", "result")
        lines = [
            (r.check, r.quantity, r.expected, r.observed, _format_p(r.p_value),
             "FAIL" if not ok else "untested" if not r.tested else "pass")
            for r, ok in zip(self.rows, self.verdicts)
        ]
        widths = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]

        def fmt(cells) -> str:
            return "  ".join(
                c.rjust(w) if i == 4 else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths))
            ).rstrip()

        out = [fmt(head), fmt(tuple("-" * w for w in widths))]
        out += [fmt(x) for x in lines]
        n_stat = sum(r.p_value is not None for r in self.rows)
        untested = [f"{r.check}: {r.quantity}" for r in self.rows if not r.tested]
        out.append("")
        out.append(
            f"{n_stat} statistical checks, decided together by Holm's correction at a "
            f"family-wise false-alarm rate of {self.alpha:g}; "
            f"{len(self.rows) - n_stat - len(untested)} exact checks; "
            f"{len(untested)} untested."
        )
        out += self.notes
        if not self.passed:
            names = ", ".join(f"{r.check}: {r.quantity}" for r in self.failures)
            out.append(f"FAIL: {names}" + (f"; untested: {', '.join(untested)}" if untested
                                           else ""))
        elif untested and strict:
            out.append(f"FAIL (--strict): untested: {', '.join(untested)}")
        elif untested:
            out.append(f"PASS, but {len(untested)} untested (they say nothing either way; "
                       f"--strict fails on them): {', '.join(untested)}")
        else:
            out.append("PASS: every check passed.")
        return "\n".join(out)


def combine(reports: Iterable[Report], alpha: float = ALPHA) -> Report:
    rows, notes = [], []
    for r in reports:
        rows += r.rows
        notes += r.notes
    return Report(rows, alpha, notes)


def holm(p_values: Sequence[float], alpha: float) -> list[bool]:
    """Holm's step-down procedure: which hypotheses are rejected, with a family-wise error
    rate of at most ``alpha`` whatever the dependence between the tests."""
    m = len(p_values)
    rejected = [False] * m
    for i, j in enumerate(np.argsort(p_values, kind="stable")):
        if p_values[j] <= alpha / (m - i):
            rejected[j] = True
        else:
            break
    return rejected


def _format_p(p: float | None) -> str:
    if p is None:
        return "-"
    if p < 1e-4:
        return f"{p:.1e}"
    return f"{p:.4f}"


# ---------------------------------------------------------------------------------------------
# Statistics


def integrated_time(x: Sequence[float]) -> float:
    """Integrated autocorrelation time 1 + 2 sum_t rho_t of a series (Geyer's initial
    monotone sequence estimator); 1 for independent draws and for a constant series."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n < 4:
        return 1.0
    x = x - x.mean()
    if not np.any(x):
        return 1.0
    f = np.fft.rfft(x, 2 * n)
    acov = np.fft.irfft(f * np.conj(f))[:n]
    rho = acov / acov[0]
    m = (n - 1) // 2
    pairs = rho[0 : 2 * m : 2] + rho[1 : 2 * m : 2]
    stop = np.flatnonzero(pairs <= 0.0)
    pairs = pairs[: stop[0] if len(stop) else len(pairs)]
    pairs = np.minimum.accumulate(pairs)
    return max(1.0, float(-1.0 + 2.0 * pairs.sum()))


def pool_bins(expected: Sequence[float], minimum: float = 5.0) -> list[list[int]]:
    """Groups of adjacent bins whose expected counts each add up to at least ``minimum``
    (the last group takes any remainder), so that the chi-square approximation holds."""
    groups: list[list[int]] = []
    current: list[int] = []
    total = 0.0
    for i, e in enumerate(expected):
        current.append(i)
        total += e
        if total >= minimum:
            groups.append(current)
            current, total = [], 0.0
    if current:
        if groups:
            groups[-1].extend(current)
        else:
            groups.append(current)
    return groups


def chisquare_gof(observed: Sequence[float], probs: Sequence[float]) -> tuple[float, float]:
    """Chi-square goodness of fit of bin counts to bin probabilities (which sum to one),
    adjacent bins pooled to expected counts of at least 5. Returns (statistic, p)."""
    observed = np.asarray(observed, dtype=float)
    probs = np.asarray(probs, dtype=float)
    n = observed.sum()
    groups = pool_bins(n * probs)
    if n == 0 or len(groups) < 2:
        return 0.0, 1.0
    o = np.array([observed[g].sum() for g in groups])
    e = np.array([n * probs[g].sum() for g in groups])
    e *= o.sum() / e.sum()  # rounding only
    stat, p = stats.chisquare(o, e)
    return float(stat), float(p)


def chisquare_two_sample(a: Sequence[Any], b: Sequence[Any]) -> tuple[float, float]:
    """Chi-square test that two samples of a discrete quantity have the same distribution
    (a 2 x k contingency table, adjacent values pooled to expected cells of at least 5)."""
    values = sorted(set(a) | set(b), key=lambda v: (isinstance(v, str), v))
    index = {v: i for i, v in enumerate(values)}
    table = np.zeros((2, len(values)))
    for row, sample in enumerate((a, b)):
        for v in sample:
            table[row, index[v]] += 1
    n = table.sum()
    if n == 0 or min(len(a), len(b)) == 0:
        return 0.0, 1.0
    share = table.sum(axis=1).min() / n
    groups = pool_bins(table.sum(axis=0) * share)
    if len(groups) < 2:
        return 0.0, 1.0
    pooled = np.stack([table[:, g].sum(axis=1) for g in groups], axis=1)
    stat, p, _, _ = stats.chi2_contingency(pooled, correction=False)
    return float(stat), float(p)


def poisson_gof(draws: Sequence[int], rate: float) -> tuple[float, float]:
    draws = np.asarray(draws, dtype=int)
    top = int(draws.max()) + 1 if len(draws) else 1
    observed = np.bincount(draws, minlength=top + 1)[: top + 1].astype(float)
    probs = stats.poisson.pmf(np.arange(top + 1), rate)
    probs[-1] = stats.poisson.sf(top - 1, rate)  # the last bin is the tail, N >= top
    return chisquare_gof(observed, probs)


def _mean_sd(x) -> str:
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return "no draws"
    return f"mean {x.mean():.3f}, sd {x.std():.3f}"


def _shares(values, labels) -> str:
    n = max(len(values), 1)
    return " ".join(f"{v} {sum(1 for x in values if x == v) / n:.2f}" for v in labels)


def _seq(seed) -> np.random.SeedSequence:
    return seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)


def with_jumps(model: Model, p_jump: float | None) -> Model:
    """The model with another chance of a model jump per sweep. Each move leaves the target
    invariant whatever this weight is, so a check may raise it to 1 to mix faster."""
    if p_jump is None:
        return model
    return replace(model, inference=replace(model.inference, p_jump=p_jump))


def with_prior_noise_steps(model: Model, *, draws: int = 2000, seed=0) -> Model:
    """The model with each sensor noise parameter's random-walk step widened to the spread of
    its prior (the standard deviation of ``draws`` prior draws) where its own is smaller.

    A model's noise steps are tuned for the posterior, where the noise is known far better
    than a priori: from the prior such a step needs about (prior sd / step)^2 sweeps to move
    one standard deviation (some hundreds for the shipped models), and prior recovery would
    need a run hundreds of times longer to test it. The random walk leaves the target invariant
    whatever its scale (as ``with_jumps`` says of the jump chance), so the move checked is the
    same; only its tuning differs."""
    rng = np.random.default_rng(_seq(seed))

    def widened(parameters):
        out = []
        for p in parameters:
            if p.continuous:
                spread = float(np.std([p.prior.sample(rng) for _ in range(draws)]))
                if spread > p.proposal_scale:
                    p = replace(p, proposal_scale=spread)
            out.append(p)
        return tuple(out)

    sensors = {kind: replace(sensor, noise=widened(sensor.noise))
               for kind, sensor in model.sensors.items()}
    # The render block's lighting parameters are random walks of the same kind.
    render = replace(model.render, latent=widened(model.render.latent))
    return replace(model, sensors=sensors, render=render)


# The moves without which a chain cannot reach every scene: against observations each of them
# must be accepted now and then. The other jumps only speed the chain up, and one fitted to
# the pixels (a merge, a split) can be rare against the observations of a prior scene.
NEEDED_MOVES = ("parameters", "noise", "birth", "death")


def _acceptance_rows(check: str, by_move: dict[str, tuple[int, int]],
                     needed: tuple[str, ...] | None = None) -> tuple[list[Row], list[str]]:
    """Exact rows: every move type that was proposed was accepted at least once (a move that
    is never accepted leaves the target invariant, and the chain stuck). With ``needed``,
    only those moves must be; another that never was is reported in a note instead."""
    rows, notes = [], []
    for move, (n, a) in sorted(by_move.items()):
        if a == 0 and needed is not None and move not in needed:
            notes.append(f"{check}: no {move} move was accepted (0/{n}); it is not needed to "
                         "reach every scene, and prior recovery checks that it is accepted")
            continue
        rows.append(Row(check, f"{move} moves accepted", "some", f"{a}/{n} ({a / n:.0%})",
                        None, a > 0))
    return rows, notes


# ---------------------------------------------------------------------------------------------
# Prior recovery


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
    chain_seq, ref_seq, pick_seq = _seq(seed).spawn(3)
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

    rows += _acceptance_rows("prior", sampler.stats.by_move())[0]
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
    rng = np.random.default_rng(_seq(seed))
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
                            f"{_mean_sd(u)} (n={len(u)})", p))
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
                        f"rejection: {_mean_sd(ref[:, i])}", _mean_sd(draws), p))
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
        return _shares(list(draws), par.domain.values)
    return _mean_sd(draws)


def _exact_test(draws, par, rng) -> tuple[str, float] | None:
    """The expected description and p-value of independent draws of a parameter against its
    prior in closed form: KS against the cdf of a continuous prior, chi-square against the
    probabilities of a categorical one; None where neither is available."""
    prior = par.prior
    if par.continuous and hasattr(prior, "cdf"):
        p = float(stats.kstest(np.asarray(draws, dtype=float), prior.cdf).pvalue)
        return f"{prior}: {_mean_sd([prior.sample(rng) for _ in range(4000)])}", p
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


# ---------------------------------------------------------------------------------------------
# Observations for the checks that need a likelihood


def for_checks(model: Model) -> Model:
    """``model`` with a ``region cameras`` taken as the ground the verify cameras see (sized
    by the unrestricted prior): the checks need a region before any observation is made. Any
    other model is returned as it is, its prior not drawn from here (a broken prior is the
    checks' to report, row by row)."""
    if not isinstance(model.region, CamerasRegion):
        return model
    return bind_region(model, [spec.camera for spec in verify_cameras(model)])


def verify_cameras(model: Model, size: int = 8, seed: int = 0) -> list[CameraSpec]:
    """Two tiny cameras, one RGB and one depth, looking at the region where the prior puts
    objects (90% of prior positions lie within the radius they frame)."""
    rng = np.random.default_rng(seed)
    radii = [
        math.hypot(v[cls.position[0]], v[cls.position[1]])
        for cls in model.classes
        if cls.position
        for v in (cls.sample_prior(rng) for _ in range(400))
    ]
    r = max(1.0, float(np.quantile(radii, 0.9))) if radii else 2.0
    f = focal_from_fov(size, 60.0)

    def camera(name, eye):
        eye = np.asarray(eye, dtype=float) * r
        return Camera(name, size, size, f, f, size / 2, size / 2, look_at(eye, (0.0, 0.0, 0.0)),
                      depth_max=4.0 * r)

    specs = []
    if "image" in model.sensors:
        specs.append(CameraSpec(camera("verify-rgb", (1.2, -1.3, 1.1)), ("rgb",)))
    if "depth" in model.sensors:
        specs.append(CameraSpec(camera("verify-depth", (-1.3, -1.0, 1.2)), ("depth",)))
    return specs


class _Simulator:
    """Renders scenes for the verify cameras and draws observations from the model's own
    likelihoods, without the clipping ``sppl simulate`` applies to write valid image files:
    the checks need observations distributed exactly as the likelihood says."""

    def __init__(self, model: Model, specs: Sequence[CameraSpec], renderer) -> None:
        self.model = model
        self.specs = list(specs)
        self.renderer = renderer
        self.likelihoods = {k: get_likelihood(s.likelihood, s.options) for k, s in model.sensors.items()}

    def render(self, objects, noise=None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Every verify camera's render of the objects, lit as ``noise``'s render group (if
        the model has lighting parameters) says."""
        parts = [*self.model.static_parts, *(p for o in objects for p in o.parts)]
        settings = self.model.render.with_values((noise or {}).get(RENDER_GROUP))
        return {i: self.renderer.render(parts, s.camera, settings)
                for i, s in enumerate(self.specs)}

    def observe(self, renders, noise, rng) -> Observations:
        frames = []
        for i, spec in enumerate(self.specs):
            rgb, depth = renders[i]
            frame = Frame(camera=spec.camera)
            high = spec.camera.depth_max
            if "rgb" in spec.modalities:
                frame.rgb = sample_observation(self.likelihoods["image"], rgb, noise["image"],
                                               rng, high)
            if "depth" in spec.modalities:
                frame.depth = sample_observation(self.likelihoods["depth"], depth,
                                                 noise["depth"], rng, high)
                frame.depth_valid = np.isfinite(frame.depth)  # NaN: no return
            frames.append(frame)
        return Observations(Path("."), frames)

    def sampler(self, observations, rng, factory, stats=None, warmup=None) -> Sampler:
        sampler = factory(self.model, Scorer(self.model, observations, self.renderer), rng)
        if stats is not None:
            sampler.stats = stats
        if warmup is not None:
            sampler.warmup = warmup
        return sampler


def _finished_warmup(model: Model, rng) -> Warmup | None:
    """The state a chain's warm-up leaves (its adapted steps, annealing over), for checks that
    test the kernel after it: the warm-up run on a chain without observations. None when the
    model has no warm-up."""
    n = warmup_sweeps(model.inference)
    if not n:
        return None
    sampler = Sampler(model, PriorScorer(), rng)
    trace = sampler.initial_trace(sample_objects(model, rng))
    for _ in range(n):
        trace = sampler.sweep(trace)
    return sampler.warmup


def prior_scene(model: Model, rng: np.random.Generator):
    """(objects, noise) drawn from the prior, the objects in a random order. ``sample_objects``
    lists them class by class, and chains started only from such tuples would never test a
    move on another order: one that depended on it (a death or a change choosing by position)
    could pass. The scene is a set, so any order is as good a start."""
    objects = sample_objects(model, rng)
    objects = tuple(objects[i] for i in rng.permutation(len(objects)))
    return objects, sample_noise(model, rng)


def _trace_with(sampler: Sampler, objects, noise, renders, log_prior=None) -> Trace:
    """The trace of these objects under the sampler's observations, from renders already
    made (so a change of observations costs no rendering)."""
    from .trace import noise_log_prior, objects_log_prior

    scorer = sampler.scorer
    stats = {(t.frame, t.kind): scorer.term_statistics(t, scorer.rendered(renders, t), noise)
             for t in scorer.terms}
    if log_prior is None:
        log_prior = objects_log_prior(sampler.model, objects) + noise_log_prior(sampler.model, noise)
    return Trace(sampler.model, tuple(objects), noise, stats, log_prior,
                 scorer.log_likelihood(stats, noise), renders)


def scene_quantities(model: Model) -> list[Quantity]:
    """Functions of a scene that the Geweke test and SBC compare, each with whether it is
    discrete: the object count, per class its count, per parameter the sum over the class's
    objects (0 when there are none), per categorical value the number of objects with it, and
    each noise parameter."""
    out: list[Quantity] = []
    if len(model.classes) > 1:
        out.append(("object count", lambda objs, noise: float(len(objs)), True))
    for cls in model.classes:
        out.append((f"count of {cls.name}",
                    lambda objs, noise, c=cls: float(sum(o.cls is c for o in objs)), True))
        for par in cls.parameters:
            name = f"{cls.name}.{par.name}"
            if not isinstance(par.domain, Finite):
                out.append((f"sum of {name}", lambda objs, noise, c=cls, n=par.name:
                            float(sum(o.values[n] for o in objs if o.cls is c)),
                            not par.continuous))
            else:
                for v in par.domain.values:
                    out.append((f"{name} = {v}", lambda objs, noise, c=cls, n=par.name, v=v:
                                float(sum(o.values[n] == v for o in objs if o.cls is c)), True))
    for kind, parameters in model.noise_groups:
        for par in parameters:
            out.append((f"{kind}.{par.name}", lambda objs, noise, k=kind, n=par.name:
                        float(noise[k][n]), False))
    return out


# ---------------------------------------------------------------------------------------------
# Geweke's joint-distribution test


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
        from .render import Renderer

        renderer = Renderer(m.render)
    quantities = list(quantities or scene_quantities(m))
    sim = _Simulator(m, verify_cameras(m, size), renderer)
    mc_seq, sc_seq = _seq(seed).spawn(2)

    mc_rng = np.random.default_rng(mc_seq)
    mc = np.empty((mc_draws, len(quantities)))
    for i in range(mc_draws):
        objs, noise = sample_objects(m, mc_rng), sample_noise(m, mc_rng)
        mc[i] = [f(objs, noise) for _, f, _ in quantities]

    sc = np.empty((chains, len(quantities)))
    stats_ = None
    warmup = _finished_warmup(m, np.random.default_rng(mc_seq.spawn(1)[0]))
    data_births = [0, 0]
    for r, chain_seq in enumerate(sc_seq.spawn(chains)):
        rng = np.random.default_rng(chain_seq)
        objs, noise = prior_scene(m, rng)
        renders = sim.render(objs, noise)
        sampler = sim.sampler(sim.observe(renders, noise, rng), rng, sampler_factory, stats_,
                              warmup)
        stats_ = sampler.stats
        trace = _trace_with(sampler, objs, noise, renders)
        for t in range(length):
            if t:
                sampler = sim.sampler(sim.observe(trace.renders, trace.noise, rng), rng,
                                      sampler_factory, stats_, warmup)
                trace = _trace_with(sampler, trace.objects, trace.noise, trace.renders,
                                    trace.log_prior)
            _count_data_births(sampler, data_births)
            trace = sampler.sweep(trace)
        sc[r] = [f(trace.objects, trace.noise) for _, f, _ in quantities]

    rows = []
    for j, (name, _, discrete) in enumerate(quantities):
        a, b = mc[:, j], sc[:, j]
        if discrete:
            p = chisquare_two_sample(list(a), list(b))[1]
        else:
            p = float(stats.ks_2samp(a, b).pvalue)
        rows.append(Row("geweke", name, f"{_mean_sd(a)} (prior, n={len(a)})",
                        f"{_mean_sd(b)} (chains, n={len(b)})", p))
    accepted, rare = _acceptance_rows("geweke", stats_.by_move(), NEEDED_MOVES) if stats_ \
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


def _count_data_births(sampler: Sampler, counter: list[int]) -> None:
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


# ---------------------------------------------------------------------------------------------
# Moves and their reverses


def same_trace(a: Trace, b: Trace) -> bool:
    """The same objects in the same places with the same values, the same noise, the same
    score."""
    if len(a.objects) != len(b.objects):
        return False
    for x, y in zip(a.objects, b.objects):
        if x.cls is not y.cls or dict(x.values) != dict(y.values):
            return False
    if {k: dict(v) for k, v in a.noise.items()} != {k: dict(v) for k, v in b.noise.items()}:
        return False
    return math.isclose(a.score, b.score, rel_tol=1e-9, abs_tol=1e-9)


def check_reverse(sampler: Sampler, trace: Trace, proposal) -> tuple[float, float, bool] | None:
    """Apply a proposal and then its reverse. Returns (log alpha forward, log alpha of the
    reverse, whether the reverse gave back ``trace``), or None when the proposal has zero prior
    (it would be rejected before rendering, and has no reverse). Raises ``ValueError`` for a
    move type that ``sppl.moves.reverse`` does not know."""
    if proposal is None:
        return None
    new = sampler.evaluate(trace, proposal)
    if new is None:
        return None
    forward = sampler.log_alpha(trace, proposal, new)
    if proposal.tries is not None:  # a multiple-try jump or a refit, undone with the same draws
        rev = proposal.tries.reverse(sampler, trace, proposal, new)
    else:
        rev = moves.reverse(sampler.model, trace, proposal, new, sampler.birth,
                            without=lambda objs: sampler.make_trace(objs, new.noise))
    back = sampler.evaluate(new, rev)
    if back is None:
        return forward, -math.inf, False
    return forward, sampler.log_alpha(new, rev, back), same_trace(trace, back)


def _ratio_gap(forward: float, backward: float) -> float:
    if math.isfinite(forward) and math.isfinite(backward):
        return abs(forward + backward)
    return 0.0 if forward == -backward else math.inf


# Per state, the move checks draw jumps from the sampler's own ``propose_jump`` until every jump
# type it can make has been seen, or this many have been drawn.
JUMP_TRIES = 60


def move_checks(
    model: Model,
    *,
    states: int = 30,
    seed=0,
    size: int = 8,
    renderer=None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    observe: bool = True,
) -> Report:
    """Every move type from ``states`` prior draws, each applied and then reversed.

    The model jumps are the sampler's own: ``Sampler.propose_jump`` is called until each jump
    type with a positive probability (``Sampler.jump``) has been proposed once from the state,
    so a new kind of jump is checked without naming it here (and fails if
    ``sppl.moves.reverse`` does not know it). Then a parameter move of each block of one
    object, and a move of each noise parameter. With sensors (and ``observe``), the states are
    scored against observations of another prior scene, so that data-driven births (which
    look at what a state leaves unexplained) are among those checked; without, against no
    observations. The change-of-class pairings are checked too (``change_declarations``).
    """
    model = for_checks(model)
    seq = _seq(seed)
    rng = np.random.default_rng(seq)
    if model.sensors and observe:
        if renderer is None:
            from .render import Renderer

            renderer = Renderer(model.render)
        sim = _Simulator(model, verify_cameras(model, size), renderer)
        objs, noise = sample_objects(model, rng), sample_noise(model, rng)
        sampler = sim.sampler(sim.observe(sim.render(objs, noise), noise, rng), rng, sampler_factory)
    else:
        sampler = sampler_factory(model, PriorScorer(), rng)
    jumps = {j for j, p in sampler.jump.items() if p > 0}
    results: dict[str, list[tuple[float, float, bool]]] = {}
    no_reverse: dict[str, str] = {}
    for _ in range(states):
        trace = sampler.initial_trace(sample_objects(model, rng))
        proposals, seen = [], set()
        for _ in range(JUMP_TRIES):
            p = sampler.propose_jump(trace)
            if p is not None and p.move not in seen:
                seen.add(p.move)
                proposals.append(p)
            if seen >= jumps:
                break
        if trace.objects:
            k = int(rng.integers(len(trace.objects)))
            for block in moves.parameter_blocks(trace.objects[k].cls):
                proposals.append(moves.propose_parameters(model, trace, k, block, rng))
        for kind, parameters in model.noise_groups:
            for p in parameters:
                proposals.append(moves.propose_noise(model, trace, kind, p.name, rng))
        for p in proposals:
            if p.move in no_reverse:
                continue
            try:
                result = check_reverse(sampler, trace, p)
            except ValueError as error:
                no_reverse[p.move] = str(error)
                continue
            results.setdefault(p.move, [])
            if result is not None:
                results[p.move].append(result)
    rows = []
    for move in sorted(set(results) | set(no_reverse)):
        name, expected = f"{move}: reverse undoes it", "same trace, log a + log a_rev = 0"
        if move in no_reverse:
            rows.append(Row("moves", name, expected, f"no reverse: {no_reverse[move]}", None, False))
            continue
        res = results[move]
        if not res:
            continue  # proposed, but never to a state of positive prior
        same = sum(r[2] for r in res)
        gap = max(_ratio_gap(f, b) for f, b, _ in res)
        rows.append(Row(
            "moves", name, expected, f"{same}/{len(res)} same, max |sum| {gap:.1e}", None,
            same == len(res) and gap < RATIO_TOLERANCE,
        ))
    notes = [
        f"moves: {move} jumps were never proposed to a state of positive prior in {states} "
        "states; prior recovery still checks them."
        for move in sorted(jumps) if not results.get(move) and move not in no_reverse
    ]
    return Report(change_declarations(model) + rows, ALPHA, notes)


def change_declarations(model: Model) -> list[Row]:
    """Exact rows, one per pair of classes: a change of class carries values as they are, so
    its reverse can carry them back only if the pairing is the same both ways, reversed, and
    each carried pair has the same domain (a value of a wider domain may not fit the narrower
    one; a whole number carried into a real parameter would land on a set of measure zero, and
    the ratio would be wrong). The language rejects such a declaration when it compiles a
    model; a class built in Python (or a future pairing rule) is checked here."""
    rows = []
    for i, a in enumerate(model.classes):
        for b in model.classes[i + 1 :]:
            forward = moves.carried_parameters(a, b)  # {parameter of b: parameter of a}
            back = moves.carried_parameters(b, a)  # {parameter of a: parameter of b}
            problems = []
            if back != {q: p for p, q in forward.items()}:
                problems.append(f"{a.name} -> {b.name} carries {_pairs(forward, a, b)} but "
                                f"{b.name} -> {a.name} carries {_pairs(back, b, a)} back")
            for p, q in forward.items():
                da, db = a.parameter(q).domain, b.parameter(p).domain
                if da != db:
                    problems.append(f"{a.name}.{q} ({da.describe()}) -> {b.name}.{p} ({db.describe()})")
            # A scaled pairing carries back only with the reciprocal factor.
            there, back_scales = moves.carried_scales(a, b), moves.carried_scales(b, a)
            for p, q in forward.items():
                if q in back_scales and not math.isclose(there[p] * back_scales[q], 1.0):
                    problems.append(f"{a.name}.{q} -> {b.name}.{p} is scaled by {there[p]:g} "
                                    f"but back by {back_scales[q]:g}")
            observed = "; ".join(problems) or f"carries {_pairs(forward, a, b) or 'nothing'}"
            rows.append(Row("moves", f"change {a.name} <-> {b.name}: carries back",
                            "the same pairs both ways, equal domains", observed, None,
                            not problems))
    return rows


def _pairs(carried: dict[str, str], old, new) -> str:
    return ", ".join(q if p == q else f"{old.name}.{q} -> {new.name}.{p}"
                     for p, q in carried.items())


# ---------------------------------------------------------------------------------------------
# Simulation-based calibration


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
        from .render import Renderer

        renderer = Renderer(m.render)
    quantities = list(quantities or scene_quantities(m))
    sim = _Simulator(m, verify_cameras(m, size), renderer)
    ranks = np.empty((replicates, len(quantities)), dtype=int)
    *replicate_seqs, warmup_seq = _seq(seed).spawn(replicates + 1)
    warmup = _finished_warmup(m, np.random.default_rng(warmup_seq))
    for r, rep_seq in enumerate(replicate_seqs):
        rng = np.random.default_rng(rep_seq)
        objs, noise = prior_scene(m, rng)
        renders = sim.render(objs, noise)
        sampler = sim.sampler(sim.observe(renders, noise, rng), rng, sampler_factory,
                              warmup=warmup)
        truth = _trace_with(sampler, objs, noise, renders)
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


# ---------------------------------------------------------------------------------------------
# Everything, for ``sppl verify``


def verify_model(
    model: Model,
    *,
    steps: int = 20_000,
    seed: int = 0,
    run_geweke: bool = True,
    geweke_chains: int = 100,
    geweke_length: int = 20,
    size: int = 8,
    alpha: float = ALPHA,
    renderer=None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    progress: Callable[[str], None] | None = None,
    proposal_draws: int = 30,
) -> Report:
    """The check of the declarations, prior recovery, the move checks and (when the model has
    sensors) a short Geweke test and the checks of the proposals that look at the
    observations (``sppl.proposal_checks``, ``proposal_draws`` draws per transform; 0 leaves
    them out) on one model, in one report whose verdict is corrected for
    multiple comparisons. A check stopped by an error of the model (a dependent prior whose
    arguments break it for some values, say) gives a failing row with the error in the notes,
    and the others still run."""
    say = progress or (lambda message: None)
    prior_seq, moves_seq, geweke_seq, proposals_seq = _seq(seed).spawn(4)
    model = for_checks(model)  # `region cameras`: the ground the verify cameras see
    if model.sensors and renderer is None and run_geweke:
        from .render import Renderer

        renderer = Renderer(model.render)
    checks = [
        ("prior", "the priors' draws against their densities", None,
         lambda: prior_declarations(model, seed=prior_seq.spawn(1)[0])),
        ("prior", "prior recovery", f"prior recovery: {steps} sweeps with no observations ...",
         lambda: prior_recovery(model, sweeps=steps, seed=prior_seq,
                                sampler_factory=sampler_factory)),
        ("moves", "moves and their reverses", "moves and their reverses ...",
         lambda: move_checks(model, seed=moves_seq, size=size, renderer=renderer,
                             sampler_factory=sampler_factory, observe=run_geweke)),
    ]
    if run_geweke and model.sensors:
        checks.append((
            "geweke", "Geweke test",
            f"geweke: {geweke_chains} chains of {geweke_length} sweeps on {size}x{size} images ...",
            lambda: geweke(model, chains=geweke_chains, length=geweke_length, seed=geweke_seq,
                           size=size, renderer=renderer, sampler_factory=sampler_factory),
        ))
    if run_geweke and model.sensors and proposal_draws > 0:
        from .proposal_checks import check_proposals

        checks.append((
            "proposals", "data-dependent proposals",
            (f"proposals: the data-dependent proposals' samplers against their densities, "
             f"{proposal_draws} draws each ..."),
            lambda: check_proposals(model, seed=proposals_seq, draws=proposal_draws,
                                    renderer=renderer, sampler_factory=sampler_factory),
        ))
    reports = []
    for check, what, message, run in checks:
        if message:
            say(message)
        try:
            reports.append(run())
        except SpplError as error:
            reports.append(Report(
                [Row(check, f"{what}: runs", "no error", "stopped by an error (below)", None,
                     False)],
                alpha, [f"{check}: {what} stopped: {error}"],
            ))
    return combine(reports, alpha)
