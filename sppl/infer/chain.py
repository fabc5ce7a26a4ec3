"""The Markov chain: the schedule of thesis Algorithms 1, 2 and 7 over the derived moves.

One *sweep* is: a parameter move for every object (each block of its parameters in turn);
then, with probability ``p_jump``, one model jump (birth, death or change, by their weights);
then a move of every noise parameter. ``Sampler.sweep`` performs one sweep.

A sweep is written as a generator (``Sampler.sweep_steps``) that yields each proposal's
final evaluation as a request, (trace, proposal), and is sent the evaluated trace back, so
that a driver can evaluate the requests of several chains together (``sppl.runs.lockstep``);
``Sampler.sweep`` answers each request itself with ``Sampler.evaluate``.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ..model.jumps import jump, jump_names
from ..model.region import bind_region
from ..model.trace import (
    SceneObject,
    Trace,
    make_object,
    noise_log_prior,
    objects_log_prior,
    overlaps_any,
)
from ..model.types import Model
from ..scoring.protocol import ScorerProtocol
from . import (
    faces,
    jumps,  # noqa: F401  (registers the built-in jumps)
    moves,
)
from .birth import BirthProposal
from .warmup import Warmup


@dataclass
class MoveStats:
    """Proposed and accepted counts per (move type, class or sensor)."""

    counts: dict[tuple[str, str], list[int]] = field(default_factory=lambda: defaultdict(lambda: [0, 0]))
    # Proposals rejected because their acceptance ratio was NaN (see ``Sampler.step``).
    nan: dict[tuple[str, str], int] = field(default_factory=lambda: defaultdict(int))

    def record(self, move: str, label: str, accepted: bool) -> None:
        c = self.counts[(move, label)]
        c[0] += 1
        c[1] += int(accepted)

    def record_nan(self, move: str, label: str) -> None:
        self.record(move, label, False)
        self.nan[(move, label)] += 1

    def by_move(self) -> dict[str, tuple[int, int]]:
        out: dict[str, list[int]] = defaultdict(lambda: [0, 0])
        for (move, _), (n, a) in self.counts.items():
            out[move][0] += n
            out[move][1] += a
        return {m: (n, a) for m, (n, a) in out.items()}

    def as_dict(self) -> dict:
        return {
            f"{m}/{lab}": {"proposed": n, "accepted": a,
                           **({"nan": self.nan[(m, lab)]} if self.nan.get((m, lab)) else {})}
            for (m, lab), (n, a) in self.counts.items()
        }


def accept(log_alpha: float, rng: np.random.Generator) -> bool:
    """The Metropolis-Hastings decision in log space: accept with probability
    min(1, exp(log_alpha)), comparing log u with log_alpha, so that ratios far beyond the
    range of a double still decide correctly. ``log_alpha`` is never NaN here."""
    if log_alpha >= 0.0:
        return True
    u = rng.random()
    return (math.log(u) if u > 0.0 else -math.inf) < log_alpha


def evaluate_batch(requests) -> list[Trace | None]:
    """``Sampler.evaluate`` of several (sampler, trace, proposal) whose samplers share one
    scorer, with the same answers: each proposal's prior is checked first, then the scorer
    is asked once for every proposal that needs a render (``evaluate_batch``), which lets
    it draw them together."""
    out: list[Trace | None] = [None] * len(requests)
    pending = []
    for i, (sampler, trace, proposal) in enumerate(requests):
        log_prior = sampler.proposal_log_prior(proposal)
        if log_prior is None:
            continue
        if proposal.move == "noise":  # the objects are the trace's: no new render
            out[i] = sampler.scored(proposal, log_prior, *sampler.rescored(trace, proposal))
        else:
            pending.append((i, log_prior))
    if not pending:
        return out
    scorer = requests[0][0].scorer
    asked = [(requests[i][2].objects, requests[i][1],
              *_noise_args(requests[i][0], requests[i][2].noise)) for i, _ in pending]
    if hasattr(scorer, "evaluate_batch"):
        answers = scorer.evaluate_batch(asked)
    else:  # a scorer of the plain protocol (evaluate and log_likelihood)
        answers = [scorer.evaluate(*request) for request in asked]
    for (i, log_prior), (stats, renders) in zip(pending, answers):
        sampler, _, proposal = requests[i]
        out[i] = sampler.scored(proposal, log_prior, stats, renders)
    return out


def _noise_args(sampler: Sampler, noise) -> tuple:
    """What a scorer is passed beyond the objects and the parent: the noise values, where
    the model has latent lighting (their render group lights the hypothesis) or the scorer
    has per-pixel likelihoods (scored at them, ``sppl.model.robust``); nothing otherwise, so that
    a scorer of the plain protocol (objects, parent) still serves."""
    if sampler.model.render.latent or getattr(sampler.scorer, "per_pixel", None):
        return (noise,)
    return ()


class Sampler:
    """Advances one chain. ``scorer`` renders and scores (``sppl.scoring.protocol``: what a scorer
    of observations has beyond ``ScorerProtocol`` is used where it has it); ``rng`` is the
    chain's only randomness."""

    def __init__(self, model: Model, scorer: ScorerProtocol, rng: np.random.Generator) -> None:
        # A `region cameras` becomes the ground the scorer's cameras see (sppl.model.region).
        self.model = model = bind_region(model, getattr(scorer, "cameras", {}).values())
        self._class_ids = {id(c) for c in model.classes}
        self.scorer = scorer
        self.rng = rng
        self.stats = MoveStats()
        self.jump = moves.jump_probabilities(model, bool(getattr(scorer, "terms", None)))
        self.birth = BirthProposal(model, scorer if getattr(scorer, "terms", None) else None)
        self.warmup = Warmup.of(model.inference)
        # The power of the likelihood this chain targets: 1 but in a tempered ladder's hotter
        # chains (sppl.infer.tempering).
        self.power = 1.0

    # -- states --------------------------------------------------------------------------------

    def initial_trace(self, objects=()) -> Trace:
        """The thesis's starting point: the given objects (default: an empty scene) and noise
        parameters drawn from their priors."""
        noise = {
            kind: {p.name: p.prior.sample(self.rng) for p in parameters}
            for kind, parameters in self.model.noise_groups
        }
        if not objects and any(c.count for c in self.model.classes):
            # A class with a fixed count gives the empty scene no prior density: start from a
            # prior draw of those objects instead.
            from ..model.simulate import fixed_objects

            objects = fixed_objects(self.model, self.rng)
        return self.make_trace(tuple(objects), noise)

    def make_trace(self, objects, noise) -> Trace:
        objects = self.own_objects(objects)
        stats, renders = self.scorer.evaluate(objects, None, *_noise_args(self, noise))
        log_prior = objects_log_prior(self.model, objects) + noise_log_prior(self.model, noise)
        return Trace(
            self.model, tuple(objects), noise, stats, log_prior,
            self.scorer.log_likelihood(stats, noise), renders,
        )

    def own_objects(self, objects) -> tuple[SceneObject, ...]:
        """``objects`` as objects of this sampler's classes. A scene made from the model before
        the sampler bound its region (a given starting scene, a truth to score) holds the
        unbound classes, whose prior ignores the region; every move keeps an object's class,
        so without this a chain from such a scene would sample, and score, outside it."""
        model = self.model
        return tuple(o if id(o.cls) in self._class_ids
                     else make_object(model, model.object_class(o.cls.name), o.values)
                     for o in objects)

    def evaluate(self, trace: Trace, proposal: moves.Proposal) -> Trace | None:
        """The proposed trace, or None where its prior is zero (out of a domain, overlapping),
        which is decided before anything is rendered."""
        log_prior = self.proposal_log_prior(proposal)
        if log_prior is None:
            return None
        if proposal.move == "noise":
            stats, renders = self.rescored(trace, proposal)
        else:
            # Given the current trace, the scorer re-renders only what the move changed.
            stats, renders = self.scorer.evaluate(proposal.objects, trace,
                                                  *_noise_args(self, proposal.noise))
        return self.scored(proposal, log_prior, stats, renders)

    def rescored(self, trace: Trace, proposal: moves.Proposal):
        """(stats, renders) of a noise move's state: the trace's own where its statistics
        are sufficient for the noise (the Gaussian's), else re-scored by the scorer."""
        rescore = getattr(self.scorer, "rescore", None)
        return (trace.stats, trace.renders) if rescore is None else rescore(trace, proposal.noise)

    def evaluate_batch(self, requests) -> list[Trace | None]:
        """``evaluate`` of several (trace, proposal) pairs, rendered together where the scorer
        can."""
        return evaluate_batch([(self, trace, proposal) for trace, proposal in requests])

    def proposal_log_prior(self, proposal: moves.Proposal) -> float | None:
        """The proposed state's log prior, or None where it is zero; nothing is rendered."""
        if any(not math.isfinite(o.log_prior) for o in proposal.changed):
            return None
        if self.model.no_overlap and any(overlaps_any(o, proposal.objects) for o in proposal.changed):
            return None
        log_prior = objects_log_prior(self.model, proposal.objects) + noise_log_prior(
            self.model, proposal.noise
        )
        return log_prior if math.isfinite(log_prior) else None

    def scored(self, proposal: moves.Proposal, log_prior: float, stats, renders) -> Trace:
        """The proposed trace from its log prior and the scorer's answer for its objects."""
        log_lik = self.scorer.log_likelihood(stats, proposal.noise)
        return Trace(
            self.model, proposal.objects, proposal.noise, stats, log_prior, log_lik, renders
        )

    def step(self, trace: Trace, proposal: moves.Proposal | None) -> Trace:
        """Metropolis-Hastings accept/reject of one proposal, evaluated here (``decide``)."""
        return self.drive(self.decide(trace, proposal))

    def decide(self, trace: Trace, proposal: moves.Proposal | None):
        """Metropolis-Hastings accept/reject, in log space, as a generator: it yields
        (trace, proposal) to have the proposal evaluated, is sent ``evaluate``'s answer, and
        returns the chain's next trace.

        A NaN ratio (a likelihood or proposal density that broke down on a degenerate scene,
        or two states that both have zero density) says nothing about the target: the
        proposal is rejected, so the chain only ever holds states with a number for a
        score, and it is counted (``stats.nan``, "nan" in the summary), so a user sees it.
        """
        if proposal is None:
            return trace
        new = yield trace, proposal
        if new is None:
            self.stats.record(proposal.move, proposal.label, False)
            return trace
        if proposal.deferred is not None:
            accepted = self._accept_deferred(trace, proposal, new)
        else:
            with np.errstate(invalid="ignore"):  # inf - inf is NaN, handled just below
                log_alpha = self.log_alpha(trace, proposal, new)
            accepted = None if math.isnan(log_alpha) else accept(log_alpha, self.rng)
        if accepted is None:
            self.stats.record_nan(proposal.move, proposal.label)
            return trace
        self.stats.record(proposal.move, proposal.label, accepted)
        return new if accepted else trace

    def _accept_deferred(self, trace: Trace, proposal: moves.Proposal, new: Trace):
        """``accept`` of the exact ratio (None where it is NaN), computing the proposal's
        deferred part only where its upper bound cannot decide: with the ratio at most
        ``bound`` below 0, the uniform that ``accept`` draws rejects whenever log u >= bound.
        The same uniforms are drawn, and the same decisions made, as with the deferred part
        computed every time, whenever that part is a number (nothing it computes draws from
        the chain's generator)."""
        with np.errstate(invalid="ignore"):
            known = self.known_log_alpha(trace, proposal, new)
            bound = known + proposal.deferred_bound
        if math.isnan(bound):
            return None
        if bound < 0.0:
            u = self.rng.random()
            log_u = math.log(u) if u > 0.0 else -math.inf
            if log_u >= bound:
                return False
        with np.errstate(invalid="ignore"):
            log_alpha = known + proposal.deferred()
        if math.isnan(log_alpha):
            return None
        if bound < 0.0:
            return log_u < log_alpha
        return accept(log_alpha, self.rng)

    def drive(self, steps):
        """Run a generator of ``decide``'s kind to its end, answering every request with
        ``evaluate``; its return value."""
        try:
            request = next(steps)
            while True:
                request = steps.send(self.evaluate(*request))
        except StopIteration as end:
            return end.value

    def log_alpha(self, trace: Trace, proposal: moves.Proposal, new: Trace) -> float:
        """log of the Metropolis-Hastings ratio of moving from ``trace`` to ``new`` (during an
        annealed warm-up, with the likelihood raised to the warm-up's power)."""
        log_alpha = self.known_log_alpha(trace, proposal, new)
        if proposal.deferred is not None:
            log_alpha += proposal.deferred()
        return log_alpha

    def known_log_alpha(self, trace: Trace, proposal: moves.Proposal, new: Trace) -> float:
        """``log_alpha`` less the proposal's deferred part."""
        beta = self.warmup.beta * self.power
        if beta == 1.0:
            log_alpha = new.score - trace.score
        else:
            log_alpha = (new.log_prior - trace.log_prior
                         + beta * (new.log_likelihood - trace.log_likelihood))
        log_alpha += proposal.log_q_ratio
        if proposal.ratio_fn is not None:
            log_alpha += proposal.ratio_fn(new)
        return log_alpha

    # -- the schedule -------------------------------------------------------------------------

    def sweep(self, trace: Trace) -> Trace:
        return self.drive(self.sweep_steps(trace))

    def adjoint_sweep(self, trace: Trace) -> Trace:
        return self.drive(self.adjoint_sweep_steps(trace))

    def sweep_steps(self, trace: Trace):
        """One sweep, as a generator of evaluation requests (see ``decide``)."""
        m, rng = self.model, self.rng
        for k in range(len(trace.objects)):
            for block in moves.parameter_blocks(trace.objects[k].cls):
                trace = yield from self._parameter_step(trace, k, block)
            for name in self._faces(trace.objects[k].cls):
                trace = yield from self._face_step(trace, k, name)
        if rng.random() < m.inference.p_jump:
            trace = yield from self.decide(trace, self.propose_jump(trace))
        for kind, parameters in m.noise_groups:
            for p in parameters:
                trace = yield from self._noise_step(trace, kind, p.name)
        self.warmup.sweep += 1
        return trace

    def adjoint_sweep_steps(self, trace: Trace):
        """The time reversal of ``sweep``: its moves in the opposite order.

        Every move is reversible, so a sweep's adjoint with respect to the posterior is the
        same moves in reverse order. Running it backwards from a posterior draw gives the past
        of a stationary chain, which simulation-based calibration uses (``sppl.verify.sbc``).
        Keep it the mirror image of ``sweep_steps``.
        """
        m, rng = self.model, self.rng
        for kind, parameters in reversed(m.noise_groups):
            for p in reversed(parameters):
                trace = yield from self._noise_step(trace, kind, p.name)
        if rng.random() < m.inference.p_jump:
            trace = yield from self.decide(trace, self.propose_jump(trace))
        for k in reversed(range(len(trace.objects))):
            for name in reversed(self._faces(trace.objects[k].cls)):
                trace = yield from self._face_step(trace, k, name)
            for block in reversed(moves.parameter_blocks(trace.objects[k].cls)):
                trace = yield from self._parameter_step(trace, k, block)
        self.warmup.sweep += 1
        return trace

    def _parameter_step(self, trace: Trace, k: int, block: tuple[str, ...]):
        site = f"{trace.objects[k].cls.name}/{'+'.join(block)}"
        proposal = moves.propose_parameters(self.model, trace, k, block, self.rng,
                                            self.warmup.factor(site))
        new = yield from self.decide(trace, proposal)
        if trace.objects[k].cls.parameter(block[0]).continuous:
            self.warmup.record(site, new is not trace)
        return new

    def _faces(self, cls) -> tuple[str, ...]:
        """The face moves of an object of ``cls`` in a sweep, in order: each of its face
        parameters ``face_steps`` times (none by default)."""
        return faces.face_parameters(cls) * self.model.inference.face_steps

    def _face_step(self, trace: Trace, k: int, name: str):
        site = f"{trace.objects[k].cls.name}/face {name}"
        proposal = faces.propose_face(self.model, trace, k, name, self.rng,
                                      self.warmup.factor(site))
        if proposal is None:  # no reach, whatever the step: nothing to decide
            return trace
        new = yield from self.decide(trace, proposal)
        self.warmup.record(site, new is not trace)
        return new

    def _noise_step(self, trace: Trace, kind: str, name: str):
        site = f"noise/{kind}.{name}"
        proposal = moves.propose_noise(self.model, trace, kind, name, self.rng,
                                       self.warmup.factor(site))
        new = yield from self.decide(trace, proposal)
        self.warmup.record(site, new is not trace)
        return new

    # -- what a checkpoint keeps beyond the trace and the generator ----------------------------

    def state_dict(self) -> dict:
        return {"warmup": self.warmup.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.warmup.load_state_dict(state["warmup"])

    def jump_type(self, u: float) -> str:
        """The jump type that a uniform draw ``u`` picks, in the order of registration
        (``sppl.model.jumps``)."""
        names = jump_names()
        total, last = 0.0, names[0]
        for kind in names:
            # A jump registered after this sampler was made has no probability in it.
            p = self.jump.get(kind, 0.0)
            if p > 0:
                total += p
                if u < total:
                    return kind
                last = kind
        return last  # u within rounding of 1

    def propose_jump(self, trace: Trace) -> moves.Proposal | None:
        return jump(self.jump_type(self.rng.random())).propose(self, trace, self.rng)

    def prune(self, trace: Trace) -> Trace:
        """Greedy deaths that raise the score, until none does.

        Used on the best sample to report a MAP scene: the chain samples, it does not
        optimise, so its best sample still carries objects whose removal would raise the
        posterior density, typically objects that no camera sees, which only the prior
        scores. This is an estimate of the mode, not part of the chain.
        """
        improved = True
        while improved and trace.objects:
            improved = False
            for k in range(len(trace.objects)):
                objects = trace.objects[:k] + trace.objects[k + 1 :]
                p = moves.Proposal("prune", "", objects, trace.noise, ())
                new = self.evaluate(trace, p)
                if new is not None and new.score > trace.score:
                    trace, improved = new, True
                    break
        return trace
