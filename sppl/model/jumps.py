"""The registry of model jumps: each jump once, by name, with how it proposes and which jump
undoes it.

A model weighs its jumps by name (``InferenceSettings.jump_weights``, ``jump_weights`` in a
model file), the sampler draws one by those weights and asks it for a proposal, and the move
checks undo each proposal with the jump it declares as its reverse. All of them read the names
from here, so a jump registered once is weighed, proposed and checked like the built-in ones
(``sppl.infer.jumps`` registers those; docs/walkthroughs/adding-a-jump.md adds one).

The registry lives with the model, not with the sampler, because the language checks a model
file's ``jump_weights`` against it, as it checks a sensor's likelihood against the likelihoods'
registry; it holds the proposal functions without calling them. Installed packages offer
jumps through the ``sppl.jumps`` entry-point group, each entry point naming a ``Jump`` or a
tuple of two that undo each other; they are registered the first time the registry is read,
in every process that reads it (worker processes included).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

from ..errors import SpplError


@dataclass(frozen=True)
class Jump:
    """A model jump.

    ``propose(sampler, trace, rng)`` returns a ``sppl.infer.moves.Proposal`` whose ``move`` is
    ``name``, or None where the jump cannot act from ``trace`` (a death in an empty scene); it
    draws only from ``rng``. ``reverse`` names the jump that undoes it (itself for a jump that is
    its own reverse). ``undo(sampler, before, proposal, after)`` builds that reverse proposal
    from ``after``, the state ``proposal`` led to: applied to ``after`` it must give back
    ``before``, with minus the forward's log acceptance ratio (``sppl.verify.move_checks``
    checks both). ``weight`` is the jump's weight where a model does not set one (0: off unless
    weighed); ``needs_observations`` marks a jump that starts from what observations leave
    unexplained, which never acts in the prior's chain, so it is given no weight there.
    """

    name: str
    propose: Callable[[Any, Any, Any], Any]
    reverse: str
    undo: Callable[[Any, Any, Any, Any], Any]
    weight: float = 0.0
    needs_observations: bool = False


_registry: dict[str, Jump] = {}


def register_jump(*jumps: Jump) -> None:
    """Register jumps: one that is its own reverse, or a pair of mutual reverses together.

    Each jump's declared reverse must be registered (or among ``jumps``) and declare it back:
    a jump without a reverse could not be balanced. The order of registration is the order in
    which the sampler lays out the jumps' probabilities, so registering a jump does not change
    what the chains of models that do not weigh it draw.
    """
    names = [j.name for j in jumps]
    taken = [n for n in names if n in _registry]
    if taken or len(set(names)) != len(names):
        raise SpplError(f"jump {(taken or names)[0]!r} is registered twice")
    known = {**_registry, **{j.name: j for j in jumps}}
    for j in jumps:
        if j.reverse not in known:
            raise SpplError(f"jump {j.name!r} declares {j.reverse!r} as its reverse, which is "
                             "not registered: register the two together")
        back = known[j.reverse].reverse
        if back != j.name:
            raise SpplError(f"jump {j.name!r} declares {j.reverse!r} as its reverse, but "
                             f"{j.reverse!r} declares {back!r}")
    _registry.update((j.name, j) for j in jumps)


def unregister_jump(*names: str) -> None:
    """Remove jumps, a pair of mutual reverses together (for tests and notebooks)."""
    missing = [n for n in names if n not in _registry]
    if missing:
        raise SpplError(f"jump {missing[0]!r} is not registered")
    lone = [n for n in names if _registry[n].reverse not in names]
    if lone:
        raise SpplError(f"jump {lone[0]!r} is the reverse of {_registry[lone[0]].reverse!r}: "
                         "remove the two together")
    for n in names:
        del _registry[n]


def jump(name: str) -> Jump:
    """The registered jump ``name``; KeyError where there is none."""
    if name not in _registry:
        _load_plugins()
    return _registry[name]


def jump_names() -> tuple[str, ...]:
    """The registered jumps' names, in the order of registration."""
    _load_plugins()
    return tuple(_registry)


def default_weights() -> dict[str, float]:
    """Each registered jump's weight where a model does not set one."""
    _load_plugins()
    return {j.name: j.weight for j in _registry.values()}


_plugins_loaded = False


def _load_plugins() -> None:
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for ep in entry_points(group="sppl.jumps"):
        try:
            loaded = ep.load()
            jumps = tuple(loaded) if isinstance(loaded, (tuple, list)) else (loaded,)
            if not any(j.name in _registry for j in jumps):  # not registered by an import
                register_jump(*jumps)
        except Exception as err:  # a broken plugin must not take sppl down with it
            raise SpplError(f"the jump plugin {ep.name!r} ({ep.value}) failed to load: "
                            f"{err}") from None


def reverse_pairs() -> tuple[tuple[str, str], ...]:
    """The pairs of distinct jumps that undo each other, each once, in the order of
    registration."""
    _load_plugins()
    return tuple((j.name, j.reverse) for i, j in enumerate(_registry.values())
                 if j.reverse != j.name and list(_registry).index(j.reverse) > i)
