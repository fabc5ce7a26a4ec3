"""Rasterising parts into RGB and metric depth images with OpenGL.

Each primitive's unit mesh lives on the GPU once; a part is drawn as that mesh under its own
matrix and colour, so a new hypothesis costs a few uniform writes, not a mesh upload. Images come
back as float32 arrays in the camera's conventions (see ``sppl.camera``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib import resources

import moderngl
import numpy as np

from ..camera import Camera
from ..errors import RenderError
from ..geometry import MESH_PREFIX, PRIMITIVES, Part, unit_mesh
from ..model import RenderSettings
from .bounds import closed, contains
from .context import gl_context

# GL's window origin is the bottom-left corner and images' is the top-left: flipping y in clip
# space makes GL's first row the image's top row, so the read-back is already in image order.
FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])


def _shader(name: str) -> str:
    return resources.files(__package__).joinpath("shaders", name).read_text(encoding="utf-8")


def _column_major(matrix: np.ndarray) -> bytes:
    """GLSL matrices are column-major; numpy's are row-major."""
    return np.asarray(matrix, dtype="f4").tobytes(order="F")


def flat_vertices(primitive: str) -> np.ndarray:
    """Non-indexed triangles of a unit mesh, as (3F, 6) rows of position and face normal.

    Shared vertices would average their normals and smooth the box's edges away; repeating each
    vertex per face keeps every face flat.
    """
    mesh = unit_mesh(primitive)
    positions = mesh.triangles.reshape(-1, 3)
    normals = np.repeat(mesh.face_normals, 3, axis=0)
    return np.hstack([positions, normals]).astype("f4")


@dataclass
class _Target:
    """The framebuffers of one image size, kept for the renderer's lifetime."""

    colour: moderngl.Texture  # RGBA32F: shaded colour, unclamped and unquantised
    depth: moderngl.Texture  # R32F: metric depth written by the fragment shader
    visibility: moderngl.Renderbuffer  # the usual depth buffer, only for the depth test
    scene: moderngl.Framebuffer
    # A framebuffer clear writes the same value to every colour attachment, but the colour and
    # depth images have different background values, so each is cleared through its own.
    clear_colour: moderngl.Framebuffer
    clear_depth: moderngl.Framebuffer

    def release(self) -> None:
        for obj in (self.scene, self.clear_colour, self.clear_depth):
            obj.release()
        for obj in (self.colour, self.depth, self.visibility):
            obj.release()


class Renderer:
    """Draws lists of parts as seen by cameras, on the process's GL context."""

    def __init__(self, render_settings: RenderSettings | None = None) -> None:
        self.settings = render_settings or RenderSettings()
        light = np.asarray(self.settings.light, dtype=float)
        if not np.all(np.isfinite(light)) or np.linalg.norm(light) == 0.0:
            raise RenderError(f"the light direction {tuple(light)} is not a nonzero vector")
        self.ctx = gl_context()
        try:
            self.program = self.ctx.program(
                vertex_shader=_shader("scene.vert"), fragment_shader=_shader("scene.frag")
            )
        except moderngl.Error as error:
            raise RenderError(f"the scene shaders did not compile on this GL driver: {error}")
        self.program["light"].value = tuple(light / np.linalg.norm(light))
        self.program["ambient"].value = float(self.settings.ambient)
        # Looked up once, so that a frame only writes through them.
        self._model = self.program["model"]
        self._normal_matrix = self.program["normal_matrix"]
        self._colour = self.program["colour"]
        self._view = self.program["view"]
        self._projection = self.program["projection"]
        self._ray_depth = self.program["ray_depth"]
        self._depth_max = self.program["depth_max"]
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._vaos: dict[str, moderngl.VertexArray] = {}
        for primitive in PRIMITIVES:
            buffer = self.ctx.buffer(flat_vertices(primitive).tobytes())
            self._buffers[primitive] = buffer
            self._vaos[primitive] = self.ctx.vertex_array(
                self.program, [(buffer, "3f 3f", "in_position", "in_normal")]
            )
        self._targets: dict[tuple[int, int], _Target] = {}

    def render(self, parts: Iterable[Part], camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """RGB (H, W, 3) in [0, 1] and depth (H, W) in metres of ``camera.depth_type``."""
        if self.program is None:
            raise RenderError("this renderer has been released")
        target = self._target(camera.width, camera.height)
        background = tuple(float(c) for c in self.settings.background)
        target.clear_colour.clear(*background, 1.0, depth=1.0)
        target.clear_depth.clear(float(camera.depth_max))

        target.scene.use()
        # The context is shared with other users in the process; set every state this pass needs.
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._view.write(_column_major(camera.w2c))
        self._projection.write(_column_major(FLIP_Y @ camera.projection()))
        self._ray_depth.value = camera.depth_type == "ray"
        self._depth_max.value = float(camera.depth_max)
        parts = list(parts)
        # Back faces of closed parts are hidden behind their front faces, so they are not
        # drawn (unless the camera may be inside a part). Drawing them anyway let a few
        # silhouette pixels show a back face's shade. The fast path (pixels.py) follows the
        # same rule, pixel for pixel. The projection's y flip makes front faces clockwise.
        cull = not any(contains(p, camera.position) for p in parts)
        self.ctx.front_face = "cw"
        for part in parts:
            if cull and closed(part.primitive):
                self.ctx.enable(moderngl.CULL_FACE)
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            self._draw(part)
        self.ctx.front_face = "ccw"

        h, w = camera.height, camera.width
        rgb = np.empty((h, w, 3), dtype="f4")
        depth = np.empty((h, w), dtype="f4")
        target.scene.read_into(rgb, components=3, attachment=0, dtype="f4")
        target.scene.read_into(depth, components=1, attachment=1, dtype="f4")
        return rgb, depth

    def render_many(
        self, parts: Iterable[Part], cameras: Sequence[Camera]
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """``render`` for each camera, in order."""
        parts = list(parts)
        return [self.render(parts, camera) for camera in cameras]

    def release(self) -> None:
        """Free this renderer's GL objects (the shared context stays)."""
        for target in self._targets.values():
            target.release()
        for obj in [*self._vaos.values(), *self._buffers.values()]:
            obj.release()
        if self.program is not None:
            self.program.release()
        self._targets, self._vaos, self._buffers, self.program = {}, {}, {}, None

    def _draw(self, part: Part) -> None:
        vao = self._vaos.get(part.primitive)
        if vao is None:
            vao = self._upload(part.primitive)
        linear = np.asarray(part.matrix, dtype=float)[:3, :3]
        try:
            normal_matrix = np.linalg.inv(linear).T
        except np.linalg.LinAlgError:
            return  # a part scaled to zero thickness encloses nothing; the ray caster agrees
        self._model.write(_column_major(part.matrix))
        self._normal_matrix.write(_column_major(normal_matrix))
        self._colour.value = tuple(float(c) for c in part.colour)
        vao.render(moderngl.TRIANGLES)

    def _upload(self, primitive: str) -> moderngl.VertexArray:
        """Upload a mesh the first time a part uses it (meshes loaded from files)."""
        if not primitive.startswith(MESH_PREFIX):
            raise RenderError(
                f"unknown primitive {primitive!r}; expected one of {', '.join(PRIMITIVES)}"
            )
        try:
            vertices = flat_vertices(primitive)
        except ValueError as error:
            raise RenderError(f"cannot load the mesh {primitive[len(MESH_PREFIX):]}: {error}")
        buffer = self.ctx.buffer(vertices.tobytes())
        self._buffers[primitive] = buffer
        self._vaos[primitive] = self.ctx.vertex_array(
            self.program, [(buffer, "3f 3f", "in_position", "in_normal")]
        )
        return self._vaos[primitive]

    def _target(self, width: int, height: int) -> _Target:
        key = (int(width), int(height))
        target = self._targets.get(key)
        if target is None:
            if min(key) < 1 or max(key) > self.ctx.info["GL_MAX_TEXTURE_SIZE"]:
                raise RenderError(f"cannot render a {width}x{height} image on this GL driver")
            colour = self.ctx.texture(key, 4, dtype="f4")
            depth = self.ctx.texture(key, 1, dtype="f4")
            visibility = self.ctx.depth_renderbuffer(key)
            target = _Target(
                colour=colour,
                depth=depth,
                visibility=visibility,
                scene=self.ctx.framebuffer([colour, depth], visibility),
                clear_colour=self.ctx.framebuffer([colour], visibility),
                clear_depth=self.ctx.framebuffer([depth]),
            )
            self._targets[key] = target
        return target
