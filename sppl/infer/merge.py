"""The merge and split jumps: two or three objects that share one object's pixels become one
fitted object, and one object becomes a fitted object and one or two newborns.

A chain that explained a cube with two smaller cubes early on cannot leave that explanation one
object at a time: the death of either small cube uncovers half the cube's pixels and costs
thousands of nats, and a refit of either is fitted with the other still there, so it fits the
half that is left. A merge removes object i and refits object j in the scene without both,
so the fit can grow j over the pixels i explained (its search starts from the best of j's
values and those of the objects taken away, as a fit of each class would start from them):

    merge (x- + i + j -> x- + y): i uniform among the n objects (or, with the model's
        ``merge_focus``, by how little the state loses without it: sppl.infer.redundant,
        whose q(i | x) then stands for 1 / n below, and q(i | x- + i + j) is scored in a
        split's reverse), j among the others with
        probability w(i, j) / sum_l w(i, l), where w(i, j) = exp(-|p_i - p_j|^2 / (2 R^2))
        with p an object's ground position, or exp(-g^2 / (2 P^2)) with g the pixels between
        the two objects' rectangles in the camera where they are nearest, whichever is larger
        (1 where neither applies), times exp(-|c_i - c_j|^2 / (2 S^2)) with c an object's
        mean part colour, and y from the refit proposal into x- starting from j or i
        (sppl.infer.fit: the better start) of a class c chosen by the fits of every class
        so started, with probability P(c | x-, i, j) (``merged_fits``: 0.95 times the
        softmax of their log joints, plus 0.05 / K);
    split (x- + y -> x- + i + j): y uniform among the n - 1 objects, j from the refit proposal
        of a uniform class into x- = the scene without y, starting from y, and i a birth of a
        uniform class into x- (sppl.infer.birth: near what x- leaves unexplained, or the prior).

A split is a merge's reverse: both go through the same x-, so the fits that the densities
depend on are the same both ways (the split's reverse fits y, as every class, from its fitted
j and its newborn i), and with K classes

    log alpha_merge = log pi(x- + y) - log pi(x- + i + j)
                      + log P(split) - log(n - 1) - 2 log K + log q_fit(j | x-, y)
                      + log q_birth(i | x-)
                      - log P(merge) + log n - log w(i, j) + log sum_l w(i, l)
                      - log P(c_y | x-, i, j) - log q_fit(y | x-, j, i)

(the split's class choices are uniform: a K each for j's and i's). Which object is born and which is
fitted are roles the move chooses, not part of the scene; a merge with its roles is undone by
exactly one split with the same roles, which is all detailed balance needs. The places in the
tuple are uniform, as for a birth, and carry no density. docs/inference.md has the derivation.

Three or more small objects on one large object's pixels need more: a merge of two of them
fits the large object with the third still standing inside it, which the no-overlap constraint or the
likelihood rejects. So a merge takes away m objects besides j, m in 1..M = min(MAX_TAKEN,
n - 1) with probability c_M(m) = (1 / m) / sum_{l <= M} 1 / l: i as above, then each further
one among those not yet chosen with probability w(j, l) / sum over them, and a split gives m
newborns (m with probability c_MAX_TAKEN(m)), each a birth into the same x-. The ratio above
gains, in the merge's density, c_M(m) and each further choice's probability, and in the
split's c_MAX_TAKEN(m), one K and one
q_birth per newborn; the newborns in the order drawn are the merged-away objects in the
order chosen.

The fit of the merged object y (in a merge, and in a split's reverse) may search further
than a refit's: from the model's ``merge_seeds`` seeds of x- as well, and polished by
``merge_polish`` evaluations of Powell's method (``merge_search``). It is still a
deterministic function of x- and the objects it starts from, the same in both directions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.trace import SceneObject, Trace, make_object
from . import fit as fitting
from . import redundant
from .moves import Proposal, _log

# How near a merge partner is looked for: at RADIUS metres on the ground, or PIXELS pixels
# apart in a camera's image, a partner is e^(-1/2) times as likely as one in the same place.
# Two objects that share one object's pixels stand within about an object's size, or, seen
# along a camera's ray, anywhere on it: a small object far behind a cone that paints the
# cone's tip is near it in the image only.
RADIUS = 0.5
PIXELS = 4.0
# A chain that explained one object with pieces gave each piece its colour, so a partner of
# another colour is rarely one to merge with: red against blue is e^-7 times as likely as a
# partner of the same colour and place. On shapes.scn's prior scene 18 it makes a chain's
# right merges (a large red cube read as a sphere and a thin cone; a wide flat blue cone read
# as six blue objects) two to three and a half times as likely to be proposed.
COLOUR = 0.25
# A merge takes away one to MAX_TAKEN objects besides the one it fits, and a split gives one
# to MAX_TAKEN newborns: several small objects that share one large object's pixels become it
# in one move, where merges one after the other would each leave an object overlapping the
# fit. On shapes.scn's prior scenes, a wide flat cone ended as eight small blue objects
# (scene 6 of benchmarks/prior_scenes.py), which a merge of all eight fits back into the cone
# (4,108 nats above them), and a red cone as nine small red objects (scene 1: +1,646 nats for
# all nine, -709 for seven of them); with at most three merged at once, no merge could.
MAX_TAKEN = 12


def partner_log_weights(objects, i: int, screen=None, colour: bool = True) -> np.ndarray:
    """log P(j | i) of a merge over the places j of ``objects`` (-inf at i itself).
    ``screen(o)``, where the scorer knows the cameras, gives the pixel rectangle an object
    covers in each camera (None where out of view); the nearer of the two measures counts,
    and the colour term (unless ``colour`` is false) multiplies it."""
    def position(o: SceneObject):
        return (o.values[o.cls.position[0]], o.values[o.cls.position[1]]) if o.cls.position \
            else None

    here = position(objects[i])
    rects = screen(objects[i]) if screen is not None else None
    logw = np.zeros(len(objects))
    for j, o in enumerate(objects):
        if j == i:
            logw[j] = -math.inf
            continue
        near = []
        there = position(o)
        if here is not None and there is not None:
            d2 = (here[0] - there[0]) ** 2 + (here[1] - there[1]) ** 2
            near.append(-0.5 * d2 / RADIUS**2)
        if rects is not None:
            gaps = [_gap(a, b) for a, b in zip(rects, screen(o))
                    if a is not None and b is not None]
            if gaps:
                near.append(-0.5 * min(gaps) ** 2 / PIXELS**2)
        logw[j] = max(near) if near else 0.0
        if colour:
            logw[j] -= 0.5 * _colour_gap(objects[i], o) / COLOUR**2
    return logw - np.logaddexp.reduce(logw)


def _colour_gap(a: SceneObject, b: SceneObject) -> float:
    """The squared distance between the mean colours of two objects' parts."""
    ca = np.mean([part.colour for part in a.parts], axis=0) if a.parts else None
    cb = np.mean([part.colour for part in b.parts], axis=0) if b.parts else None
    return 0.0 if ca is None or cb is None else float(((ca - cb) ** 2).sum())


def _gap(a, b) -> float:
    """Pixels between two rectangles (rows r0..r1, columns c0..c1); 0 where they meet."""
    rows = max(0, a[0] - b[1], b[0] - a[1])
    cols = max(0, a[2] - b[3], b[2] - a[3])
    return math.hypot(rows, cols)


def screen_of(sampler):
    """The pixel rectangles of an object per camera, from the fast scorer's cache; None
    for a scorer that keeps none (the prior's, the reference path's)."""
    draws = getattr(sampler.scorer, "draws", None)
    return None if draws is None else (lambda o: draws.of_object(o).rects)


@dataclass(frozen=True)
class MergeSplit:
    """What a merge or split used, for its reverse: the scene x- without the objects it took
    out, and the places, in the tuple that has them all, of the fitted object and of the
    others (the merged-away objects, or the newborns, in the order they were chosen)."""

    state: Trace
    fitted_place: int
    other_places: tuple[int, ...]

    def reverse(self, sampler, before: Trace, proposal: Proposal, after: Trace) -> Proposal:
        # The place of the single object (merged or split), in the tuple without the others.
        single = self.fitted_place - sum(p < self.fitted_place for p in self.other_places)
        if proposal.move == "merge":
            return propose_split(sampler, after, sampler.rng, k=single, state=self.state,
                                 fitted=before.objects[self.fitted_place],
                                 born=tuple(before.objects[p] for p in self.other_places),
                                 born_places=self.other_places)
        return propose_merge(sampler, after, sampler.rng, i=self.other_places[0],
                             j=self.fitted_place, more=self.other_places[1:],
                             state=self.state, target=before.objects[single])


def _chosen_first(sampler, objects, noise, i: int, back, bound):
    """``back`` and ``bound`` of a split with the merge's focused choice of ``i`` in the
    state ``objects`` (``redundant.log_probs``) added to them."""
    def with_choice() -> float:
        state = sampler.make_trace(objects, noise)
        return back() + float(redundant.log_probs(sampler, state)[i])

    return with_choice, bound + redundant.log_prob_bound(sampler, len(objects))


def log_q_born(sampler, obj: SceneObject, state: Trace) -> float:
    """log q_birth of a split's newborn in the scene x- (its class chosen apart)."""
    return sampler.birth.log_density(obj.cls, obj.values, state)


def _without(objects, *places) -> tuple:
    return tuple(o for p, o in enumerate(objects) if p not in places)


def merge_search(sampler) -> dict[str, int]:
    """How far a merge's fit searches (``sppl.infer.fit.fit``): from the model's
    ``merge_seeds`` seeds of the scene without the merged objects besides their values, and
    ``merge_polish`` evaluations of Powell's method, and ``merge_anchor`` evaluations of
    anchored steps (a size or angle moved with the place so that one corner stays put) after
    each pattern search. Only the fit of the merged object (in the merge, and in the split's
    reverse) searches further; the split's fit of its object from the one it splits, which
    only shrinks it, is the refit's."""
    settings = sampler.model.inference
    return {"seeds": settings.merge_seeds, "polish": settings.merge_polish,
            "anchor": settings.merge_anchor}


def _refitted(sampler, state: Trace, like: SceneObject, rng: np.random.Generator,
              target: SceneObject | None) -> tuple[SceneObject, dict]:
    """A split's fitted object: a draw from the refit proposal of a uniform class into
    ``state``, starting from ``like`` (or exactly ``target``), and the fit it is drawn
    around."""
    model = sampler.model
    cls = target.cls if target is not None else model.classes[
        int(rng.integers(len(model.classes)))]
    forward = fitting.fit(sampler, state, cls, like)
    if target is None:
        target = make_object(model, cls, fitting.sample(sampler, state, cls, forward, rng))
    return target, forward


def merged_fits(sampler, state: Trace, like: SceneObject, also) -> tuple[list[dict], np.ndarray]:
    """The merged object fitted as each class of the model into ``state`` (x-), from ``like``
    and the objects ``also`` (``merge_search``), and log P(c | x-, the merged objects) of
    choosing each class (``fit.class_log_probs`` of the fits' log joints): a function of x-
    and the merged objects, the same in a merge and in a split's reverse."""
    search = merge_search(sampler)
    fits, scores = zip(*(fitting.scored_fit(sampler, state, cls, like, also=also, **search)
                         for cls in sampler.model.classes))
    return list(fits), fitting.class_log_probs(scores)


def merged_back(sampler, state: Trace, old: SceneObject, like: SceneObject, also):
    """The reverse density of a split of ``old`` into ``like`` and the newborns ``also``, the
    merge's class choice and log q_mixture(old | its class's fit), deferred: the function
    that computes it (a fit of every class), and an upper bound of it (no fit needed: the
    choice's log probability is at most 0)."""
    def back() -> float:
        fits, log_p = merged_fits(sampler, state, like, also)
        c = fitting.class_index(sampler.model.classes, old.cls)
        return fitting.class_log_prob(log_p, c) + fitting.log_mixture(
            sampler, state, sampler.model.classes[c], old.values, fits[c])

    return back, fitting.log_mixture_bound(sampler, state, old.cls, old.values)


def taken_counts(n: int) -> int:
    """How many numbers of merged-away objects a merge of ``n`` objects chooses among: 1 to
    MAX_TAKEN, and at most n - 1."""
    return min(MAX_TAKEN, n - 1)


def count_log_prob(m: int, top: int) -> float:
    """log c_top(m): m objects taken away (or born) out of 1..top, with probability
    proportional to 1 / m. Most merges and splits are of one or two objects; a uniform
    choice up to MAX_TAKEN made a split into one object as rare as one into twelve, which is
    never accepted."""
    return -math.log(m) - math.log(sum(1.0 / k for k in range(1, top + 1)))


def draw_count(rng: np.random.Generator, top: int) -> int:
    p = 1.0 / np.arange(1, top + 1)
    return 1 + int(rng.choice(top, p=p / p.sum()))


def more_log_probs(logw_j: np.ndarray, excluded) -> np.ndarray:
    """log P of each place as the next merged-away object after the first: by its weight
    from the fitted object j (``logw_j``, -inf at j), among the places not yet chosen."""
    logw = logw_j.copy()
    logw[list(excluded)] = -math.inf
    return logw - np.logaddexp.reduce(logw)


def chosen_log_prob(logw_i, logw_j, i: int, j: int, more) -> float:
    """log P of choosing the fitted object j after the first merged-away i, and then the
    other merged-away objects ``more`` in that order."""
    total, excluded = float(logw_i[j]), [i]
    for p in more:
        total += float(more_log_probs(logw_j, excluded)[p])
        excluded.append(p)
    return total


def propose_merge(sampler, trace: Trace, rng: np.random.Generator, i: int | None = None,
                  j: int | None = None, state: Trace | None = None,
                  target: SceneObject | None = None, more: tuple[int, ...] | None = None
                  ) -> Proposal | None:
    """Merge object i (uniform), and with it MORE - 1 further objects near j (MORE in
    1..``taken_counts``, ``draw_count``), into object j (near i) as a fitted object of a
    class chosen by fit (``merged_fits``); given ``target`` (and ``more``), the proposal of
    exactly that object (a split's reverse)."""
    objects = trace.objects
    n = len(objects)
    if n < 2:
        return None
    model = sampler.model
    n_classes = len(model.classes)
    screen = screen_of(sampler)
    i = redundant.choose(sampler, trace, rng) if i is None else i
    logw = partner_log_weights(objects, i, screen)
    if j is None:
        j = int(rng.choice(n, p=np.exp(logw)))
    logw_j = partner_log_weights(objects, j, screen)
    if more is None:
        count = draw_count(rng, taken_counts(n))
        more = []
        for _ in range(count - 1):
            p = np.exp(more_log_probs(logw_j, [i, *more]))
            more.append(int(rng.choice(n, p=p / p.sum())))
    more = tuple(more)
    taken = (i, *more)
    gone, old = [objects[p] for p in taken], objects[j]
    rest = _without(objects, j, *taken)
    state = state if state is not None else sampler.make_trace(rest, trace.noise)
    fits, log_p = merged_fits(sampler, state, old, gone)
    c = fitting.draw_class(rng, log_p) if target is None else \
        fitting.class_index(model.classes, target.cls)
    cls, forward = model.classes[c], fits[c]
    new = target if target is not None else make_object(
        model, cls, fitting.sample(sampler, state, cls, forward, rng))
    merged = tuple(new if p == j else o for p, o in enumerate(objects) if p not in taken)
    tag = MergeSplit(state, j, taken)
    if not math.isfinite(new.log_prior):
        return Proposal("merge", old.cls.name, merged, trace.noise, (new,), -math.inf, tries=tag)
    log_q_forward = (_log(sampler.jump["merge"]) + float(redundant.log_probs(sampler, trace)[i])
                     + count_log_prob(len(taken), taken_counts(n))
                     + chosen_log_prob(logw, logw_j, i, j, more)
                     + fitting.class_log_prob(log_p, c)
                     + fitting.log_mixture(sampler, state, cls, new.values, forward))
    # log q(reverse), less the fitted density of old, which is deferred (Sampler.decide).
    log_q_back = (_log(sampler.jump["split"]) - math.log(len(merged))
                  + count_log_prob(len(taken), MAX_TAKEN)
                  - (1 + len(taken)) * math.log(n_classes)
                  + sum(log_q_born(sampler, o, state) for o in gone))
    back, bound = fitting.refitted_back(sampler, state, old, new)
    return Proposal("merge", old.cls.name, merged, trace.noise, (new,),
                    log_q_back - log_q_forward, tries=tag, deferred=back, deferred_bound=bound)


def propose_split(sampler, trace: Trace, rng: np.random.Generator, k: int | None = None,
                  state: Trace | None = None, fitted: SceneObject | None = None,
                  born: tuple[SceneObject, ...] | None = None,
                  born_places: tuple[int, ...] | None = None) -> Proposal | None:
    """Split object k (uniform) into a fitted object of a uniform class in its place and
    MORE births of uniform classes (MORE in 1..MAX_TAKEN, ``draw_count``); given ``fitted``,
    ``born`` and ``born_places`` (their places in the split tuple), the proposal of exactly
    those (a merge's reverse)."""
    objects = trace.objects
    m = len(objects)
    if m < 1:
        return None
    model = sampler.model
    n_classes = len(model.classes)
    k = int(rng.integers(m)) if k is None else k
    old = objects[k]
    rest = _without(objects, k)
    state = state if state is not None else sampler.make_trace(rest, trace.noise)
    fitted, forward = _refitted(sampler, state, old, rng, fitted)
    replaced = objects[:k] + (fitted,) + objects[k + 1 :]
    if born is None:
        born, split = [], list(replaced)
        for _ in range(draw_count(rng, MAX_TAKEN)):
            cls = model.classes[int(rng.integers(n_classes))]
            obj = make_object(model, cls, sampler.birth.sample(cls, state, rng))
            born.append(obj)
            split.insert(int(rng.integers(len(split) + 1)), obj)
        born = tuple(born)
        born_places = tuple(next(p for p, o in enumerate(split) if o is b) for b in born)
        split = tuple(split)
    else:
        slots = iter(replaced)
        by_place = dict(zip(born_places, born))
        split = tuple(by_place[p] if p in by_place else next(slots)
                      for p in range(len(replaced) + len(born)))
    j = next(p for p, o in enumerate(split) if o is fitted)
    tag = MergeSplit(state, j, born_places)
    if not (math.isfinite(fitted.log_prior) and all(math.isfinite(b.log_prior) for b in born)):
        return Proposal("split", old.cls.name, split, trace.noise, (fitted, *born), -math.inf,
                        tries=tag)
    n = len(split)
    log_q_forward = (_log(sampler.jump["split"]) - math.log(m)
                     + count_log_prob(len(born), MAX_TAKEN)
                     - (1 + len(born)) * math.log(n_classes)
                     + fitting.log_mixture(sampler, state, fitted.cls, fitted.values, forward)
                     + sum(log_q_born(sampler, b, state) for b in born))
    screen = screen_of(sampler)
    i, more = born_places[0], born_places[1:]
    logw = partner_log_weights(split, i, screen)
    logw_j = partner_log_weights(split, j, screen)
    # log q(reverse), less the merge's class choice and fitted density of old, which are
    # deferred (Sampler.decide), and, with a focused choice, less the merge's choice of i.
    log_q_back = (_log(sampler.jump["merge"])
                  + count_log_prob(len(born), taken_counts(n))
                  + chosen_log_prob(logw, logw_j, i, j, more))
    back, bound = merged_back(sampler, state, old, fitted, born)
    if model.inference.merge_focus == 0.0:
        log_q_back -= math.log(n)
    else:
        # The choice needs the split state's deaths scored: only when the bound cannot decide.
        back, bound = _chosen_first(sampler, split, trace.noise, i, back, bound)
    return Proposal("split", old.cls.name, split, trace.noise, (fitted, *born),
                    log_q_back - log_q_forward, tries=tag, deferred=back, deferred_bound=bound)
