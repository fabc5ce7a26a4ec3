"""The refit jump: replace an object by one of any class fitted to the pixels it explains.

A sphere that the chain grew where a cube stands cannot become that cube by any one move that
draws the cube's size and angle from the prior: the chance that a draw lands close enough to
be accepted is around one in a million. The refit jump instead *fits* the new object to the
observations first. It picks object k (where the observations disagree with the state:
``sppl.infer.misfit``), removes k, and runs for every class c a short deterministic search
for the parameters of a c-object that maximise the posterior of the scene without k plus that
object, starting from k's own values (by name) and its place; it chooses the class by those
fits (``class_log_probs``: P(c | x-, k) = 0.95 softmax of their log joints + 0.05 / K).
The proposal is then a mixture of the fit and a birth into x- (``sppl.infer.birth``, the replace
jump's proposal), B the model's ``fit_births`` setting, so that a refit can also leave a state
the fit does not explain:

    y ~ q(y | x-, k) = (1 - B) q_fit(y | x-, k) + B q_birth(y | x-)
    q_fit(y | x-, k) = (1/3) sum_c N(continuous parameters; fitted, diag((c s)^2))
                       x P(categorical parameters | fitted: the fitted value w.p. 1 - EPS)
                       x prior(integer parameters)

with s each parameter's random-walk step and c in SPREADS (half a step, a twentieth, a
two-hundredth: a fit that is off, or one inside a posterior millimetres wide). It is a
proper, computable density because the fit is a deterministic function of the scene without
k (x-) and of k. The reverse picks the new object and k's class, fits a
k-class object from the new object's values in the same x-, and must propose k exactly:

    alpha_refit = pi(x- + y) q(old | x-, y) / (pi(x- + old) q(y | x-, old)).

The class choices are P(c | x-, old) forward and P(c_old | x-, y) back (the reverse fits
every class from y, deferred with its fit); the object's is q(k | y) / q(k | x) of
``sppl.infer.misfit`` (the proposal's ``ratio_fn``). Proposals outside a
parameter's domain have zero prior and are rejected, so the Gaussians need no truncation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize

from ..model.domains import Finite, Periodic
from ..model.geometry import span
from ..model.trace import SceneObject, Trace, make_object
from ..model.types import ObjectClass
from ..render.bounds import world_corners
from . import misfit
from .moves import Proposal

# Chance that a categorical parameter is not the fitted value (then uniform among the rest).
EPS = 0.2
# The search: passes over the continuous parameters, first step (in random-walk steps), and
# how often a step is halved when no move improves the fit.
START_STEP = 4.0
# The spreads of the draw around the fit, in random-walk steps, one chosen uniformly per draw:
# wide enough to leave a fit that is off, and narrow enough to land inside a posterior that
# is millimetres wide, as a visible object's is at 96x96 pixels and a few percent noise.
SPREADS = (0.5, 0.05, 0.005)
HALVINGS = 6
MAX_EVALUATIONS = 100
# A fit from a seed (a fitted birth's) also runs its search once more, that time first over
# the object's other continuous parameters with its place held at the seed (at most this many
# scores), the better fit winning. The seed is the middle of the pixels left unexplained, a
# few centimetres from an object that small; a search from a prior draw's size (tens of
# centimetres) moved the place in steps of 40 cm as it shrank, and no object 4 cm wide it
# then came to was near those pixels (shapes.scn's prior scene 2: a sphere 4 cm wide, worth 56
# nats, its seed 3 cm from it, fitted 13 cm away with nothing explained). A large object's
# seed is tens of centimetres from its centre, where the held search fits a small one: it
# needs the search that moves the place from the start.
SETTLE_EVALUATIONS = 40
# Where the search starts for the parameters the object it replaces does not have (a cube's
# side and angle where a sphere stood): the best of this many fixed draws of the class's
# prior. A single draw starts a small cube's fit from a side of 0.6 m, a size from which the
# search walks off to a local optimum far from the pixels.
START_DRAWS = 16
# An angle's score has a local optimum at each turn where an edge lines up, which a search by
# steps does not leave: before it, each periodic parameter is tried at this many turns evenly
# spread over its period.
TURNS = 8
# A fit from a speck's seed whose every start has zero prior also starts from them with their
# sizes scaled so: a pole 4 cm thick beside a cube, fitted from draws of the cylinder's prior,
# none thinner than 20 cm, overlaps the cube from every start. Only there: at a blob's seed,
# which may be a misplaced object's rim, a shrunk start fits a sliver into the rim that the
# chain then holds (every start of such a fit overlapping the object keeps it out).
SHRINK = (0.5, 0.25, 0.125, 0.0625)
# The anchored steps after a merge's pattern search (``_Search.anchored``, the model's
# ``merge_anchor`` scores at most): a size or angle stepped with the place moved so that one
# corner of the object stays put, from this many random-walk steps, halved this often. A
# cube turned 3 degrees too far and shifted to make up for it stands on a ridge that no step
# of one parameter climbs: each alone uncovers or overpaints a column of pixels
# (examples/occlusion, a merge's fit: 152 nats gained by turning it about a corner, 62 more
# by the pattern search after).
ANCHOR_STEP = 0.5
ANCHOR_HALVINGS = 4
# A fitted birth's class, a merged object's and a refitted one's, is the class whose fit
# explains the pixels best, but for this share of the moves, whose class is uniform. With the
# class uniform, the first object a chain fitted to a large cone was as often a cube, a
# cylinder or a sphere, each accepted (anything explains a blob better than nothing), and the
# cone's pixels the cube left were then explained by pieces that no later single move could
# take back (shapes_plus.scn's prior scene 16: a cone fitted at the first seed scores 42,181
# against the empty scene, a cube 19,110, a cylinder 23,382). The share keeps every class
# proposable where the fits rank them wrong.
UNIFORM = 0.05
_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Refit:
    """What a refit jump used: the scene without the object, for its reverse."""

    state: Trace
    place: int

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        old = before.objects[self.place]
        return propose_refit(sampler, after, sampler.rng, k=self.place, cls=old.cls,
                             target=old, state=self.state)


def _starts(cls: ObjectClass, like: SceneObject, keep=None) -> list[dict[str, Any]]:
    """Where the search may start: the values of ``like`` that ``cls`` has (by name and
    domain; only those named in ``keep`` if given), the others from each of START_DRAWS fixed
    draws of the class's prior (one draw where every parameter is kept)."""
    shared = [p.name for p in cls.parameters
              if (keep is None or p.name in keep)
              and (q := like.cls.parameter(p.name)) is not None and q.domain == p.domain]
    rng = np.random.default_rng(0)
    draws = START_DRAWS if len(shared) < len(cls.parameters) else 1
    starts = []
    for _ in range(draws):
        values = cls.sample_prior(rng)
        values.update({n: like.values[n] for n in shared})
        starts.append(values)
    size = span(like.parts) if keep is None and like.cls.name != cls.name else 0.0
    if size > 0.0:
        starts += [_sized(cls, v, size) for v in starts]
    return starts


def _sizes(cls: ObjectClass) -> list[str]:
    """The names of a class's sizes: its continuous parameters other than its place and
    angles."""
    return [p.name for p in cls.parameters if p.continuous and not isinstance(p.domain, Periodic)
            and p.name not in (cls.position or ())]


def _sized(cls: ObjectClass, values, size: float) -> dict[str, Any]:
    """``values`` with its sizes scaled so that the object's span (``geometry.span``) is
    ``size``, the span of the object it replaces; twice, for classes whose span does not
    grow in proportion to their sizes."""
    for _ in range(2):
        own = span(cls.parts(values))
        if not (own > 0.0 and math.isfinite(own)):
            break
        values = {**values, **{n: values[n] * size / own for n in _sizes(cls)}}
    return values


def _shrunk(cls: ObjectClass, values) -> list[dict[str, Any]]:
    """``values`` with its sizes (the continuous parameters other than its place and angles)
    scaled by each of SHRINK."""
    return [{**values, **{n: values[n] * f for n in _sizes(cls)}} for f in SHRINK]


def _score(sampler, state: Trace, cls: ObjectClass, values) -> float:
    obj = make_object(sampler.model, cls, values)
    p = Proposal("birth", cls.name, state.objects + (obj,), state.noise, (obj,))
    new = sampler.evaluate(state, p)
    return -math.inf if new is None else new.score


class _Scores:
    """``_score`` of one class's objects in one state, each point scored once: a pattern
    search steps back onto points it has scored, and the searches of one fit share their
    starts (about one trial in nine is such a repeat). A repeat still counts as an
    evaluation where a search counts them, so the fit is the same as without the memo."""

    def __init__(self, sampler, state: Trace, cls: ObjectClass) -> None:
        self.sampler, self.state, self.cls = sampler, state, cls
        self.names = tuple(p.name for p in cls.parameters)
        self.known: dict[tuple, float] = {}

    def __call__(self, values) -> float:
        key = tuple(values[n] for n in self.names)
        s = self.known.get(key)
        if s is None:
            s = self.known[key] = _score(self.sampler, self.state, self.cls, values)
        return s


class _Search:
    """The best values found so far, and each trial's score against them."""

    def __init__(self, score: _Scores, values, best: float) -> None:
        self.score, self.cls = score, score.cls
        self.values, self.best, self.evaluations = values, best, 0

    def trial(self, name: str, value, **also) -> bool:
        trial = {**self.values, name: value, **also}
        s = self.score(trial)
        self.evaluations += 1
        if s > self.best:
            self.values, self.best = trial, s
            return True
        return False

    def categorical(self, held=()) -> None:
        for p in self.cls.parameters:
            if isinstance(p.domain, Finite) and p.name not in held:
                for v in p.domain.values:
                    if v != self.values[p.name]:
                        self.trial(p.name, v)

    def turns(self) -> bool:
        improved = False
        for p in self.cls.parameters:
            if p.continuous and isinstance(p.domain, Periodic):
                period = p.domain.high - p.domain.low
                here = self.values[p.name]
                for t in range(1, TURNS):
                    improved |= self.trial(p.name, p.domain.wrap(here + t * period / TURNS))
        return improved

    def anchored(self, evaluations: int) -> bool:
        """A pattern search of at most ``evaluations`` scores whose steps each move one size
        or angle together with the place, so that one corner of the object's parts' boxes
        stays where it stands (as a face move does in the chain; ``sppl.infer.faces``): a size
        grown from one face, an angle turned about one corner. Whether it improved the fit."""
        names = anchored_parameters(self.cls)
        if not names:
            return False
        start = self.evaluations
        steps = {n: ANCHOR_STEP * self.cls.parameter(n).proposal_scale for n in names}
        improved = False
        for _ in range(ANCHOR_HALVINGS + 1):
            moved = True
            while moved and self.evaluations - start < evaluations:
                moved = self._anchored_pass(names, steps, start + evaluations)
                improved |= moved
            steps = {n: v / 2 for n, v in steps.items()}
        return improved

    def _anchored_pass(self, names, steps, until) -> bool:
        x, y = self.cls.position
        for name in names:
            p = self.cls.parameter(name)
            for sign in (1.0, -1.0):
                value = self.values[name] + sign * steps[name]
                if isinstance(p.domain, Periodic):
                    value = p.domain.wrap(value)
                stepped = {**self.values, name: value}
                for shift in _corner_shifts(self.cls, self.values, stepped):
                    if self.evaluations >= until:
                        return False
                    if self.trial(name, value, **{x: self.values[x] + float(shift[0]),
                                                  y: self.values[y] + float(shift[1])}):
                        return True
        return False

    def polish(self, evaluations: int) -> None:
        """Powell's method over the continuous parameters, in units of their steps, from the
        values found so far, for at most ``evaluations`` scores: its line searches along the
        directions it has moved in follow a ridge that steps of one parameter at a time
        cannot, as a box fitted short along its length needs its length and both coordinates
        of its centre to move together."""
        cont = [p for p in self.cls.parameters if p.continuous]
        if not cont or evaluations <= 0:
            return
        scale = np.array([p.proposal_scale for p in cont])
        base = dict(self.values)

        def values_at(z) -> dict[str, Any]:
            values = dict(base)
            for p, v in zip(cont, np.asarray(z) * scale):
                values[p.name] = p.domain.wrap(float(v)) if isinstance(p.domain, Periodic) \
                    else float(v)
            return values

        def loss(z) -> float:
            values = values_at(z)
            s = self.score(values)
            self.evaluations += 1
            if s > self.best:
                self.values, self.best = values, s
            # Powell's line searches need finite values; outside the prior's support the
            # loss is a wall far above any score the search has seen.
            return -s if math.isfinite(s) else -self.best + 1e9

        start = np.array([base[p.name] for p in cont]) / scale
        optimize.minimize(loss, start, method="Powell",
                          options={"maxfev": evaluations, "xtol": 1e-3, "ftol": 1e-12})

    def pattern(self, held=(), evaluations: int = MAX_EVALUATIONS) -> None:
        """The pattern search over the continuous parameters not ``held``, until the search
        has made ``evaluations`` scores in all."""
        cont = [p for p in self.cls.parameters if p.continuous and p.name not in held]
        steps = {p.name: START_STEP * p.proposal_scale for p in cont}
        halvings = 0
        while cont and halvings <= HALVINGS and self.evaluations < evaluations:
            improved = False
            for p in cont:
                for sign in (1.0, -1.0):
                    v = self.values[p.name] + sign * steps[p.name]
                    if isinstance(p.domain, Periodic):
                        v = p.domain.wrap(v)
                    if self.trial(p.name, v):
                        improved = True
                        break
                if self.evaluations >= evaluations:
                    break
            if not improved:
                steps = {n: v / 2 for n, v in steps.items()}
                halvings += 1


def fit(sampler, state: Trace, cls: ObjectClass, like: SceneObject, keep=None, also=(),
        seeds: int = 0, polish: int = 0) -> dict[str, Any]:
    """The fitted values (``scored_fit``'s, without their score)."""
    return scored_fit(sampler, state, cls, like, keep, also, seeds, polish)[0]


def scored_fit(sampler, state: Trace, cls: ObjectClass, like: SceneObject, keep=None,
               also=(), seeds: int = 0, polish: int = 0,
               settle=(), shrink: bool = False, anchor: int = 0
               ) -> tuple[dict[str, Any], float]:
    """The deterministic fit of a ``cls`` object into ``state``, from ``like``'s values (those
    named in ``keep``, if given) or those of the objects ``also`` (a merge's others, whose
    pixels the fit takes over): the best of the starts, each categorical parameter set to
    its best value, each angle at its best of TURNS turns, then a pattern search over the
    continuous parameters (a step each way per parameter, halved when nothing improves); the
    turns and the search once more where the turns still improve the fit (the first ones were
    tried at a size and place that were off), and the categorical parameters again.

    With ``seeds``, the same search also runs from each of that many of the state's seeds
    (its largest blobs of unexplained pixels, ``BirthProposal.seeds``), starting from the
    best of the first start's values and START_DRAWS fixed prior draws, each moved there;
    the best search wins. With ``polish``, Powell's method then takes at most that many
    scores more (``_Search.polish``). With ``settle`` (names of parameters, a fitted birth's
    place), each search runs twice, the second time first over the other continuous
    parameters with those held (SETTLE_EVALUATIONS), the better winning. With ``shrink`` (a
    fitted birth at a speck's seed), where every start has zero prior the starts are tried
    again with their sizes scaled by each of SHRINK. With ``anchor`` (a merge's fit, the
    model's ``merge_anchor``), each search then makes at most that many scores of anchored
    steps (``_Search.anchored``) and searches once more where they improved it. All keep the
    fit a deterministic function of its arguments and the state. Returned with the fit: the log
    joint of the state with the fitted object in it (-inf where no start had a finite one)."""
    score = _Scores(sampler, state, cls)
    starts = [v for o in (like, *also) for v in _starts(cls, o, keep)]
    scores = [score(v) for v in starts]
    if shrink and not np.isfinite(scores).any():
        starts += [v for start in starts for v in _shrunk(cls, start)]
        scores = [score(v) for v in starts]
    best = max(scores)
    values = starts[scores.index(best)]
    found = _search(score, values, best, settle, anchor)
    if seeds and cls.position:
        draws = [values, *_starts(cls, like, keep=())]
        for seed in sampler.birth.seeds(state)[:seeds]:
            moved = [{**v, cls.position[0]: float(seed[0]), cls.position[1]: float(seed[1])}
                     for v in draws]
            scores = [score(v) for v in moved]
            best = max(scores)
            other = _search(score, moved[scores.index(best)], best, anchor=anchor)
            if other.best > found.best:
                found = other
    if polish:
        found.polish(polish)
    return found.values, found.best


def class_log_probs(scores) -> np.ndarray:
    """log P(c) of a class choice by fit, from each class's fitted log joint: (1 - UNIFORM)
    times their softmax, plus UNIFORM / K (uniform where no fit has a finite score)."""
    scores = np.asarray(scores, dtype=float)
    k = len(scores)
    if not np.isfinite(scores).any():
        return np.full(k, -math.log(k))
    by_fit = scores - np.logaddexp.reduce(scores)
    return np.logaddexp(math.log1p(-UNIFORM) + by_fit, math.log(UNIFORM / k))


def class_index(classes, cls: ObjectClass) -> int:
    """The place of ``cls`` among ``classes``, by name: a region binds a model's classes anew
    (``sppl.model.region``), so an object made from the model before its sampler bound it has
    a class equal to none of the sampler's."""
    return next(k for k, c in enumerate(classes) if c.name == cls.name)


def draw_class(rng: np.random.Generator, log_p: np.ndarray) -> int:
    """A class drawn from ``class_log_probs``'s probabilities."""
    return int(rng.choice(len(log_p), p=np.exp(log_p - np.logaddexp.reduce(log_p))))


def class_log_prob(log_p: np.ndarray, c: int) -> float:
    """log P(c) of a class chosen by fit, in the ratios of the moves that choose so and of
    their reverses (looked up when called, so that a test can put a wrong one in its
    place)."""
    return float(log_p[c])


def anchored_parameters(cls: ObjectClass) -> tuple[str, ...]:
    """The parameters an anchored step moves: the continuous ones other than the place, of a
    class with a ground position."""
    if cls.position is None:
        return ()
    return tuple(p.name for p in cls.parameters
                 if p.continuous and not isinstance(p.domain, Finite)
                 and p.name not in cls.position)


def _corner_shifts(cls: ObjectClass, values, stepped) -> np.ndarray:
    """The distinct horizontal moves of the place, one per corner of the parts' boxes, that
    put that corner of the ``stepped`` object back where it is on the object with ``values``;
    none that is zero (the plain step) and none where a part cannot be built."""
    try:
        before = world_corners(cls.parts(values))[:2].T
        after = world_corners(cls.parts(stepped))[:2].T
    except (ValueError, ArithmeticError):
        return np.empty((0, 2))
    if before.shape != after.shape:
        return np.empty((0, 2))
    shifts = np.round(before - after, 9)
    shifts = shifts[np.isfinite(shifts).all(axis=1) & (np.abs(shifts).max(axis=1) > 1e-9)]
    return np.unique(shifts, axis=0) if len(shifts) else np.empty((0, 2))


def _search(score: _Scores, values, best, settle=(), anchor: int = 0) -> _Search:
    """The search from ``values``; and, for each categorical parameter that shapes the
    object (``shaping``), once more from each of its other values, held there, the best
    search winning. A large sphere that a chain read as two small objects is fitted, from
    where they stand, as a small one: at their places the large one scores worse, and the
    search moves the size before it moves the place (blocks.scn's prior scene 8: the merge
    of the two as a large sphere gains 2,616 nats, as a small one fitted loses 544)."""
    cls = score.cls
    found = _held_search(score, values, best, (), settle, anchor)
    for name in shaping(cls):
        for value in cls.parameter(name).domain.values:
            if value == values[name]:
                continue
            start = {**values, name: value}
            other = _held_search(score, start, score(start), (name,), settle, anchor)
            if other.best > found.best:
                found = other
    return found


def _held_search(score: _Scores, values, best, held, settle=(), anchor: int = 0
                 ) -> _Search:
    """The search with the categorical parameters ``held`` kept; with ``settle``, also the
    one that first searches with those parameters held, the better winning."""
    found = _one_search(score, values, best, held, (), anchor)
    if settle:
        other = _one_search(score, values, best, held, settle, anchor)
        if other.best > found.best:
            found = other
    return found


def _one_search(score: _Scores, values, best, held, settle=(), anchor: int = 0
                ) -> _Search:
    search = _Search(score, values, best)
    if settle:
        search.pattern(held=settle, evaluations=SETTLE_EVALUATIONS)
    search.categorical(held)
    search.turns()
    search.pattern()
    if search.turns():
        search.pattern()
    if anchor and search.anchored(anchor):
        search.pattern(evaluations=search.evaluations + MAX_EVALUATIONS)
    search.categorical(held)
    return search


_SHAPING: dict[int, tuple[ObjectClass, tuple[str, ...]]] = {}


def shaping(cls: ObjectClass) -> tuple[str, ...]:
    """The categorical parameters of ``cls`` that shape it (blocks.scn's size, small or
    large), as against those that only colour it or set its material: those whose other
    values change its parts' primitives or poses at three fixed draws of its prior. Worked
    out once per class."""
    known = _SHAPING.get(id(cls))
    if known is not None and known[0] is cls:
        return known[1]
    rng = np.random.default_rng(0)
    draws = [cls.sample_prior(rng) for _ in range(3)]
    names = []
    for p in cls.parameters:
        if not isinstance(p.domain, Finite) or len(p.domain.values) < 2:
            continue
        if any(_shape_of(cls, {**v, p.name: other}) != _shape_of(cls, v)
               for v in draws for other in p.domain.values if other != v[p.name]):
            names.append(p.name)
    _SHAPING[id(cls)] = (cls, tuple(names))
    return tuple(names)


def _shape_of(cls: ObjectClass, values) -> list:
    return [(part.primitive, part.matrix.round(9).tobytes()) for part in cls.parts(values)]


def log_density(cls: ObjectClass, values, fitted) -> float:
    """log q(values | fitted) of the refit proposal for a ``cls`` object."""
    total = 0.0
    spread = np.zeros(len(SPREADS))  # the continuous parameters' log density, per spread
    for p in cls.parameters:
        v = values[p.name]
        if p.continuous:
            for k, c in enumerate(SPREADS):
                tau = c * p.proposal_scale
                spread[k] += (-0.5 * ((v - fitted[p.name]) / tau) ** 2 - math.log(tau)
                              - 0.5 * _LOG_2PI)
        elif isinstance(p.domain, Finite):
            others = len(p.domain.values) - 1
            if v == fitted[p.name]:
                total += math.log(1.0 - EPS) if others else 0.0
            else:
                total += math.log(EPS / others)
        else:
            total += p.log_prob(v, values)
    return total + float(np.logaddexp.reduce(spread)) - math.log(len(SPREADS))


def log_density_bound(cls: ObjectClass, values) -> float:
    """The largest ``log_density(cls, values, fitted)`` over every fit: its Gaussians at
    their peaks and each categorical parameter at its likelier outcome."""
    total = 0.0
    spread = np.zeros(len(SPREADS))
    for p in cls.parameters:
        if p.continuous:
            for k, c in enumerate(SPREADS):
                spread[k] -= math.log(c * p.proposal_scale) + 0.5 * _LOG_2PI
        elif isinstance(p.domain, Finite):
            others = len(p.domain.values) - 1
            total += max(math.log(1.0 - EPS), math.log(EPS / others)) if others else 0.0
        else:
            total += p.log_prob(values[p.name], values)
    return total + float(np.logaddexp.reduce(spread)) - math.log(len(SPREADS))


def _births(sampler) -> float:
    return sampler.model.inference.fit_births


def log_mixture(sampler, state: Trace, cls: ObjectClass, values, fitted) -> float:
    b = _births(sampler)
    return float(np.logaddexp(math.log1p(-b) + log_density(cls, values, fitted),
                              math.log(b) + sampler.birth.log_density(cls, values, state)))


def log_mixture_bound(sampler, state: Trace, cls: ObjectClass, values) -> float:
    """An upper bound of ``log_mixture`` over every fit, computed without one."""
    b = _births(sampler)
    return float(np.logaddexp(math.log1p(-b) + log_density_bound(cls, values),
                              math.log(b) + sampler.birth.log_density(cls, values, state)))


def refitted_classes(sampler, state: Trace, like: SceneObject) -> tuple[list[dict], np.ndarray]:
    """A refit's fits of every class into ``state`` from ``like``, and log P(c | x-, like) of
    choosing each (``class_log_probs`` of their log joints)."""
    fits, scores = zip(*(scored_fit(sampler, state, cls, like) for cls in sampler.model.classes))
    return list(fits), class_log_probs(scores)


def refit_back(sampler, state: Trace, old: SceneObject, new: SceneObject):
    """The reverse density of a refit of ``old`` into ``new`` in ``state``: the class choice
    from ``new`` and log q_mixture(old | its class's fit), deferred (the function, every
    class's fit; and an upper bound, no fit)."""
    def back() -> float:
        fits, log_p = refitted_classes(sampler, state, new)
        c = class_index(sampler.model.classes, old.cls)
        return class_log_prob(log_p, c) + log_mixture(
            sampler, state, sampler.model.classes[c], old.values, fits[c])

    return back, log_mixture_bound(sampler, state, old.cls, old.values)


def refitted_back(sampler, state: Trace, old: SceneObject, new: SceneObject, also=(),
                  seeds: int = 0, polish: int = 0):
    """The reverse density of a move that replaced ``old`` by the fitted ``new`` in
    ``state``, log q_mixture(old | the fit of old's class from new, and ``also``), deferred:
    the function that computes it (one more fit), and an upper bound of it (no fit
    needed)."""
    return (lambda: log_mixture(sampler, state, old.cls, old.values,
                                fit(sampler, state, old.cls, new, also=also,
                                    seeds=seeds, polish=polish)),
            log_mixture_bound(sampler, state, old.cls, old.values))


def draw(cls: ObjectClass, fitted, rng: np.random.Generator) -> dict[str, Any]:
    values = dict(fitted)
    c = SPREADS[int(rng.integers(len(SPREADS)))]
    for p in cls.parameters:
        if p.continuous:
            values[p.name] = fitted[p.name] + c * p.proposal_scale * float(rng.standard_normal())
        elif isinstance(p.domain, Finite):
            others = [v for v in p.domain.values if v != fitted[p.name]]
            if others and rng.random() < EPS:
                values[p.name] = others[int(rng.integers(len(others)))]
        else:
            values[p.name] = p.sample(rng, values)
    return values


def sample(sampler, state: Trace, cls: ObjectClass, fitted, rng: np.random.Generator):
    """A draw of the values of a ``cls`` object from the refit proposal around ``fitted``:
    the mixture whose density ``log_mixture`` gives."""
    if rng.random() < _births(sampler):
        return sampler.birth.sample(cls, state, rng)
    return draw(cls, fitted, rng)


def propose_refit(sampler, trace: Trace, rng: np.random.Generator, k: int | None = None,
                  cls: ObjectClass | None = None, target: SceneObject | None = None,
                  state: Trace | None = None) -> Proposal | None:
    """A refit of object k (``misfit.choose``) as a ``cls`` object (chosen by the fits of every
    class, ``refitted_classes``); given ``target``, the
    proposal of exactly that object (the reverse of a refit, through the same ``state``)."""
    n = len(trace.objects)
    if n == 0:
        return None
    model = sampler.model
    k = misfit.choose(sampler, trace, rng) if k is None else k
    here = misfit.choice_log_probs(sampler, trace)
    old = trace.objects[k]
    rest = trace.objects[:k] + trace.objects[k + 1 :]
    # The scene without k, rendered in full so that its scores, and so the fits, are the
    # same whichever state it is reached from.
    state = state if state is not None else sampler.make_trace(rest, trace.noise)
    fits, log_p = refitted_classes(sampler, state, old)
    c = draw_class(rng, log_p) if cls is None else class_index(model.classes, cls)
    cls, forward = model.classes[c], fits[c]
    values = dict(target.values) if target is not None else sample(sampler, state, cls, forward,
                                                                    rng)
    obj = target if target is not None else make_object(model, cls, values)
    objects = rest[:k] + (obj,) + rest[k:]
    if not math.isfinite(obj.log_prior):
        return Proposal("refit", old.cls.name, objects, trace.noise, (obj,), -math.inf,
                        tries=Refit(state, k))
    log_q_forward = class_log_prob(log_p, c) + log_mixture(sampler, state, cls, values, forward)
    # The reverse fits are computed only when the proposal has a chance (Sampler.decide).
    back, bound = refit_back(sampler, state, old, obj)

    def choices(new: Trace) -> float:
        # A focused choice of k has its probability in either state (sppl.infer.misfit).
        return float(misfit.choice_log_probs(sampler, new)[k] - here[k])

    focused = model.inference.refit_focus > 0.0
    return Proposal("refit", old.cls.name, objects, trace.noise, (obj,), -log_q_forward,
                    ratio_fn=choices if focused else None, tries=Refit(state, k),
                    deferred=back, deferred_bound=bound)
