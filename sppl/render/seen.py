"""Which objects of a scene some camera sees: at least one pixel, after occlusion.

The posterior over the total number of objects counts objects no camera sees, which only the
prior speaks for; the number the cameras *see* is what the observations settle. An object is
seen when it is the nearest surface at one pixel or more of some camera, with the model's
static parts (a ground, a table) occluding like any object.

The renderer answers that with one object-id pass per camera: every part is drawn with its
object's number as its colour (static parts and the background 0) under an ambient light of 1,
so that the shaded colour is the number itself, exactly (``colour * (1 + 0 * lambert)`` in
float32). The ray caster (``sppl.render.raycast``) draws the same pass as the slow twin
(``seen_reference``). Computed only for the samples that are kept, when they are written.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..model.geometry import Part
from ..model.types import Model, RenderSettings


def id_settings(model: Model) -> RenderSettings:
    return RenderSettings(background=(0.0, 0.0, 0.0), ambient=1.0, light=model.render.light)


def id_parts(model: Model, objects) -> list[Part]:
    """The scene's parts with each object's number (1, 2, ...) as its colour, static parts 0."""
    parts = [replace(p, colour=(0.0, 0.0, 0.0)) for p in model.static_parts]
    for i, o in enumerate(objects):
        parts += [replace(p, colour=(float(i + 1), 0.0, 0.0)) for p in o.parts]
    return parts


def seen_in(id_images: Sequence[np.ndarray], n_objects: int) -> list[bool]:
    """Which of ``n_objects`` show in some id image (an (H, W, 3) render of ``id_parts``)."""
    seen = np.zeros(n_objects + 1, dtype=bool)
    for image in id_images:
        ids = np.rint(image[..., 0]).astype(np.int64).ravel()
        ids = ids[(ids > 0) & (ids <= n_objects)]
        seen[np.unique(ids)] = True
    return [bool(s) for s in seen[1:]]


class SeenPass:
    """The fast path: an id pass per camera with the GL renderer."""

    def __init__(self, model: Model, cameras: Sequence, renderer=None) -> None:
        from . import Renderer

        self.model = model
        self.cameras = list(cameras)
        self.renderer = renderer or Renderer(id_settings(model))

    def __call__(self, objects) -> list[bool]:
        objects = list(objects)
        if not objects:
            return []
        parts = id_parts(self.model, objects)
        images = [self.renderer.render(parts, camera)[0] for camera in self.cameras]
        return seen_in(images, len(objects))

    def release(self) -> None:
        self.renderer.release()


def seen_reference(model: Model, objects, cameras: Sequence) -> list[bool]:
    """The slow twin: the same pass by ray casting (tiny images only)."""
    from .raycast import raycast

    objects = list(objects)
    parts = id_parts(model, objects)
    settings = id_settings(model)
    return seen_in([raycast(parts, camera, settings)[0] for camera in cameras], len(objects))


class SeenCache:
    """``SeenPass`` for a chain's samples, made on first use (a run with no samples to write
    renders nothing), reusing the last answer while the objects are the same ones: most
    sweeps of a converged chain change none of them."""

    def __init__(self, model: Model, cameras: Sequence) -> None:
        self.model, self.cameras = model, list(cameras)
        self.pass_: SeenPass | None = None
        self.last: tuple[tuple, list[bool]] = ((), [])

    def __call__(self, objects, keep: bool = True) -> list[bool]:
        objects = tuple(objects)
        last_objects, last_seen = self.last
        if len(objects) == len(last_objects) and all(
                a is b for a, b in zip(objects, last_objects)):
            return last_seen
        if self.pass_ is None:
            self.pass_ = SeenPass(self.model, self.cameras)
        seen = self.pass_(objects)
        if keep:
            self.last = (objects, seen)
        return seen

    def release(self) -> None:
        if self.pass_ is not None:
            self.pass_.release()
            self.pass_ = None
