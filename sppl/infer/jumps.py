"""The built-in model jumps, registered with their reverses (``sppl.model.jumps``), and the
one way the move checks build a proposal's reverse.

Every jump proposes with the same signature, ``(sampler, trace, rng)``. Births, deaths and
replaces weigh several candidates at once where the model sets ``tries`` above 1
(``sppl.infer.tries``): that is how those three propose, not a jump of its own, and each one's
reverse is then the multiple-try reverse through the same candidates.

The built-ins are registered in the order the sampler has always laid out their
probabilities (``Sampler.jump_type``), so that a seed draws the chain it drew before.
"""

from __future__ import annotations

import numpy as np

from ..model.jumps import Jump, jump, register_jump
from ..model.trace import Trace
from . import fit, fitted_birth, fitted_split, merge, moves, pair_refit, tries


def _tries(sampler) -> int:
    return sampler.model.inference.tries


def _without(sampler, noise):
    """What a replace renders the scene without its object with."""
    return lambda objects: sampler.make_trace(objects, noise)


def propose_birth(sampler, trace: Trace, rng: np.random.Generator):
    if _tries(sampler) > 1:
        return tries.propose_birth(sampler, trace, rng, _tries(sampler))
    return moves.propose_birth(sampler.model, trace, rng, sampler.birth)


def propose_death(sampler, trace: Trace, rng: np.random.Generator):
    if _tries(sampler) > 1:
        return tries.propose_death(sampler, trace, rng, _tries(sampler))
    return moves.propose_death(sampler.model, trace, rng, sampler.birth)


def propose_change(sampler, trace: Trace, rng: np.random.Generator):
    return moves.propose_change(sampler.model, trace, rng)


def propose_replace(sampler, trace: Trace, rng: np.random.Generator):
    if _tries(sampler) > 1:
        return tries.propose_replace(sampler, trace, rng, _tries(sampler))
    return moves.propose_replace(sampler.model, trace, rng, sampler.birth,
                                 _without(sampler, trace.noise))


# The jumps of their own modules are looked up when called, as the dispatch did before, so
# that a test can put a broken one in their place (and see the checks catch it).
def propose_refit(sampler, trace: Trace, rng: np.random.Generator):
    return fit.propose_refit(sampler, trace, rng)


def propose_merge(sampler, trace: Trace, rng: np.random.Generator):
    return merge.propose_merge(sampler, trace, rng)


def propose_split(sampler, trace: Trace, rng: np.random.Generator):
    return merge.propose_split(sampler, trace, rng)


def propose_fitted_birth(sampler, trace: Trace, rng: np.random.Generator):
    return fitted_birth.propose_fitted_birth(sampler, trace, rng)


def propose_fitted_death(sampler, trace: Trace, rng: np.random.Generator):
    return fitted_birth.propose_fitted_death(sampler, trace, rng)


def propose_fitted_split(sampler, trace: Trace, rng: np.random.Generator):
    return fitted_split.propose_fitted_split(sampler, trace, rng)


def propose_fitted_merge(sampler, trace: Trace, rng: np.random.Generator):
    return fitted_split.propose_fitted_merge(sampler, trace, rng)


def propose_pair_refit(sampler, trace: Trace, rng: np.random.Generator):
    return pair_refit.propose_pair_refit(sampler, trace, rng)


def undo_drawn(sampler, before: Trace, proposal, after: Trace):
    """The reverse of a proposal that keeps what it drew (the multiple-try jumps' candidates,
    a refit's or a merge's scene without its objects) through those same draws; of one that
    keeps nothing, the reverse built from the proposal densities (``moves.reverse``)."""
    if proposal.tries is not None:
        return proposal.tries.reverse(sampler, before, proposal, after)
    return moves.reverse(sampler.model, before, proposal, after, sampler.birth,
                          without=_without(sampler, after.noise))


register_jump(Jump("birth", propose_birth, "death", undo_drawn, weight=1.0),
              Jump("death", propose_death, "birth", undo_drawn, weight=1.0))
register_jump(Jump("change", propose_change, "change", undo_drawn, weight=1.0))
register_jump(Jump("replace", propose_replace, "replace", undo_drawn, weight=1.0))
register_jump(Jump("refit", propose_refit, "refit", undo_drawn))
register_jump(Jump("merge", propose_merge, "split", undo_drawn),
              Jump("split", propose_split, "merge", undo_drawn))
register_jump(Jump("fitted_birth", propose_fitted_birth, "fitted_death", undo_drawn,
                   needs_observations=True),
              Jump("fitted_death", propose_fitted_death, "fitted_birth", undo_drawn,
                   needs_observations=True))
register_jump(Jump("fitted_split", propose_fitted_split, "fitted_merge", undo_drawn,
                   needs_observations=True),
              Jump("fitted_merge", propose_fitted_merge, "fitted_split", undo_drawn,
                   needs_observations=True))
register_jump(Jump("pair_refit", propose_pair_refit, "pair_refit", undo_drawn))


def reverse(sampler, before: Trace, proposal, after: Trace):
    """The proposal that undoes ``proposal``, made from ``after``, the state it led to: a
    jump's by the ``undo`` it was registered with, which must propose the jump it declares as
    its reverse; a parameter, noise or lighting move's the step back (``moves.reverse``).
    ``ValueError`` where there is none, which the move checks report as a failure."""
    try:
        registered = jump(proposal.move)
    except KeyError:
        return moves.reverse(sampler.model, before, proposal, after, sampler.birth,
                              without=_without(sampler, after.noise))
    back = registered.undo(sampler, before, proposal, after)
    if back.move != registered.reverse:
        raise ValueError(f"the reverse of a {proposal.move!r} proposal is declared to be "
                         f"{registered.reverse!r}, but its undo proposed a {back.move!r}")
    return back
