"""The face move: a size stepped together with the place, so that one side of the object stays
where it stands.

A box the chain holds 5 cm too long, its far end over bare table, is not shortened by the
random walk of its parameters: shortened with its centre kept, the box uncovers 2.5 cm of its
near end, which the cameras see; moved alone, it uncovers that end too. Each change alone is
worse, and the joint step of all six parameters rarely lines up with the one direction that
is better: shortened by 5 cm with its near end kept, tabletop.scn's prior scene 6 gains 524
nats, with no dip deeper than 2 nats on the way (benchmarks/README.md). A refit's search
moves one parameter at a time and stops there too. The face move steps a size parameter p
of object k and moves its place so that one corner of each of its parts' boxes stays put:

    p' = p + delta,   (x', y') = (x, y) - delta u,

with delta ~ N(0, (s f)^2) (s the parameter's declared step, f the warm-up's factor) and u
uniform among the object's reaches R(p): the distinct horizontal displacements of its parts'
posed bounding-box corners per unit of p (a box's width: half its width axis, either way; a
cube's side or a radius: one towards each corner of the object's box). R is measured at two fixed values of p
(``REFERENCE``) and a fixed place, so it depends on the object's other parameters alone, and
the move does not change those. So its reverse is the same u with -delta: the map (p, x, y)
-> (p', x', y') is a shear of Jacobian 1, both directions draw u with probability 1 / |R| and
delta with the same density, and the ratio is the posterior's alone. A p' outside its domain
has zero prior and is rejected (no reflection, which would break the shear). A parameter
with no horizontal reach (a height) has no face move. docs/inference.md has the derivation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.domains import Finite, Periodic
from ..model.trace import Trace, make_object
from ..model.types import Model, ObjectClass
from ..render.bounds import world_corners
from .moves import Proposal

# The two values of p at which the reaches are measured: fixed, so that they do not depend
# on p (for a size the geometry is linear in, any two give the same reaches).
REFERENCE = (1.0, 2.0)
# Displacements closer than this (metres per unit of p) are one reach; a shorter one is none.
ROUNDING = 9


def face_parameters(cls: ObjectClass) -> tuple[str, ...]:
    """The parameters of ``cls`` a face move may step: continuous, not angles, not its place;
    only for a class with a declared ground position."""
    if cls.position is None:
        return ()
    return tuple(p.name for p in cls.parameters
                 if p.continuous and not isinstance(p.domain, (Periodic, Finite))
                 and p.name not in cls.position)


def reaches(cls: ObjectClass, values, name: str) -> np.ndarray:
    """R(p) of an object with ``values``: (m, 2) distinct horizontal displacements of its
    parts' corners per unit of parameter ``name``, each nonzero, in a fixed order; empty where
    the parameter moves no corner sideways or the geometry cannot be built at the references."""
    x, y = cls.position
    at = {**values, x: 0.0, y: 0.0}
    try:
        lo = world_corners(cls.parts({**at, name: REFERENCE[0]}))
        hi = world_corners(cls.parts({**at, name: REFERENCE[1]}))
    except (ValueError, ArithmeticError):
        return np.empty((0, 2))
    moved = ((hi[:2] - lo[:2]) / (REFERENCE[1] - REFERENCE[0])).T
    moved = np.round(moved, ROUNDING)
    moved = moved[np.isfinite(moved).all(axis=1) & (np.abs(moved).max(axis=1) > 0.0)]
    return np.unique(moved, axis=0) if len(moved) else np.empty((0, 2))


@dataclass(frozen=True)
class FaceStep:
    """What a face move drew, for its reverse: the object's place, the parameter, the reach
    and the step."""

    place: int
    name: str
    side: int
    delta: float

    def undo(self, model: Model, after: Trace, before: Trace) -> Proposal:
        """The reverse: the same reach, the step back, from ``after``. It lands on the object
        of ``before`` to rounding (p + delta - delta); that object itself is proposed, so
        that the pair gives back exactly the state it left. ``ValueError`` where it lands
        elsewhere: the reach changed with the step, and the move would not be symmetric."""
        back = propose_face(model, after, self.place, self.name, None,
                            side=self.side, delta=-self.delta)
        old = before.objects[self.place]
        if back is None or any(
                not math.isclose(back.changed[0].values[n], old.values[n], rel_tol=1e-9,
                                 abs_tol=1e-12) for n in (self.name, *old.cls.position)):
            raise ValueError(f"a face move of {old.cls.name}.{self.name} stepped back does not "
                             "give the object back: its reach changed with the step")
        objects = after.objects[:self.place] + (old,) + after.objects[self.place + 1:]
        return Proposal("face", old.cls.name, objects, after.noise, (old,),
                        tries=FaceStep(self.place, self.name, self.side, -self.delta))


def propose_face(model: Model, trace: Trace, k: int, name: str, rng: np.random.Generator | None,
                 factor: float = 1.0, side: int | None = None, delta: float | None = None
                 ) -> Proposal | None:
    """A face move of parameter ``name`` of object ``k``; with ``side`` and ``delta``, exactly
    that one (a face move's reverse). None where the parameter has no reach."""
    old = trace.objects[k]
    cls = old.cls
    reach = reaches(cls, old.values, name)
    if not len(reach):
        return None
    if side is None:
        side = int(rng.integers(len(reach)))
    if delta is None:
        delta = cls.parameter(name).proposal_scale * factor * float(rng.standard_normal())
    x, y = cls.position
    values = dict(old.values)
    values[name] = old.values[name] + delta
    values[x] = old.values[x] - delta * float(reach[side, 0])
    values[y] = old.values[y] - delta * float(reach[side, 1])
    if not all(math.isfinite(values[n]) for n in (name, x, y)):
        return None
    obj = make_object(model, cls, values)
    objects = trace.objects[:k] + (obj,) + trace.objects[k + 1:]
    return Proposal("face", cls.name, objects, trace.noise, (obj,),
                    tries=FaceStep(k, name, side, delta))
