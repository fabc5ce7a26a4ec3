"""Likelihood terms computed where the pixels are: on the GL side.

The fast path of ``sppl.scoring.scorer``. Each camera's observation is uploaded once as an RGBA float
texture (RGB, and depth in alpha); a hypothesis is drawn with a fragment shader that writes
each pixel's squared-residual terms instead of its colour (``shaders/terms.frag``; for a robust
likelihood its log densities, ``shaders/likelihood.glsl``, at noise values set by
``set_noise``), every part
of a primitive in one instanced draw. The read-back is two floats a pixel, inside the rectangle
the drawn parts can reach only (every term outside it is 0), and the CPU only sums them, in
float64: the GPU sums nothing, so float32 there costs only the rounding of each pixel's own
terms (a few units of 2^-24 of its squares; tests/test_fast_scoring.py bounds the total). Each camera has its own programs,
whose uniforms are set once.

Every camera draws into its own framebuffer with the viewport at the origin, exactly as
``Renderer`` does: an offset viewport (tiles of one big framebuffer) changes the rounding of
window coordinates, and thin triangles then cover different pixels. With the same arithmetic
and the same culling the terms are those of the reference path's read-back images, pixel for
pixel (the tests hold the two to that rounding). Drawing the cameras of one size as the layers of one
framebuffer keeps that rounding, but measured slower on llvmpipe (``docs/scoring.md``).

Rendering a region only (a scissor rectangle per camera) is what incremental scoring uses: the
pixels there come out exactly as in a full render, since everything that can reach them is
still drawn.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from ..data.camera import Camera
from ..errors import RenderError
from ..model.geometry import Part, linear_inverse
from ..model.types import RenderSettings
from .bounds import Rect, closed, union
from .context import claim_state, gl_context
from .kernels import compiled
from .lighting import BLOCK_BYTES, block
from .renderer import (
    FLIP_Y,
    LIGHTING_BINDING,
    VERTEX_FORMAT,
    _column_major,
    flat_vertices,
    program,
    ray_cast,
    shape,
)

if TYPE_CHECKING:
    from .drawlist import Drawn

# An instance's row of floats: model matrix (16), normal matrix (9), colour (3), column-major.
INSTANCE_FORMAT = "16f 9f 3f/i"
ROW_BYTES = 4 * (16 + 9 + 3)
# An observed value that marks "no term here". Not -1 or any value an observation can take:
# simulated images and depth maps (Gaussian noise around a dark colour or a near surface) go
# below zero, and such a pixel must still be scored. The shader takes any value below
# terms.frag's MISSING_BELOW for this mark.
MISSING = -3.0e38
TRIANGLES = moderngl.TRIANGLES


def instance_rows(parts: Sequence[Part]) -> dict[str, bytes]:
    """Per primitive, the instance rows of its parts, in the parts' order, packed as the
    instance buffer holds them. Parts whose matrix is singular are left out, as ``Renderer``
    leaves them out (they enclose nothing)."""
    groups: dict[str, list[float]] = {}
    for part in parts:
        inverse = linear_inverse(part.matrix)
        if inverse is None:
            continue
        # Column-major model matrix; the inverse's rows are the inverse-transpose's columns.
        floats = groups.setdefault(part.primitive, [])
        floats += part.matrix.ravel(order="F").tolist()
        floats += inverse
        floats += part.colour
    # Packed bytes rather than an array: a pass joins and uploads them and needs nothing else,
    # and packing a few floats costs a third of making an array of them.
    return {primitive: struct.pack(f"{len(floats)}f", *floats)
            for primitive, floats in groups.items()}


class _Slot:
    """One camera's instance buffers, one per primitive, with their vertex arrays: each
    camera has its own, so that no buffer is rewritten while a pass that reads it is
    pending."""

    def __init__(self) -> None:
        self.buffers: dict[str, moderngl.Buffer] = {}
        self.vaos: dict[str, moderngl.VertexArray] = {}
        self.entries: dict[str, tuple] = {}  # PixelScorer._entry's, by primitive


class PixelScorer:
    """Draws hypotheses into per-pixel squared-residual terms for a fixed set of cameras.

    ``observed[i]`` is camera i's (rgb or None, depth or None): depth with NaN where it is
    masked out. The terms at a pixel are (image, depth): the squared residual of that modality
    minus the squared residual against the empty scene's render (background colour, depth_max).
    """

    def __init__(self, settings: RenderSettings, cameras: Sequence[Camera], observed,
                 terms: Mapping[str, int] | None = None, shaders: Sequence[str] = ()) -> None:
        self.ctx = ctx = gl_context()
        self.compiled = compiled
        self.cameras = list(cameras)
        # Which likelihood each modality's terms are (the defines of the ``shaders`` that
        # compute per-pixel densities, as sppl.model.gl_statistics names them; all 0: the
        # Gaussian's squared residuals), and per camera the robust ones' noise uniforms
        # (``set_noise``).
        terms = {"IMAGE_TERM": 0, "DEPTH_TERM": 0, "DEPTH_RETURNS": 0, **(terms or {})}
        self._prelude = "".join(f"#define {k} {int(v)}\n" for k, v in terms.items())
        for name in shaders:
            self._prelude += resources.files(__package__).joinpath(
                "shaders", name).read_text(encoding="utf-8")
        self._noise: list[dict[str, tuple]] = [{} for _ in self.cameras]
        # Each camera's observation stays bound to a texture unit of its own (while there
        # are units enough), so that a pass need not bind it.
        units = min(len(self.cameras), ctx.info["GL_MAX_TEXTURE_IMAGE_UNITS"])
        self._unit = [c % units for c in range(len(self.cameras))]
        self._bound: list[int | None] = [None] * units  # which camera's texture each unit holds
        self._culling = False
        # Each camera has its own programs (one per kind of shape, made when first drawn),
        # whose uniforms are set then, once: writing a camera's ten uniforms before each of
        # its passes cost more than the draws. The lighting, which a hypothesis may change,
        # is one uniform block all of them read (lighting.glsl), written when it changes.
        self._settings = settings
        self._lighting = ctx.buffer(reserve=BLOCK_BYTES, dynamic=True)
        self._written: bytes | None = None
        self.default_block = block(settings)
        self._programs: list[dict[str | None, moderngl.Program]] = [{} for _ in self.cameras]
        self._meshes = {}
        limit = ctx.info["GL_MAX_TEXTURE_SIZE"]
        self.observed = []
        for camera, (rgb, depth) in zip(self.cameras, observed):
            if max(camera.width, camera.height) > limit:
                raise RenderError(f"cannot render a {camera.width}x{camera.height} image on "
                                  "this GL driver")
            texels = np.full((camera.height, camera.width, 4), MISSING, dtype="f4")
            if rgb is not None:
                texels[..., :3] = rgb
            if depth is not None:
                texels[..., 3] = np.where(np.isfinite(depth), depth, MISSING)
            texture = ctx.texture((camera.width, camera.height), 4, texels.tobytes(), dtype="f4")
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.observed.append(texture)
        self._ones = np.ones(max(c.width * c.height for c in self.cameras))
        self._slots = [_Slot() for _ in self.cameras]
        self._targets = [self._make_target(c) for c in self.cameras]
        self._fbos = [fbo for fbo, _ in self._targets]

    # -- drawing -------------------------------------------------------------------------------

    def render(self, hypotheses: Sequence[Sequence[Drawn]],
               lighting: Sequence[bytes] | None = None):
        """Terms of whole hypotheses, each given as the ``Drawn`` of its static parts and
        objects in order, lit by the ``Lighting`` block (``lighting.block``) given for it
        (default: the scorer's settings, no casters). Per hypothesis, a list of per-camera
        blocks (rect, terms): every pixel outside rect is 0, since no part can reach it
        (None: nothing is in view); and their float64 sums, (len(hypotheses), cameras, 2)."""
        blocks, sums = [], np.zeros((len(hypotheses), len(self.cameras), 2))
        self._begin()
        # One hypothesis at a time, read back before the next is drawn: with llvmpipe
        # rasterising on the calling thread nothing overlaps anyway, and a batch of pending
        # framebuffers measured slower per hypothesis than one.
        for b, drawn in enumerate(hypotheses):
            self._light(lighting[b] if lighting is not None else self.default_block)
            rects = []
            for c in range(len(self.cameras)):
                fbo = self._target(c)
                fbo.scissor = None  # a framebuffer keeps its scissor, and use() applies it
                fbo.use()
                fbo.clear(0.0, 0.0, 0.0, 0.0, 1.0)
                rects.append(self._draw(c, drawn, None))
            # Only the pixels the parts can reach are read back and kept: objects usually
            # cover a small part of the image, and the rest is the cleared 0.
            terms = []
            for c, rect in enumerate(rects):
                if rect is None:
                    terms.append(None)
                    continue
                block = np.empty((rect[1] - rect[0], rect[3] - rect[2], 2), dtype="f4")
                self._target(c).read_into(block, viewport=_window(rect), components=2,
                                          dtype="f4")
                sums[b, c] = self.change(block, None)
                terms.append((rect, block))
            blocks.append(terms)
        self.ctx.scissor = None  # left on, the scissor test would restrict others' clears
        return blocks, sums

    def render_regions(self, drawn: Sequence[Drawn], rects: Sequence[Rect | None],
                       lighting: bytes | None = None):
        """Terms of one hypothesis inside one rectangle per camera (None: skip that camera);
        a list of (rows, cols, 2) arrays, or None for the cameras skipped. Only what meets a
        rectangle is drawn there; the ``Lighting`` block's casters, which shade it too, are
        all the hypothesis's parts."""
        self._begin()
        self._light(self.default_block if lighting is None else lighting)
        out = []
        for c, rect in enumerate(rects):
            if rect is None:
                out.append(None)
                continue
            window = (rect[2], rect[0], rect[3] - rect[2], rect[1] - rect[0])  # _window(rect)
            fbo = self._fbos[c]
            fbo.scissor = window  # for the clear and the draws: use() applies it
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, 1.0)
            self._draw(c, drawn, rect)
            patch = np.empty((window[3], window[2], 2), dtype="f4")
            fbo.read_into(patch, window, 2, dtype="f4")
            out.append(patch)
        self.ctx.scissor = None  # left on, the scissor test would restrict others' clears
        return out

    def change(self, new: np.ndarray, old: np.ndarray | None):
        """Float64 sums of new's terms less old's (None: no terms; else of new's shape), as
        a pair of floats."""
        if self.compiled is not None:
            found = self.compiled.change(new, old)
            if found is not None:
                return found
        return tuple(self.change_python(new, old).tolist())

    def change_python(self, new: np.ndarray, old: np.ndarray | None) -> np.ndarray:
        """``change`` in numpy: the compiled kernel's twin and fallback."""
        if old is None:
            return self.total(new)
        # One difference of the blocks in float64 (exact: both are float32) and one sum.
        flat = np.subtract(new, old, dtype=np.float64).reshape(-1, 2)
        return self._ones[: len(flat)] @ flat

    def total(self, terms: np.ndarray) -> np.ndarray:
        """Float64 sums of the two channels of a (rows, cols, 2) block of terms."""
        # A product with a vector of ones, in float64: exact to rounding, and far faster
        # than numpy's sum over the first axis of an (n, 2) array.
        flat = terms.reshape(-1, 2).astype(np.float64)
        n = len(flat)
        if len(self._ones) < n:
            self._ones = np.ones(n)
        return self._ones[:n] @ flat

    def set_noise(self, c: int, uniforms: Mapping[str, tuple]) -> None:
        """Camera c's robust likelihoods' noise uniforms (likelihood.glsl's image_noise,
        depth_noise, depth_returns), for the passes that follow."""
        self._noise[c] = dict(uniforms)
        for found in self._programs[c].values():
            self._write(found, uniforms)

    @staticmethod
    def _write(found: moderngl.Program, uniforms: Mapping[str, tuple]) -> None:
        for name, value in uniforms.items():
            member = found.get(name, None)  # the compiler drops a uniform a program never reads
            if member is not None:
                member.value = value

    def release(self) -> None:
        for fbo, objects in self._targets:
            fbo.release()
            for obj in objects:
                obj.release()
        for slot in self._slots:
            for obj in [*slot.vaos.values(), *slot.buffers.values()]:
                obj.release()
        programs_ = [p for kinds in self._programs for p in kinds.values()]
        for obj in [*self._meshes.values(), *self.observed, *programs_, self._lighting]:
            obj.release()
        self._targets, self._slots, self._meshes, self.observed = [], [], {}, []
        self._programs = []

    # -- helpers -------------------------------------------------------------------------------

    def _begin(self) -> None:
        # The context is shared with ``Renderer`` and other scorers: set every state these
        # passes need when another has set its own since.
        if claim_state(self):
            self.ctx.enable_only(moderngl.DEPTH_TEST)
            self._culling = False
            # The projection's y flip makes front faces clockwise on the screen.
            self.ctx.front_face = "cw"
            self._bound = [None] * len(self._bound)
            # Another user binds its own block to the same point.
            self._lighting.bind_to_uniform_block(LIGHTING_BINDING)

    def _light(self, data: bytes) -> None:
        """Make ``data`` the block the next draws read, writing it only if it changed."""
        if data != self._written:
            self._lighting.write(data)
            self._written = data

    def _draw(self, c: int, drawn: Sequence[Drawn], region: Rect | None) -> Rect | None:
        """Draw camera c's view of ``drawn`` (inside ``region``) into the bound framebuffer;
        the rectangle that holds every pixel drawn (None: nothing was)."""
        rows: dict[str, list[bytes]] = {}
        cover = None
        cull = True
        for d in drawn:
            rect = d.rects[c]
            if rect is None:
                continue
            if region is None:
                cover = rect if cover is None else union(cover, rect)
            elif not (rect[0] < region[1] and region[0] < rect[1] and rect[2] < region[3]
                      and region[2] < rect[3]):  # meets(rect, region), inlined: a hot loop
                continue
            if d.inside[c]:
                cull = False
            for primitive, r in d.rows.items():
                chunks = rows.get(primitive)
                if chunks is None:
                    rows[primitive] = [r]
                else:
                    chunks.append(r)
        if not rows:
            return None
        unit = self._unit[c]
        if self._bound[unit] != c:
            self.observed[c].use(location=unit)
            self._bound[unit] = c
        # Back faces of closed parts are hidden behind their front faces unless the camera
        # is inside a part (``cull`` above): the same rule as Renderer's, so the same pixels.
        slot = self._slots[c]
        for primitive, chunks in rows.items():
            data = chunks[0] if len(chunks) == 1 else b"".join(chunks)
            entry = slot.entries.get(primitive)
            if entry is None or entry[2] < len(data):
                entry = self._entry(c, slot, primitive, len(data))
            vao, buffer, _, is_closed = entry
            buffer.write(data)
            culling = cull and is_closed
            if culling != self._culling:
                (self.ctx.enable if culling else self.ctx.disable)(moderngl.CULL_FACE)
                self._culling = culling
            vao.render(TRIANGLES, -1, 0, len(data) // ROW_BYTES)
        return cover if region is None else region

    def _entry(self, c: int, slot: _Slot, primitive: str, nbytes: int) -> tuple:
        """Camera c's (vertex array, instance buffer, its size, closed) for a primitive, with
        room for nbytes of instance rows."""
        buffer = slot.buffers.get(primitive)
        if buffer is None:
            buffer = slot.buffers[primitive] = self.ctx.buffer(reserve=max(nbytes, 1024),
                                                               dynamic=True)
            slot.vaos[primitive] = self.ctx.vertex_array(self._program(c, shape(primitive)), [
                (self._mesh(primitive), *VERTEX_FORMAT[ray_cast(primitive)]),
                (buffer, INSTANCE_FORMAT, "i_model", "i_normal", "i_colour"),
            ])
        elif buffer.size < nbytes:
            buffer.orphan(2 * nbytes)
        entry = slot.entries[primitive] = (slot.vaos[primitive], buffer, buffer.size,
                                           closed(primitive))
        return entry

    def _program(self, c: int, kind: str | None) -> moderngl.Program:
        """Camera c's program for a kind of shape (None: meshes), its uniforms set."""
        found = self._programs[c].get(kind)
        if found is None:
            camera, settings = self.cameras[c], self._settings
            found = self._programs[c][kind] = program(self.ctx, "terms.vert", "terms.frag", kind,
                                                      self._prelude)
            self._write(found, self._noise[c])
            found["background"].value = tuple(float(x) for x in settings.background)
            found["observed"].value = self._unit[c]
            found["view"].write(_column_major(camera.w2c))
            found["projection"].write(_column_major(FLIP_Y @ camera.projection()))
            found["ray_depth"].value = camera.depth_type == "ray"
            found["depth_max"].value = float(camera.depth_max)
            if kind is not None:
                found["intrinsics"].value = (camera.fx, camera.fy, camera.cx, camera.cy)
                found["near"].value = float(camera.near)
        return found

    def _mesh(self, primitive: str) -> moderngl.Buffer:
        vbo = self._meshes.get(primitive)
        if vbo is None:
            try:
                vertices = flat_vertices(primitive)
            except (KeyError, ValueError) as error:
                raise RenderError(f"cannot draw the primitive {primitive!r}: {error}")
            vbo = self._meshes[primitive] = self.ctx.buffer(vertices.tobytes())
        return vbo

    def _target(self, c: int) -> moderngl.Framebuffer:
        return self._targets[c][0]

    def _make_target(self, camera: Camera) -> tuple:
        size = (camera.width, camera.height)
        terms = self.ctx.texture(size, 2, dtype="f4")
        visibility = self.ctx.depth_renderbuffer(size)
        return self.ctx.framebuffer([terms], visibility), (terms, visibility)


def _window(rect: Rect) -> tuple[int, int, int, int]:
    """A rectangle of an image (rows r0..r1, columns c0..c1) in window coordinates. With the
    projection's y flip, window row = image row."""
    r0, r1, c0, c1 = rect
    return (c0, r0, c1 - c0, r1 - r0)
