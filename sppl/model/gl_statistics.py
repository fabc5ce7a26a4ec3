"""The likelihood statistics the GL side can compute, by name.

Scoring is fast when a likelihood's statistics are reduced where the pixels are drawn
(``sppl.render.pixels``) instead of read back; which computation serves a likelihood is its own
declaration, the class attribute ``gl_statistics`` (a name registered here, or None: the
scorer reads the renders back and calls ``statistics``). Each GL-side computation is registered
once, with the numpy function it must equal, the shader it needs and the likelihood methods it
stands in for.

A declaration holds for the class that makes it and for subclasses that keep those methods: a
subclass that redefines one of them (``statistics``, or a per-pixel density) without declaring
again is scored in numpy, since the GL side would still compute its parent's.

The registry lives in ``model`` so that the likelihoods (here) and the GL side (``render``,
``scoring``) can both read it without ``model`` importing ``render``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from ..errors import SpplError


@dataclass(frozen=True)
class GlStatistics:
    """One GL-side computation of a likelihood's statistics."""

    name: str
    #: The numpy function the GL side must equal, called as a likelihood's ``statistics`` is
    #: (the likelihood first): the reference path's answer, and what tests hold the GL side to.
    reference: Callable
    #: The GLSL file under ``sppl/render/shaders`` the terms pass includes (after the defines
    #: that pick each modality's term), or None where ``terms.frag``'s own squared residuals
    #: are the terms.
    shader: str | None
    #: Scored at given noise values (the likelihood's ``per_pixel``, ``sppl.model.robust``):
    #: the terms are per-pixel log densities, else sums the noise moves re-use.
    per_pixel: bool
    #: The likelihood methods whose results the GL side reproduces: redefining one below the
    #: declaring class leaves the GL side computing something else.
    methods: tuple[str, ...]
    description: str = ""


_registry: dict[str, GlStatistics] = {}


def register_gl_statistics(name: str, reference: Callable, *, shader: str | None = None,
                           per_pixel: bool = False, methods: tuple[str, ...] = ("statistics",),
                           description: str = "") -> GlStatistics:
    """Register a GL-side computation under ``name``, once.

    The GL side carries it out from this record alone: a per-pixel computation's ``shader``
    defines each modality's log density (``image_density`` and ``depth_density``, as
    ``likelihood.glsl`` does, picked by the likelihood's ``shader_term`` and fed its
    ``uniforms``); any other is ``terms.frag``'s squared residuals, which is all the GL side
    sums without a shader."""
    if name in _registry:
        raise SpplError(f"the GL statistics {name!r} are already registered")
    if per_pixel != (shader is not None):
        raise SpplError(f"the GL statistics {name!r}: a per-pixel computation names the shader "
                        "of its log densities, and only a per-pixel one does")
    if "statistics" not in methods:
        # Whatever else the GL side reproduces, it stands in for the statistics.
        methods = ("statistics", *methods)
    found = _registry[name] = GlStatistics(name, reference, shader, per_pixel, tuple(methods),
                                           description)
    return found


def registered_gl_statistics() -> Mapping[str, GlStatistics]:
    """Every registered GL-side computation, by name (read-only)."""
    return MappingProxyType(_registry)


def declared_gl_statistics(likelihood) -> GlStatistics | None:
    """The GL-side computation a likelihood declares and may use, or None: it declares none,
    or a subclass below the declaring class redefines a method the computation stands in for.
    A name that is not registered is an error, not a quiet fall back to the slow path."""
    cls = type(likelihood)
    declarer = next((c for c in cls.__mro__ if "gl_statistics" in c.__dict__), None)
    if declarer is None:
        return None
    name = declarer.__dict__["gl_statistics"]
    if name is None:
        return None
    found = _registry.get(name)
    if found is None:
        known = ", ".join(sorted(_registry))
        raise SpplError(f"{declarer.__name__} declares the GL statistics {name!r}, which are not "
                        f"registered; the registered ones are {known}")
    below = cls.__mro__[: cls.__mro__.index(declarer)]
    if any(m in c.__dict__ for c in below for m in found.methods):
        return None
    if found.per_pixel != bool(getattr(likelihood, "per_pixel", False)):
        return None  # its statistics would not have the shape the scorer gives
    return found
