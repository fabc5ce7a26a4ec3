"""Exactness checks of the proposals whose densities look at the observations.

Prior recovery runs without observations, so it never switches on the proposals that look at
them: births near unexplained pixels (``sppl.birth``, also used by replaces, splits, the
refit's mixture and multiple tries), refits fitted to the pixels (``sppl.fit``, also merges'
and splits'), and merge partners chosen by distance in the image (``sppl.merge``). Geweke's
test runs them, but its power against a wrong density is small: a birth density replaced by
the prior passes it. So these checks hold the observations fixed and test each such proposal
directly, with the very functions the moves call to draw from it and to score it:

- ``sampler against density``: draws from the proposal's sampler, and for each coordinate the
  conditional probability integral transform u = F(v_j | the draw's other coordinates), F
  computed from the proposal's own log density by quadrature along that coordinate (by sums
  over a categorical one, randomised within the atom). If the density is the sampler's, every
  u is uniform (Rosenblatt); Kolmogorov-Smirnov tests it. For a merge partner (a discrete
  choice), chi-square of the chosen partners against the probabilities the ratio uses.
- ``importance identity``: for a normalised reference density r that is zero outside a
  bounded region B (a normal truncated to B, around what the proposal aims at, times the
  prior of the coordinates the proposal draws from the prior), E_{v ~ sampler}[r(v) / q(v)]
  = 1 whenever q > 0 on B. A density that is not the sampler's (the prior in its place, a
  wrong spread) moves the mean; a z-test on the mean of these bounded weights decides.
- ``joint_check``: a chain with every data-driven move switched on, on fixed tiny images,
  against the exact posterior of a model with at most one or two objects whose parameters
  are all bounded, computed by quadrature over a grid of the objects' parameters (one render
  per cell, or pair of cells) and of the noise scales. Many short chains start from exact posterior draws, so their final
  states are independent posterior draws if every move is right: the count by chi-square,
  a parameter of one object by KS against the grid's marginal, the noise scales by KS. In
  principle it sees a consistent ratio for the wrong target, which the first two cannot (the
  thesis's literal birth ratio, on two objects); in practice its power is where births and
  deaths are often accepted, which a sharp likelihood prevents (docs/inference.md says what
  it caught).

Every statistical row carries its p-value, and a ``Report`` decides them together with Holm's
correction at its ``alpha`` (the family-wise false-alarm rate of the whole report).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import stats

from . import fit as fitting
from . import merge
from .chain import Sampler
from .domains import Finite, Integer, Interval, Periodic
from .model import Model, ObjectClass
from .trace import SceneObject, Trace, make_object
from .verify import ALPHA, Report, Row, _seq, _Simulator, verify_cameras

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


# ---------------------------------------------------------------------------------------------
# Conditional probability integral transforms


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


# ---------------------------------------------------------------------------------------------
# Ranges and grids


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


# ---------------------------------------------------------------------------------------------
# The data-driven birth


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


# ---------------------------------------------------------------------------------------------
# The refit proposal


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


# ---------------------------------------------------------------------------------------------
# Merge partners


class _Chosen(Exception):
    """Raised where a merge would start its fit, carrying the partner it chose."""

    def __init__(self, place: int) -> None:
        self.place = place


def merge_partner(sampler: Sampler, trace: Trace, i: int, rng: np.random.Generator) -> int:
    """The partner ``merge.propose_merge`` chooses for object i of ``trace``: the move's own
    code run up to the choice, and stopped where its fit would begin."""
    objects = trace.objects
    original = merge._refitted

    def stop(sampler_, state, like, rng_, target):
        raise _Chosen(next(k for k, o in enumerate(objects) if o is like))

    merge._refitted = stop
    try:
        merge.propose_merge(sampler, trace, rng, i=i, state=trace)
    except _Chosen as chosen:
        return chosen.place
    finally:
        merge._refitted = original
    raise RuntimeError("propose_merge made no choice of partner")


def partner_rows(sampler: Sampler, trace: Trace, i: int, rng: np.random.Generator,
                 draws: int) -> list[Row]:
    """The partners ``merge.propose_merge`` chooses for object i, against
    ``merge.partner_log_weights`` (what its ratio and a split's reverse use): chi-square over
    the other objects (bins pooled to expected counts of at least 5), and E[r/q] = 1 with r
    uniform over them."""
    logw = merge.partner_log_weights(trace.objects, i, merge.screen_of(sampler))
    chosen = np.array([merge_partner(sampler, trace, i, rng) for _ in range(draws)])
    label = f"merge partner of object {i} of {len(trace.objects)}"
    from .verify import chisquare_gof

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


# ---------------------------------------------------------------------------------------------
# For a model: fixed observations, states that leave something unexplained


def _uses(sampler: Sampler, *jumps: str) -> bool:
    return any(sampler.jump.get(j, 0.0) > 0 for j in jumps)


def observed_state(model: Model, renderer, *, size: int, seed, sampler_factory=Sampler,
                   tries: int = 40):
    """A sampler scoring fixed observations simulated from a prior scene (verify cameras of
    ``size`` pixels) and a state that leaves an object of it unexplained: the scene less one
    object with a position, chosen where the birth sees unexplained pixels. None when no
    such scene turns up in ``tries`` draws."""
    from .simulate import sample_noise, sample_objects

    rng = np.random.default_rng(_seq(seed))
    sim = _Simulator(model, verify_cameras(model, size), renderer)
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
    model = sampler.model
    best, best_d = None, 0.0
    for _ in range(tries):
        n = 3 + int(rng.integers(3))
        objects = tuple(make_object(model, c, c.sample_prior(rng))
                        for c in (model.classes[int(rng.integers(len(model.classes)))]
                                  for _ in range(n)))
        if any(not math.isfinite(o.log_prior) for o in objects):
            continue
        trace = sampler.make_trace(objects, noise)
        for i in range(n):
            chosen = [merge_partner(sampler, trace, i, rng) for _ in range(pilot)]
            f = np.delete(np.bincount(chosen, minlength=n), i)
            if f.min() < 2:
                continue
            d = float(np.sum((f / pilot - 1 / len(f)) ** 2) * len(f))
            if d > best_d:
                best, best_d = (trace, i), d
    return best


def check_proposals(model: Model, *, seed=0, size: int = 16, draws: int = 150,
                    weights: int = 3000, partner_draws: int = 1000, renderer=None,
                    sampler_factory=Sampler, alpha: float = ALPHA) -> Report:
    """The sampler-against-density rows and the importance identity of every data-dependent
    proposal the model's sampler makes, on observations simulated from a prior scene:
    the data-driven birth of each class with a position, the refit of the missing object as
    each class (where refits, merges or splits are on), and merge partners (where merges or
    splits are on). Rows of proposals that are off, or that no state exercised, are left out
    and named in the notes."""
    if not model.sensors:
        return Report([], alpha, [("proposals: the model has no sensors; no proposal looks at "
                                   "observations.")])
    if renderer is None:
        from .render import Renderer

        renderer = Renderer(model.render)
    seed_state, seed_draws = _seq(seed).spawn(2)
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
                                           "merge"):
        for cls in model.classes:
            if cls.position:
                rows += birth_rows(sampler, state, cls, rng, draws, weights)
    else:
        notes.append("proposals: births do not look at the observations (data_birth = 0).")
    if _uses(sampler, "refit", "merge", "split", "fitted_birth", "fitted_death"):
        for cls in model.classes:
            rows += refit_rows(sampler, state, cls, missing, rng, draws, weights)
    if _uses(sampler, "merge", "split"):
        crowded = crowded_state(sampler, state.noise, rng)
        if crowded is None:
            notes.append("proposals: no state of three or more objects gave a merge partner "
                         "any doubt; partners untested.")
        else:
            rows += partner_rows(sampler, *crowded, rng, partner_draws)
    notes.append(f"proposals: {size}x{size} verify cameras, the scene less one "
                 f"{missing.cls.name} ({len(sampler.birth.points(state))} unexplained points); "
                 f"{draws} draws per transform, {weights} per identity.")
    return Report(rows, alpha, notes)


# ---------------------------------------------------------------------------------------------
# The chain against the exact posterior


class GridPosterior:
    """The exact posterior, given fixed observations, of a model with at most one or two
    objects whose parameters are intervals or categorical, by quadrature.

    Each class's parameters are put on a grid (``cells`` midpoints across each interval
    parameter, or ``cells[name]`` across parameter ``name``: one where the likelihood does
    not depend on it; every value of a categorical one), refined once to ``cells`` midpoints across
    the box of coarse cells within e^-REFINE of the best single object (what mass a single
    object leaves outside it is ``outside_log``). The hypotheses are the empty scene, one
    object in any cell, and (where two objects are allowed) an unordered pair of cells, each
    rendered once; a pair of the same cell counts half, as a set of two objects does under
    the unit-rate Poisson process. Each sensor's noise scale is integrated out per
    hypothesis on a grid over its prior's range (the trapezoid rule in the scale). The error
    is the grid's: the likelihood's change across a cell, the midpoint rule's, second order in
    the cell's width."""

    REFINE = 25.0

    def __init__(self, sampler: Sampler, cells: int | Mapping[str, int],
                 rng: np.random.Generator,
                 noise_cells: int = 400) -> None:
        model = sampler.model
        self.model, self.sampler, self.cells = model, sampler, cells
        self.noise_axes = {}
        for kind, sensor in model.sensors.items():
            (par,) = sensor.noise
            xs = [par.prior.sample(rng) for _ in range(RANGE_DRAWS)]
            # Steps of about 1.5% for a prior's usual range: a scale's posterior from a few
            # hundred values is about 5% wide.
            self.noise_axes[kind] = (par.name, np.geomspace(min(xs) / 3, 3 * max(xs),
                                                            noise_cells))
        self.half: dict[str, dict[str, float]] = {}  # class name -> a cell's half widths
        self.outside_log = -math.inf
        atoms = []  # (class, values, log volume of its cell)
        for cls in model.classes:
            bounds = {p.name: (p.domain.low, p.domain.high) for p in cls.parameters
                      if not isinstance(p.domain, Finite)}
            coarse = self._atoms(cls, bounds)
            weights = np.array([self._weight((a,))[0] for a in coarse])
            top = np.max(weights)
            fine_bounds = {}
            for name, (lo, hi) in bounds.items():
                step = (hi - lo) / (cells if isinstance(cells, int) else cells[name])
                near = [a[1][name] for a, w in zip(coarse, weights) if w > top - self.REFINE]
                fine_bounds[name] = (max(lo, min(near) - 1.5 * step),
                                     min(hi, max(near) + 1.5 * step))
            out = [w for a, w in zip(coarse, weights) if any(
                not (fine_bounds[n][0] <= a[1][n] <= fine_bounds[n][1]) for n in bounds)]
            if out:
                self.outside_log = max(self.outside_log, float(
                    np.logaddexp.reduce(out) - np.logaddexp.reduce(weights)))
            atoms += self._atoms(cls, fine_bounds)
        self.atoms = atoms
        sets = [()] + [(a,) for a in range(len(atoms))]
        if (model.max_objects or 1) >= 2:
            sets += [(a, b) for a in range(len(atoms)) for b in range(a, len(atoms))]
        self.sets = sets
        self.logs, self.curves = [], []
        for k in sets:
            w, curves = self._weight(tuple(atoms[a] for a in k))
            self.logs.append(w - (math.log(2.0) if len(k) == 2 and k[0] == k[1] else 0.0))
            self.curves.append(curves)
        self.logs = np.array(self.logs)
        self._normalise()

    def _normalise(self) -> None:
        self.probs = np.exp(self.logs - np.logaddexp.reduce(self.logs))

    def _atoms(self, cls: ObjectClass, bounds):
        axes, half = {}, {}
        for p in cls.parameters:
            if isinstance(p.domain, Finite):
                axes[p.name] = tuple(p.domain.values)
            else:
                lo, hi = bounds[p.name]
                n = self.cells if isinstance(self.cells, int) else self.cells[p.name]
                axes[p.name] = lo + (hi - lo) * (np.arange(n) + 0.5) / n
                half[p.name] = 0.5 * (hi - lo) / n
        self.half[cls.name] = half
        volume = sum(math.log(2 * h) for h in half.values())
        return [(cls, {n: (float(v) if not isinstance(v, str) else v)
                       for n, v in zip(axes, combo)}, volume)
                for combo in _product(list(axes.values()))]

    def _weight(self, atoms):
        """log of the posterior mass of these objects' cells (unnormalised), and each
        sensor's log integrand over its grid of noise scales."""
        from .trace import objects_log_prior

        model, scorer = self.model, self.sampler.scorer
        objects = tuple(make_object(model, cls, values) for cls, values, _ in atoms)
        if any(not math.isfinite(o.log_prior) for o in objects):
            return -math.inf, None
        stats_, _ = scorer.evaluate(objects)
        curves = {}
        total = objects_log_prior(model, objects) + sum(v for _, _, v in atoms)
        for kind, (name, sigmas) in self.noise_axes.items():
            curve = np.array([
                noise_log_prior_of(model, kind, name, s)
                + sum(t.likelihood.log_prob(stats_[(t.frame, t.kind)], {name: s})
                      for t in scorer.terms if t.kind == kind)
                for s in sigmas])
            curves[kind] = curve
            total += _log_trapezoid(curve, sigmas)
        return total, curves

    def p_count(self) -> dict[tuple[str, ...], float]:
        """Posterior probability of each multiset of classes (sorted names; () for none)."""
        out: dict[tuple[str, ...], float] = {}
        for k, p in zip(self.sets, self.probs):
            key = tuple(sorted(self.atoms[a][0].name for a in k))
            out[key] = out.get(key, 0.0) + float(p)
        return out

    def scale_rates(self, p_empty: float, model: Model, sampler: Sampler) -> float:
        """Scale every class's rate by the one factor f that makes the empty scene's
        posterior probability ``p_empty``, for ``model`` (the same with those rates), whose
        chains ``sampler`` runs: a hypothesis of n objects gains n log f (the total rate's
        exp(-sum) is the same in every one and cancels). Returns f."""
        n = np.array([len(k) for k in self.sets])
        mass = [float(np.sum(self.probs[n == j])) for j in range(3)]
        # p_empty (m0 + m1 f + m2 f^2) = m0
        a, b, c = p_empty * mass[2], p_empty * mass[1], (p_empty - 1.0) * mass[0]
        f = -c / b if a == 0.0 else (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
        self.logs = self.logs + n * math.log(f)
        self._normalise()
        by_name = {c.name: c for c in model.classes}
        self.atoms = [(by_name[c.name], v, w) for c, v, w in self.atoms]
        self.model, self.sampler = model, sampler
        return f

    def draw(self, rng: np.random.Generator):
        """A draw of (objects, noise): a hypothesis by its probability, each object's values
        uniform within its cell, each noise scale from its conditional on the hypothesis's
        grid of scales."""
        k = int(rng.choice(len(self.probs), p=self.probs))
        objects = []
        for a in self.sets[k]:
            cls, values, _ = self.atoms[a]
            values = dict(values)
            for name, half in self.half[cls.name].items():
                values[name] = float(values[name] + rng.uniform(-half, half))
            objects.append(make_object(self.model, cls, values))
        objects = [objects[i] for i in rng.permutation(len(objects))]
        noise = {}
        for kind, (name, sigmas) in self.noise_axes.items():
            curve = self.curves[k][kind]
            d = np.exp(curve - curve.max())
            w = 0.5 * (d[1:] + d[:-1]) * np.diff(sigmas)  # the trapezoids' masses
            i = int(rng.choice(len(w), p=w / w.sum()))
            noise[kind] = {name: float(rng.uniform(sigmas[i], sigmas[i + 1]))}
        return tuple(objects), noise

    def _one_object(self, cls: ObjectClass):
        """(cell values, probability) of a uniformly chosen object of the scene, given that
        it is of class ``cls``."""
        out = []
        for k, p in zip(self.sets, self.probs):
            for a in k:
                if self.atoms[a][0].name == cls.name and p > 0:
                    out.append((self.atoms[a][1], p / len(k)))
        total = sum(p for _, p in out)
        return [(v, p / total) for v, p in out]

    def marginal_cdf(self, cls: ObjectClass, name: str) -> Callable[[np.ndarray], np.ndarray]:
        """The cdf of parameter ``name`` of a uniformly chosen object of class ``cls``:
        piecewise linear across the cells (uniform within each, as ``draw`` draws)."""
        half = self.half[cls.name][name]
        mass: dict[float, float] = {}
        for values, p in self._one_object(cls):
            mass[values[name]] = mass.get(values[name], 0.0) + p
        centres = np.array(sorted(mass))
        m = np.array([mass[c] for c in centres])
        edges = np.stack([centres - half, centres + half], axis=1).ravel()
        cum = np.stack([np.concatenate([[0.0], np.cumsum(m)[:-1]]), np.cumsum(m)],
                       axis=1).ravel()
        return lambda x: np.interp(x, edges, cum)

    def categorical(self, cls: ObjectClass, name: str) -> dict[Any, float]:
        out: dict[Any, float] = {}
        for values, p in self._one_object(cls):
            out[values[name]] = out.get(values[name], 0.0) + p
        return out

    def noise_cdf(self, kind: str) -> Callable[[np.ndarray], np.ndarray]:
        _, sigmas = self.noise_axes[kind]
        dens = np.zeros(len(sigmas))
        for curves, p in zip(self.curves, self.probs):
            if p == 0.0:
                continue
            c = curves[kind]
            w = np.exp(c - c.max())
            dens += p * w / np.trapezoid(w, sigmas)
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(sigmas))])
        cum /= cum[-1]
        return lambda x: np.interp(x, sigmas, cum)


def noise_log_prior_of(model: Model, kind: str, name: str, value: float) -> float:
    par = next(p for p in model.sensors[kind].noise if p.name == name)
    return par.log_prob(value)


def _log_trapezoid(log_f: np.ndarray, xs: np.ndarray) -> float:
    top = float(np.max(log_f))
    return top + math.log(float(np.trapezoid(np.exp(log_f - top), xs)))


def _product(axes):
    import itertools

    return itertools.product(*axes)


def joint_ready(model: Model) -> str | None:
    """Why ``joint_check`` cannot compute the exact posterior of ``model``, or None."""
    if model.max_objects not in (1, 2):
        return "it needs a model of at most one or two objects (max_objects = 1 or 2)"
    if any(c.count is not None for c in model.classes):
        return "it needs Poisson counts, not fixed ones"
    for c in model.classes:
        for p in c.parameters:
            if not isinstance(p.domain, Interval | Finite) or p.prior_fn is not None:
                return (f"{c.name}.{p.name} is not an interval or categorical parameter with "
                        "an independent prior")
    if not model.sensors or any(len(s.noise) != 1 for s in model.sensors.values()):
        return "it needs sensors with one noise scale each"
    return None


def joint_check(model: Model, truth, truth_noise, *, chains: int = 200, length: int = 8,
                cells: int | Mapping[str, int] = 31, size: int = 16, seed=0,
                p_empty: float | None = None,
                renderer=None, sampler_factory=Sampler, alpha: float = ALPHA) -> Report:
    """Many short chains, with every move of the model's sampler (data-driven births,
    refits, replaces, merges and splits where two objects are allowed) on fixed observations
    simulated from ``truth`` (objects) and ``truth_noise`` on the ``size`` pixel verify
    cameras, each started from an exact draw of the posterior (``GridPosterior``) and run
    ``length`` sweeps. If every move leaves the posterior invariant, their final states are
    independent posterior draws; they are compared with the exact posterior: the classes of
    the objects (the count, with one class) by chi-square, a parameter of one object of the
    scene chosen uniformly by KS (chi-square for a categorical one), each noise scale by KS.

    With ``p_empty``, every class's rate is scaled by the one factor that gives the empty
    scene that posterior probability (any rates make a valid model, and no move depends on
    them): births and deaths must be accepted for their ratios to show, and they are where
    no count is certain. The false-alarm rate is ``alpha`` (Holm over the rows), up to the
    grid's error."""
    from .errors import SpplError
    from .verify import _count_data_births, _finished_warmup, chisquare_gof

    why = joint_ready(model)
    if why is not None:
        raise SpplError(f"joint_check: {why}")
    if renderer is None:
        from .render import Renderer

        renderer = Renderer(model.render)
    obs_seq, grid_seq, chain_seq, warm_seq = _seq(seed).spawn(4)
    sim = _Simulator(model, verify_cameras(model, size), renderer)
    observations = sim.observe(sim.render(truth), truth_noise, np.random.default_rng(obs_seq))
    rng = np.random.default_rng(chain_seq)
    warmup = _finished_warmup(model, np.random.default_rng(warm_seq))
    sampler = sim.sampler(observations, rng, sampler_factory, warmup=warmup)
    exact = GridPosterior(sampler, cells, np.random.default_rng(grid_seq))
    scaled = ""
    if p_empty is not None:
        factor = exact.scale_rates(p_empty, model, sampler)
        model = replace(model, classes=tuple(replace(c, rate=c.rate * factor)
                                             for c in model.classes))
        sim.model = model
        sampler = sim.sampler(observations, rng, sampler_factory, warmup=warmup)
        exact.scale_rates(p_empty, model, sampler)  # factor 1 now: the classes swapped in
        scaled = f" (rates scaled by {factor:.3g})"
    data_births = [0, 0]
    _count_data_births(sampler, data_births)
    finals = []
    for _ in range(chains):
        objects, noise = exact.draw(rng)
        trace = sampler.make_trace(objects, noise)
        for _ in range(length):
            trace = sampler.sweep(trace)
        finals.append(trace)

    rows = []
    p_count = exact.p_count()
    keys = sorted(p_count)
    seen = [tuple(sorted(o.cls.name for o in t.objects)) for t in finals]
    observed = [sum(s == k for s in seen) for k in keys]
    p = chisquare_gof(observed, [p_count[k] for k in keys])[1]
    shares = lambda xs: ", ".join(f"{'+'.join(k) or 'none'} {x:.3f}"
                                  for k, x in zip(keys, xs))
    rows.append(Row("joint", "objects in the scene", shares([p_count[k] for k in keys]),
                    shares([o / len(finals) for o in observed]) + f" (n={len(finals)})", p))
    for cls in model.classes:
        picked = [t.objects[int(rng.integers(len(t.objects)))] for t in finals if t.objects]
        objs = [o for o in picked if o.cls.name == cls.name]
        if len(objs) < 20:
            continue
        for par in cls.parameters:
            if isinstance(par.domain, Finite):
                probs = exact.categorical(cls, par.name)
                counts = [sum(o.values[par.name] == v for o in objs) for v in probs]
                p = chisquare_gof(counts, list(probs.values()))[1]
                rows.append(Row("joint", f"{cls.name}.{par.name} of an object",
                                "exact posterior (chi-square)", f"n={len(objs)}", p))
                continue
            xs = np.array([o.values[par.name] for o in objs])
            ks = stats.kstest(xs, exact.marginal_cdf(cls, par.name))
            rows.append(Row("joint", f"{cls.name}.{par.name} of an object",
                            "exact posterior (KS)", f"n={len(objs)}, D={ks.statistic:.3f}",
                            float(ks.pvalue)))
    for kind, (name, _) in exact.noise_axes.items():
        ks = stats.kstest(np.array([t.noise[kind][name] for t in finals]), exact.noise_cdf(kind))
        rows.append(Row("joint", f"{kind}.{name}", "exact posterior (KS)",
                        f"n={len(finals)}, D={ks.statistic:.3f}", float(ks.pvalue)))
    by_move = sampler.stats.by_move()
    notes = [f"joint: {chains} chains of {length} sweeps from exact posterior draws{scaled}; "
             f"{len(exact.atoms)} cells, grid mass left out {math.exp(exact.outside_log):.1e}; "
             f"{size}x{size} verify cameras; {data_births[1]} of {data_births[0]} birth "
             "proposals could use unexplained pixels; accepted/proposed: "
             + ", ".join(f"{m} {a}/{n}" for m, (n, a) in sorted(by_move.items()))]
    return Report(rows, alpha, notes)
