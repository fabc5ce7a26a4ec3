"""The registry of primitives: the shapes a geometry line can name.

Everything that draws, ray-casts, bounds or footprints a part finds its shape here, so that a
new shape is one module (a ``Primitive`` and its ``register_primitive`` call) and, if it is to
be drawn exactly rather than as a triangle mesh, a GLSL snippet with its numpy twin. Installed
packages offer primitives through the ``sppl.primitives`` entry-point group, each entry point
naming a ``Primitive``.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np
import trimesh

from ...errors import SpplError

# Round shapes are footprinted as polygons with this many sides: enough that the polygon
# differs from the circle by under 0.2% of the radius.
ROUND_SECTIONS = 48

# A part whose primitive is MESH_PREFIX + an absolute path draws the mesh in that file; the
# language's ``mesh("file")`` is therefore not a registered primitive.
MESH_PREFIX = "mesh:"
RESERVED = ("mesh",)

# Candidate hits of rays with a unit shape: each (t, normal), t (N,) the distance along the
# ray (NaN where that candidate is missed), normal (N, 3) the unit shape's outward normal.
Hits = list[tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True, eq=False)
class Primitive:
    """A shape that model files name in a geometry line, ``name(arguments...)``.

    A *base* shape has a unit shape (``mesh``, a closed solid: the renderers skip the back
    faces of every registered shape) resting on the ground, its lowest point at z = 0 and its
    axis the z axis, which a part poses with one 4x4 matrix; ``scale`` maps the
    geometry line's arguments to that matrix's scale along x, y and z. A *composite* shape
    has no mesh of its own: ``pieces`` maps the arguments to base shapes, each under its own
    matrix (a capsule is a cylinder and two spheres).

    A base shape is drawn as its mesh's triangles, unless it has ``glsl``: the source of a
    function ``bool NAME_hit(vec3 origin, mat3 unit_from_camera, vec3 ray, out float t, out
    vec3 normal)`` giving the nearest hit of a camera ray with the exact unit shape
    (``sppl/render/shaders/ray_cast.glsl`` says what each argument is and has helpers). Then
    ``hits``, its numpy twin for the reference renderer, is required: ``hits(origin,
    direction)`` with (N, 3) arrays in the unit shape's coordinates returns every candidate
    hit (``Hits``). The fragment shader is reached through ``proxy``, a convex solid around
    the unit shape (default: the mesh's bounding box). ``outline`` gives points whose convex
    hull seen from above is the unit shape's footprint (default: the mesh's hull vertices).

    ``caster`` is the code of the built-in shapes that ``lighting.glsl`` tests shadow rays
    against; other shapes receive shadows but cast none, as mesh files do.
    """

    name: str
    arguments: tuple[str, ...]
    mesh: Callable[[], trimesh.Trimesh] | None = None
    scale: Callable[[Sequence[float]], Sequence[float]] | None = None
    pieces: Callable[[Sequence[float]], list[tuple[str, np.ndarray]]] | None = None
    glsl: str | None = None
    hits: Callable[[np.ndarray, np.ndarray], Hits] | None = None
    proxy: Callable[[], trimesh.Trimesh] | None = None
    outline: Callable[[], np.ndarray] | None = None
    caster: int | None = None

    @property
    def base(self) -> bool:
        return self.mesh is not None

    @property
    def ray_cast(self) -> bool:
        return self.glsl is not None

    def parts(self, sizes: Sequence[float]) -> list[tuple[str, np.ndarray]]:
        """The base shapes this shape is made of at these argument values, each with the
        matrix that scales (and places) it."""
        if self.pieces is not None:
            return self.pieces(sizes)
        x, y, z = self.scale(sizes)
        return [(self.name, np.diag([x, y, z, 1.0]))]


_registry: dict[str, Primitive] = {}
_plugins_loaded = False


def register_primitive(primitive: Primitive) -> Primitive:
    """Make a shape usable in model files and drawable by both renderers; returns it.

    Registering a second shape under a name that is taken is an error (a cached mesh or
    shader would otherwise draw the first); registering the same object again does nothing.
    """
    _check(primitive)
    existing = _registry.get(primitive.name)
    if existing is primitive:
        return primitive
    if existing is not None:
        raise SpplError(f"a primitive named {primitive.name!r} is already registered")
    _registry[primitive.name] = primitive
    return primitive


def _check(p: Primitive) -> None:
    def bad(why: str) -> SpplError:
        return SpplError(f"the primitive {p.name!r} cannot be registered: {why}")

    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", p.name) or p.name in RESERVED:
        raise bad("its name must be an identifier other than " + ", ".join(RESERVED))
    if not p.arguments or len(set(p.arguments)) != len(p.arguments):
        raise bad("it needs one or more arguments, each named once")
    if (p.mesh is None) == (p.pieces is None):
        raise bad("give either a unit mesh (a base shape) or pieces (a composite)")
    if p.mesh is not None and p.scale is None:
        raise bad("a base shape needs `scale`, its arguments' scale along x, y and z")
    if (p.glsl is None) != (p.hits is None):
        raise bad("an exact ray-cast needs both `glsl` and its numpy twin `hits`")
    if p.glsl is not None and not re.search(rf"\bbool\s+{p.name}_hit\s*\(", p.glsl):
        raise bad(f"its GLSL must define `bool {p.name}_hit(...)`")
    if p.glsl is not None and p.mesh is None:
        raise bad("only a base shape can be ray-cast")


def get_primitive(name: str) -> Primitive:
    """The registered shape of this name; KeyError naming the known ones if there is none."""
    if name not in _registry:
        _load_plugins()
    try:
        return _registry[name]
    except KeyError:
        raise KeyError(f"unknown primitive {name!r}; known primitives: "
                       f"{', '.join(primitive_names())}") from None


def find_primitive(name: str) -> Primitive | None:
    try:
        return get_primitive(name)
    except KeyError:
        return None


def primitive_names() -> tuple[str, ...]:
    """Every registered shape's name, in the order of registration (built-ins first)."""
    _load_plugins()
    return tuple(_registry)


def unregister_primitive(name: str) -> None:
    """Forget a shape (for tests that register one of their own)."""
    _registry.pop(name, None)


def _load_plugins() -> None:
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for ep in entry_points(group="sppl.primitives"):
        if ep.name in _registry:
            continue
        try:
            register_primitive(ep.load())
        except Exception as err:  # a broken plugin must not take sppl down with it
            raise SpplError(f"the primitive plugin {ep.name!r} ({ep.value}) failed to load: "
                            f"{err}") from None


def glsl_beside(module_file: str) -> str:
    """The GLSL snippet in the file beside a shape's module, of the same name with the suffix
    ``.glsl``: a shader file of its own, which editors highlight and GL reports lines of."""
    return Path(module_file).with_suffix(".glsl").read_text(encoding="utf-8")


def bounding_box(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The default proxy: the axis-aligned box around a unit mesh."""
    return trimesh.creation.box(bounds=mesh.bounds)


def disc(height: float) -> tuple[np.ndarray, np.ndarray]:
    """Points of the unit circle at a height, homogeneous (ROUND_SECTIONS, 4): outlines."""
    t = np.linspace(0.0, 2.0 * np.pi, ROUND_SECTIONS, endpoint=False)
    xy = np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.column_stack([xy, np.full(len(xy), height), np.ones(len(xy))])


def roots(a, b, c):
    """Both roots of a t^2 + 2 b t + c = 0 per ray (NaN where there are none); where a = 0,
    the one root of the linear equation, twice. For the ``hits`` of quadric shapes."""
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(b * b - a * c)
        linear = np.where(a == 0.0, -c / (2.0 * b), np.nan)
        return (np.where(a != 0.0, (-b - root) / a, linear),
                np.where(a != 0.0, (-b + root) / a, linear))


def plane_hit(o: np.ndarray, d: np.ndarray, height: float, facing: float) -> tuple:
    """The candidate hit of rays with the disc of radius 1 in the plane z = height, its
    normal (0, 0, facing)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (height - o[:, 2]) / d[:, 2]
    point = o + np.nan_to_num(t, posinf=0.0, neginf=0.0)[:, None] * d
    t = np.where(point[:, 0] ** 2 + point[:, 1] ** 2 <= 1.0, t, np.nan)
    return t, np.tile((0.0, 0.0, facing), (len(d), 1))
