"""The chain against the exact posterior of a tiny world (``joint_check``).

A chain with every data-driven move switched on, on fixed tiny images, against the exact posterior of a model with at most one or two objects whose parameters
are all bounded, computed by quadrature over a grid of the objects' parameters (one render
per cell, or pair of cells) and of the noise scales. Many short chains start from exact posterior draws, so their final
states are independent posterior draws if every move is right: the count by chi-square,
a parameter of one object by KS against the grid's marginal, the noise scales by KS. In
principle it sees a consistent ratio for the wrong target, which the proposal checks (``sppl.verify.proposals``) cannot (the
thesis's literal birth ratio, on two objects); in practice its power is where births and
deaths are often accepted, which a sharp likelihood prevents (docs/inference.md says what
it caught).

Its rows are decided together with Holm's correction, like every report's."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import stats

from ..infer.chain import Sampler
from ..model.domains import Finite, Interval
from ..model.trace import make_object
from ..model.types import Model, ObjectClass
from .proposals import RANGE_DRAWS
from .report import ALPHA, Report, Row
from .simulated import Simulator, verify_cameras
from .statistics import seed_sequence


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
        from ..model.trace import objects_log_prior

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
    from ..errors import SpplError
    from .joint import count_data_births
    from .simulated import finished_warmup
    from .statistics import chisquare_gof

    why = joint_ready(model)
    if why is not None:
        raise SpplError(f"joint_check: {why}")
    if renderer is None:
        from ..render import Renderer

        renderer = Renderer(model.render)
    obs_seq, grid_seq, chain_seq, warm_seq = seed_sequence(seed).spawn(4)
    sim = Simulator(model, verify_cameras(model, size), renderer)
    observations = sim.observe(sim.render(truth), truth_noise, np.random.default_rng(obs_seq))
    rng = np.random.default_rng(chain_seq)
    warmup = finished_warmup(model, np.random.default_rng(warm_seq))
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
    count_data_births(sampler, data_births)
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
