"""``capsule(radius, length)``: a cylinder of the given length between two half-buried
spheres, resting on the ground like the other shapes (total height length + 2 radius)."""

import numpy as np

from .registry import Primitive, register_primitive


def _pieces(s) -> list[tuple[str, np.ndarray]]:
    r, length = s
    body = np.diag([r, r, length, 1.0])
    body[2, 3] = r
    top = np.diag([r, r, r, 1.0])
    top[2, 3] = length
    return [("cylinder", body), ("sphere", np.diag([r, r, r, 1.0])), ("sphere", top)]


CAPSULE = register_primitive(Primitive("capsule", ("radius", "length"), pieces=_pieces))
