"""Exactness checks of the proposals whose densities look at the observations.

Prior recovery runs without observations, so it never switches on the proposals that look at
them: births near unexplained pixels (``sppl.infer.birth``, also used by replaces, splits, the
refit's mixture and multiple tries), refits fitted to the pixels (``sppl.infer.fit``, also merges'
and splits') of an object chosen where the pixels disagree (``sppl.infer.misfit``), and merge
partners chosen by distance in the image (``sppl.infer.merge``). Geweke's
test runs them, but its power against a wrong density is small: a birth density replaced by
the prior passes it. So these checks hold the observations fixed and test each such proposal
directly, with the very functions the moves call to draw from it and to score it:

- ``sampler against density``: draws from the proposal's sampler, and for each coordinate the
  conditional probability integral transform u = F(v_j | the draw's other coordinates), F
  computed from the proposal's own log density by quadrature along that coordinate (by sums
  over a categorical one, randomised within the atom). If the density is the sampler's, every
  u is uniform (Rosenblatt); Kolmogorov-Smirnov tests it. For a merge partner, the object a
  refit replaces and a fitted birth's class (discrete choices), chi-square of the choices
  against the probabilities the ratio uses.
- ``importance identity``: for a normalised reference density r that is zero outside a
  bounded region B (a normal truncated to B, around what the proposal aims at, times the
  prior of the coordinates the proposal draws from the prior), E_{v ~ sampler}[r(v) / q(v)]
  = 1 whenever q > 0 on B. A density that is not the sampler's (the prior in its place, a
  wrong spread) moves the mean; a z-test on the mean of these bounded weights decides.

Every statistical row carries its p-value, and a ``Report`` decides them together with Holm's
correction at its ``alpha`` (the family-wise false-alarm rate of the whole report).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from scipy import stats

from ..infer import fit as fitting
from ..infer import fitted_birth, merge, misfit, redundant
from ..infer.chain import Sampler
from ..model.domains import Finite, Integer, Interval, Periodic
from ..model.trace import SceneObject, Trace, make_object
from ..model.types import Model, ObjectClass
from .report import ALPHA, Report, Row
from .simulated import Simulator, verify_cameras
from .statistics import seed_sequence

# Quadrature along a coordinate: steps of half of each width a density has there (the
# trapezoid rule's error on a whole Gaussian so sampled is below 1e-30, and on the part of one
# up to a draw, within a step of width/2, below 0.5% of its mass), REACH widths each way
# (beyond which a Gaussian has 6e-7 of its mass), and PRIOR_STEPS steps over the range its
# prior covers (at most 1/25 of that range: a prior's cdf is smooth on that scale).
PRIOR_STEPS = 100


PER_WIDTH = 2


# How far past a Gaussian's centre the grid reaches, in widths.
REACH = 5.0


# Prior draws that give a coordinate's range where the prior has no closed support.
RANGE_DRAWS = 4000


def _pit_continuous(log_q: Callable[[Mapping[str, Any]], float], values: Mapping[str, Any],
                    name: str, grid: np.ndarray) -> float:
    """F(values[name] | the other values) under the density ``log_q``, by the trapezoid rule
    over ``grid`` (with the value itself inserted)."""
    v = float(values[name])
    xs = np.union1d(grid, [v])
    logs = np.array([log_q({**values, name: float(x)}) for x in xs])
    top = np.max(logs)
    if not np.isfinite(top):
        return math.nan
    dens = np.exp(logs - top)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(xs))])
    return float(cum[np.searchsorted(xs, v)] / cum[-1])


def _pit_discrete(log_q, values, name: str, options, u: float) -> float:
    """The randomised transform F(v-) + u P(v) of a discrete coordinate over ``options``."""
    logs = np.array([log_q({**values, name: o}) for o in options])
    top = np.max(logs)
    if not np.isfinite(top):
        return math.nan
    p = np.exp(logs - top)
    p /= p.sum()
    k = list(options).index(values[name])
    return float(p[:k].sum() + u * p[k])


def coordinate_rows(check: str, label: str, draws, log_q, grids: Mapping[str, Any],
                    rng: np.random.Generator) -> list[Row]:
    """One KS row per coordinate: the conditional transforms of ``draws`` under ``log_q``.
    ``grids`` maps a continuous coordinate to its quadrature grid, a discrete one to a tuple
    of its possible values. A draw the density gives zero fails the row outright."""
    rows = []
    for name, grid in grids.items():
        pits = []
        for values in draws:
            if isinstance(grid, tuple):
                pits.append(_pit_discrete(log_q, values, name, grid, float(rng.random())))
            else:
                pits.append(_pit_continuous(log_q, values, name, grid))
        pits = np.array(pits)
        zero = int(np.sum(~np.isfinite(pits)))
        quantity = f"{label}: {name} given the rest"
        expected = "F(draw) uniform (KS)"
        if zero:
            rows.append(Row(check, quantity, expected,
                            f"{zero} of {len(pits)} draws have density 0", None, False))
            continue
        ks = stats.kstest(pits, "uniform")
        rows.append(Row(check, quantity, expected,
                        f"n={len(pits)}, D={ks.statistic:.3f}", float(ks.pvalue)))
    return rows


def identity_row(check: str, label: str, draws, log_q, log_r) -> Row:
    """E[r / q] = 1 over draws from q's sampler, r a density that is nonzero only on a region
    where q > 0 (``log_r`` is -inf outside it): a two-sided z-test of the mean weight."""
    w = np.array([math.exp(log_r(v) - log_q(v)) if math.isfinite(log_r(v)) else 0.0
                  for v in draws])
    mean, sd = float(w.mean()), float(w.std(ddof=1))
    if sd <= 1e-12 * max(1.0, abs(mean)):  # every weight the same: exact
        p = 1.0 if math.isclose(mean, 1.0, rel_tol=1e-9) else 0.0
    else:
        p = float(2.0 * stats.norm.sf(abs(mean - 1.0) / (sd / math.sqrt(len(w)))))
    return Row(check, f"{label}: E[r/q] over a region", "1",
               f"{mean:.3f} +- {sd / math.sqrt(len(w)):.3f} (n={len(w)})", p)


# The reference densities of the identity: a normal of the given widths around a centre,
# truncated to BOX widths each way (a bounded region), normalised. Where q has a component of
# the same width there (a birth's kernel at that point, a refit's widest spread at the fit),
# r / q is bounded, so the mean weight has a small, finite variance.
BOX = 2.0


_LOG_BOX_MASS = math.log(math.erf(BOX / math.sqrt(2.0)))


def _log_box_normal(x, centre, widths) -> float:
    total = 0.0
    for v, c, w in zip(x, centre, widths):
        z = (v - c) / w
        if abs(z) > BOX:
            return -math.inf
        total += -0.5 * z * z - math.log(w) - 0.5 * math.log(2.0 * math.pi) - _LOG_BOX_MASS
    return total


def _prior_range(cls: ObjectClass, name: str, rng: np.random.Generator) -> tuple[float, float]:
    """Where the prior of a continuous parameter puts its mass: its domain where bounded, else
    the range of many prior draws, widened by a tenth each way."""
    p = cls.parameter(name)
    if isinstance(p.domain, Interval | Periodic):
        return float(p.domain.low), float(p.domain.high)
    xs = [cls.sample_prior(rng)[name] for _ in range(RANGE_DRAWS)]
    lo, hi = float(min(xs)), float(max(xs))
    pad = 0.1 * (hi - lo)
    lo = max(lo - pad, 0.0) if lo >= 0.0 else lo - pad
    return lo, hi + pad


def _grid(lo: float, hi: float, centres=(), widths=(), cloud=None, spread=None) -> np.ndarray:
    """A quadrature grid over [lo, hi], and around each centre, for each width, REACH widths
    each way at PER_WIDTH points a width; domain edges are grid points. ``cloud``, the
    coordinates of a birth's unexplained points, adds PER_WIDTH points per ``spread`` over
    their range, REACH spreads past either end."""
    parts = [np.linspace(lo, hi, PRIOR_STEPS + 1)]
    if cloud is not None and len(cloud):
        a, b = float(np.min(cloud)) - REACH * spread, float(np.max(cloud)) + REACH * spread
        parts.append(np.linspace(a, b, math.ceil((b - a) / spread * PER_WIDTH) + 1))
    for c in centres:
        for w in widths:
            n = int(2 * REACH * PER_WIDTH)
            parts.append(c + w * np.linspace(-REACH, REACH, n + 1))
    return np.unique(np.concatenate(parts))


def _discrete_options(cls: ObjectClass, name: str, rng: np.random.Generator) -> tuple:
    p = cls.parameter(name)
    if isinstance(p.domain, Finite):
        return tuple(p.domain.values)
    lo, hi = p.domain.low, p.domain.high
    if not (math.isfinite(lo) and math.isfinite(hi)):
        xs = [cls.sample_prior(rng)[name] for _ in range(RANGE_DRAWS)]
        lo = lo if math.isfinite(lo) else min(xs)
        hi = hi if math.isfinite(hi) else 2 * max(xs) + 10
    return tuple(range(int(lo), int(hi) + 1))


def birth_rows(sampler: Sampler, state: Trace, cls: ObjectClass, rng: np.random.Generator,
               draws: int, weights: int) -> list[Row]:
    """``sampler.birth.sample`` against ``sampler.birth.log_density`` for a ``cls`` object
    born into ``state``: conditional transforms of every coordinate, and E[r/q] = 1 with r a
    normal of the birth's spread around an unexplained point, truncated to two spreads
    (times the prior of the other coordinates, which a birth draws from the prior)."""
    birth = sampler.birth
    points = birth.points(state)
    label = f"birth of {cls.name}"
    log_q = lambda v: birth.log_density(cls, v, state)
    sample = [birth.sample(cls, state, rng) for _ in range(max(draws, weights))]
    grids: dict[str, Any] = {}
    for p in cls.parameters:
        if p.continuous:
            lo, hi = _prior_range(cls, p.name, rng)
            if p.name in cls.position:
                axis = cls.position.index(p.name)
                grids[p.name] = _grid(lo, hi, cloud=points[:, axis], spread=birth.spread)
            else:
                grids[p.name] = _grid(lo, hi)
        else:
            grids[p.name] = _discrete_options(cls, p.name, rng)
    rows = coordinate_rows("proposals", label, sample[:draws], log_q, grids, rng)

    centre = points[len(points) // 2]
    rest = [n for n in cls.parameter_names if n not in cls.position]
    spread = birth.spread

    def log_r(v):
        xy = (v[cls.position[0]], v[cls.position[1]])
        return _log_box_normal(xy, centre, (spread, spread)) + cls.log_prior(v, only=rest)

    rows.append(identity_row("proposals", label, sample[:weights], log_q, log_r))
    return rows


def refit_rows(sampler: Sampler, state: Trace, cls: ObjectClass, like: SceneObject,
               rng: np.random.Generator, draws: int, weights: int) -> list[Row]:
    """``fit.sample`` against ``fit.log_mixture`` for a ``cls`` object fitted into ``state``
    from ``like`` (the fit ``fit.fit`` makes, once): conditional transforms of every
    coordinate, and E[r/q] = 1 with r a normal of the refit's widest spread around the fit in
    the continuous coordinates, truncated to two of it, uniform over a categorical one's
    values, and the prior of an integer one."""
    fitted = fitting.fit(sampler, state, cls, like)
    label = f"refit as {cls.name}"
    log_q = lambda v: fitting.log_mixture(sampler, state, cls, v, fitted)
    sample = [fitting.sample(sampler, state, cls, fitted, rng) for _ in range(max(draws, weights))]
    points = sampler.birth.points(state) if cls.position else np.empty((0, 2))
    grids: dict[str, Any] = {}
    for p in cls.parameters:
        if p.continuous:
            lo, hi = _prior_range(cls, p.name, rng)
            steps = [c * p.proposal_scale for c in fitting.SPREADS]
            lo = min(lo, fitted[p.name] - REACH * max(steps))
            hi = max(hi, fitted[p.name] + REACH * max(steps))
            cloud = (points[:, cls.position.index(p.name)]
                     if cls.position and p.name in cls.position else None)
            grids[p.name] = _grid(lo, hi, [float(fitted[p.name])], steps, cloud,
                                  sampler.birth.spread)
        else:
            grids[p.name] = _discrete_options(cls, p.name, rng)
    rows = coordinate_rows("proposals", label, sample[:draws], log_q, grids, rng)

    cont = [p.name for p in cls.parameters if p.continuous]
    widths = [max(fitting.SPREADS) * cls.parameter(n).proposal_scale for n in cont]
    centre = [float(fitted[n]) for n in cont]
    finite = [p for p in cls.parameters if isinstance(p.domain, Finite)]
    others = [p.name for p in cls.parameters if isinstance(p.domain, Integer)]

    def log_r(v):
        return (_log_box_normal([v[n] for n in cont], centre, widths)
                - sum(math.log(len(p.domain.values)) for p in finite)
                + (cls.log_prior(v, only=others) if others else 0.0))

    rows.append(identity_row("proposals", label, sample[:weights], log_q, log_r))
    return rows


class _Chosen(Exception):
    """Raised where a move would start its fit, carrying the place of the object it chose."""

    def __init__(self, place: int) -> None:
        self.place = place


def _stopped_choice(module, fit: str, objects, chosen_of, run: Callable[[], Any]) -> int:
    """The place in ``objects`` of the object a move chooses: the move's own code (``run``)
    run up to the choice, and stopped where its fit, ``module.fit``, would begin;
    ``chosen_of`` reads the chosen object from that call's arguments."""
    original = getattr(module, fit)

    def stop(*args, **_):
        chosen = chosen_of(*args)
        raise _Chosen(next(k for k, o in enumerate(objects) if o is chosen))

    setattr(module, fit, stop)
    try:
        run()
    except _Chosen as chosen:
        return chosen.place
    finally:
        setattr(module, fit, original)
    raise RuntimeError(f"the move made no choice before {fit}")


def merge_partner(sampler: Sampler, trace: Trace, i: int, rng: np.random.Generator) -> int:
    """The partner ``merge.propose_merge`` chooses for object i of ``trace`` (the object it
    fits from)."""
    return _stopped_choice(merge, "merged_fits", trace.objects,
                           lambda sampler_, state, like, *_: like,
                           lambda: merge.propose_merge(sampler, trace, rng, i=i, state=trace))


def merge_first(sampler: Sampler, trace: Trace, rng: np.random.Generator) -> int:
    """The first object ``merge.propose_merge`` takes away in ``trace``."""
    return _stopped_choice(merge, "merged_fits", trace.objects,
                           lambda sampler_, state, like, also, *_: also[0],
                           lambda: merge.propose_merge(sampler, trace, rng, state=trace))


def merge_first_rows(sampler: Sampler, trace: Trace, rng: np.random.Generator,
                     draws: int) -> list[Row]:
    """The first objects ``merge.propose_merge`` takes away in ``trace``, against
    ``redundant.log_probs`` (what its ratio, and its split's reverse, use): ``choice_rows``."""
    log_q = redundant.log_probs(sampler, trace)
    chosen = [merge_first(sampler, trace, rng) for _ in range(draws)]
    return choice_rows(f"merge's first object of {len(trace.objects)}", "objects", chosen,
                       log_q)


def partner_rows(sampler: Sampler, trace: Trace, i: int, rng: np.random.Generator,
                 draws: int) -> list[Row]:
    """The partners ``merge.propose_merge`` chooses for object i, against
    ``merge.partner_log_weights`` (what its ratio and a split's reverse use): chi-square over
    the other objects (bins pooled to expected counts of at least 5), and E[r/q] = 1 with r
    uniform over them."""
    logw = merge.partner_log_weights(trace.objects, i, merge.screen_of(sampler))
    chosen = np.array([merge_partner(sampler, trace, i, rng) for _ in range(draws)])
    label = f"merge partner of object {i} of {len(trace.objects)}"
    from .statistics import chisquare_gof

    others = [j for j in range(len(trace.objects)) if j != i]
    observed = np.array([np.sum(chosen == j) for j in others], dtype=float)
    probs = np.exp(logw[others])
    if np.any(observed[probs == 0.0] > 0):
        rows = [Row("proposals", f"{label}: partners", "chosen with the ratio's probabilities",
                    "a partner of probability 0 was chosen", None, False)]
    else:
        chi2, p = chisquare_gof(observed, probs / probs.sum())
        rows = [Row("proposals", f"{label}: partners",
                    "chosen with the ratio's probabilities (chi-square)",
                    f"chi2={chi2:.1f}, n={draws}", p)]
    n_others = len(others)
    rows.append(identity_row("proposals", label, list(chosen),
                             lambda j: float(logw[j]), lambda j: -math.log(n_others)))
    return rows


def refit_object(sampler: Sampler, trace: Trace, rng: np.random.Generator) -> int:
    """The object ``fit.propose_refit`` chooses in ``trace``."""
    return _stopped_choice(fitting, "refitted_classes", trace.objects,
                           lambda sampler_, state, like: like,
                           lambda: fitting.propose_refit(sampler, trace, rng, state=trace))


def choice_rows(label: str, options: str, chosen, log_q: np.ndarray) -> list[Row]:
    """A discrete choice's draws ``chosen`` against the log probabilities ``log_q`` its ratio
    uses: chi-square over the options (bins pooled to expected counts of at least 5), and
    E[r/q] = 1 with r uniform."""
    from .statistics import chisquare_gof

    n = len(log_q)
    chosen = np.asarray(chosen)
    observed = np.bincount(chosen, minlength=n).astype(float)
    chi2, p = chisquare_gof(observed, np.exp(log_q) / np.exp(log_q).sum())
    return [Row("proposals", f"{label}: {options}",
                "chosen with the ratio's probabilities (chi-square)",
                f"chi2={chi2:.1f}, n={len(chosen)}", p),
            identity_row("proposals", label, list(chosen), lambda k: float(log_q[k]),
                         lambda k: -math.log(n))]


def refit_choice_rows(sampler: Sampler, trace: Trace, rng: np.random.Generator,
                      draws: int) -> list[Row]:
    """The objects ``fit.propose_refit`` chooses in ``trace``, against
    ``misfit.choice_log_probs`` (what its ratio uses, in both states): ``choice_rows``."""
    log_q = misfit.choice_log_probs(sampler, trace)
    chosen = [refit_object(sampler, trace, rng) for _ in range(draws)]
    return choice_rows(f"refit object of {len(trace.objects)}", "objects", chosen, log_q)


def fitted_class_rows(sampler: Sampler, state: Trace, rng: np.random.Generator,
                      draws: int) -> list[Row]:
    """The classes a fitted birth into ``state`` chooses at its first seed
    (``fit.draw_class``), against ``fit.class_log_prob`` (what its ratio, and its death's,
    use): ``choice_rows``. No rows where ``state`` has no seed."""
    seeds = sampler.birth.seeds(state)
    if not len(seeds):
        return []
    _, log_p = fitted_birth.class_choice(sampler, state, seeds[0],
                                         sampler.birth.speck_seeds(state)[0])
    log_q = np.array([fitting.class_log_prob(log_p, c) for c in range(len(log_p))])
    chosen = [fitting.draw_class(rng, log_p) for _ in range(draws)]
    return choice_rows(f"fitted birth's class of {len(log_p)}", "classes", chosen, log_q)


def _from_uniform(counts: np.ndarray) -> float | None:
    """The chi-square distance of a pilot's counts of each option from uniform; None where
    an option was drawn fewer than twice (a wrong density would not show there)."""
    if counts.min() < 2:
        return None
    share = counts / counts.sum()
    return float(np.sum((share - 1 / len(counts)) ** 2) * len(counts))


def _prior_states(sampler: Sampler, noise, rng: np.random.Generator, tries: int, low: int,
                  high: int):
    """Up to ``tries`` states of ``low`` to ``high`` objects (a uniform number) of uniform
    classes drawn from their priors, with their sizes; draws that break a constraint are
    skipped."""
    model = sampler.model
    for _ in range(tries):
        n = low + int(rng.integers(high - low + 1))
        objects = tuple(make_object(model, c, c.sample_prior(rng))
                        for c in (model.classes[int(rng.integers(len(model.classes)))]
                                  for _ in range(n)))
        if all(math.isfinite(o.log_prior) for o in objects):
            yield n, sampler.make_trace(objects, noise)


def misfit_state(sampler: Sampler, noise, rng: np.random.Generator, tries: int = 30,
                 pilot: int = 60):
    """A state of two to five objects (prior draws) whose refit choices, in a pilot of
    ``pilot`` draws from the move itself, are furthest from uniform (chi-square distance),
    every object drawn at least twice; as ``crowded_state``, the pilot looks at the move's
    sampler only. None if no state qualifies."""
    best, best_d = None, 0.0
    for n, trace in _prior_states(sampler, noise, rng, tries, 2, 5):
        d = _from_uniform(np.bincount([refit_object(sampler, trace, rng)
                                       for _ in range(pilot)], minlength=n))
        if d is not None and d > best_d:
            best, best_d = trace, d
    return best


def _uses(sampler: Sampler, *jumps: str) -> bool:
    return any(sampler.jump.get(j, 0.0) > 0 for j in jumps)


def observed_state(model: Model, renderer, *, size: int, seed, sampler_factory=Sampler,
                   tries: int = 40):
    """A sampler scoring fixed observations simulated from a prior scene (verify cameras of
    ``size`` pixels) and a state that leaves an object of it unexplained: the scene less one
    object with a position, chosen where the birth sees unexplained pixels. None when no
    such scene turns up in ``tries`` draws."""
    from ..model.simulate import sample_noise, sample_objects

    rng = np.random.default_rng(seed_sequence(seed))
    sim = Simulator(model, verify_cameras(model, size), renderer)
    for _ in range(tries):
        objects, noise = sample_objects(model, rng), sample_noise(model, rng)
        placed = [k for k, o in enumerate(objects) if o.cls.position]
        if not placed:
            continue
        sampler = sim.sampler(sim.observe(sim.render(objects), noise, rng), rng, sampler_factory)
        for k in placed:
            rest = objects[:k] + objects[k + 1 :]
            state = sampler.make_trace(rest, noise)
            if len(sampler.birth.points(state)) >= 2:
                return sampler, state, objects[k]
    return None


def crowded_state(sampler: Sampler, noise, rng: np.random.Generator, tries: int = 30,
                  pilot: int = 60):
    """A state of three to five objects (prior draws), and an object i of it, whose merge
    partners, in a pilot of ``pilot`` draws from the move itself, are furthest from uniform
    (by chi-square distance) while every one of them is drawn at least twice: where a wrong
    partner density shows, with every partner drawn. The pilot looks at the move's sampler
    only, so a wrong density cannot steer it. None if no state qualifies."""
    best, best_d = None, 0.0
    for n, trace in _prior_states(sampler, noise, rng, tries, 3, 5):
        for i in range(n):
            chosen = [merge_partner(sampler, trace, i, rng) for _ in range(pilot)]
            d = _from_uniform(np.delete(np.bincount(chosen, minlength=n), i))
            if d is not None and d > best_d:
                best, best_d = (trace, i), d
    return best


def check_proposals(model: Model, *, seed=0, size: int = 16, draws: int = 150,
                    weights: int = 3000, partner_draws: int = 1000, renderer=None,
                    sampler_factory=Sampler, alpha: float = ALPHA) -> Report:
    """The sampler-against-density rows and the importance identity of every data-dependent
    proposal the model's sampler makes, on observations simulated from a prior scene:
    the data-driven birth of each class with a position, the refit of the missing object as
    each class (where refits, merges or splits are on), a fitted birth's class (where fitted
    births are on, with two or more classes) and merge partners (where merges or splits are
    on). Rows of proposals that are off, or that no state exercised, are left out
    and named in the notes."""
    if not model.sensors:
        return Report([], alpha, [("proposals: the model has no sensors; no proposal looks at "
                                   "observations.")])
    if renderer is None:
        from ..render import Renderer

        renderer = Renderer(model.render)
    seed_state, seed_draws = seed_sequence(seed).spawn(2)
    found = observed_state(model, renderer, size=size, seed=seed_state,
                           sampler_factory=sampler_factory)
    rng = np.random.default_rng(seed_draws)
    if found is None:
        return Report([], alpha, [(f"proposals: no prior scene left pixels unexplained on the "
                                   f"{size}x{size} verify cameras; nothing was tested.")])
    sampler, state, missing = found
    rows: list[Row] = []
    notes: list[str] = []
    if sampler.birth.weight > 0 and _uses(sampler, "birth", "replace", "split", "refit",
                                           "merge", "fitted_split", "fitted_merge",
                                           "pair_refit"):
        for cls in model.classes:
            if cls.position:
                rows += birth_rows(sampler, state, cls, rng, draws, weights)
    else:
        notes.append("proposals: births do not look at the observations (data_birth = 0).")
    if _uses(sampler, "refit", "merge", "split", "fitted_birth", "fitted_death",
             "fitted_split", "fitted_merge", "pair_refit"):
        for cls in model.classes:
            rows += refit_rows(sampler, state, cls, missing, rng, draws, weights)
    if _uses(sampler, "refit") and model.inference.refit_focus > 0.0:
        chosen = misfit_state(sampler, state.noise, rng)
        if chosen is None:
            notes.append("proposals: no state of two or more objects gave the refit's choice "
                         "of object any doubt; the choice untested.")
        else:
            rows += refit_choice_rows(sampler, chosen, rng, partner_draws)
    if _uses(sampler, "fitted_birth", "fitted_death", "fitted_split", "fitted_merge") and \
            len(fitted_birth.placed_classes(model)) > 1:
        classes = fitted_class_rows(sampler, state, rng, partner_draws)
        if not classes:
            notes.append("proposals: the scene less one object left no seed for a fitted "
                         "birth; its choice of class untested.")
        rows += classes
    if _uses(sampler, "merge", "split", "fitted_split", "fitted_merge"):
        crowded = crowded_state(sampler, state.noise, rng)
        if crowded is None:
            first = (" and the merge's choice of its first object"
                     if _uses(sampler, "merge", "split") and model.inference.merge_focus > 0.0
                     else "")
            notes.append("proposals: no state of three or more objects gave a merge partner "
                         f"any doubt; partners{first} untested.")
        else:
            rows += partner_rows(sampler, *crowded, rng, partner_draws)
            if _uses(sampler, "merge", "split") and model.inference.merge_focus > 0.0:
                rows += merge_first_rows(sampler, crowded[0], rng, partner_draws)
    notes.append(f"proposals: {size}x{size} verify cameras, the scene less one "
                 f"{missing.cls.name} ({len(sampler.birth.points(state))} unexplained points); "
                 f"{draws} draws per transform, {weights} per identity.")
    return Report(rows, alpha, notes)
