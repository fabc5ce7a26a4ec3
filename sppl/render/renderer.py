"""Rasterising parts into RGB and metric depth images with OpenGL.

Each primitive's unit mesh lives on the GPU once; a part is drawn as that mesh under its own
matrix and colour, so a new hypothesis costs a few uniform writes, not a mesh upload. Images come
back as float32 arrays in the camera's conventions (see ``sppl.data.camera``).

Round shapes are the exception (``ray_cast``): a tessellated sphere needs a thousand triangles
to look round, and on a software rasteriser the setup of a cone's or a cylinder's hundred or two
costs more than their pixels. Each is drawn as a convex solid around it turned inside out
(``_proxy``), and the fragment shader intersects each pixel's ray with the exact (affinely
posed) sphere, cylinder or cone (``shaders/ray_cast.glsl``), which is both cheaper and exact.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib import resources

import moderngl
import numpy as np
import trimesh

from ..data.camera import Camera
from ..errors import RenderError
from ..model.geometry import MESH_PREFIX, Part, linear_inverse, unit_mesh
from ..model.primitives import find_primitive, get_primitive
from ..model.types import RenderSettings
from .bounds import closed, contains
from .context import claim_state, gl_context
from .lighting import BLOCK_BYTES, block, caster_rows, check_light

# GL's window origin is the bottom-left corner and images' is the top-left: flipping y in clip
# space makes GL's first row the image's top row, so the read-back is already in image order.
FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])


# The uniform-buffer binding point of lighting.glsl's block, in every program.
LIGHTING_BINDING = 0


def ray_cast(primitive: str) -> bool:
    """Whether the fragment shader ray-casts this primitive's exact surface over a proxy
    (its ``Primitive.glsl``), rather than drawing its mesh's triangles."""
    shape = None if primitive.startswith(MESH_PREFIX) else find_primitive(primitive)
    return shape is not None and shape.ray_cast


# The vertex rows' layout as each program reads it: a proxy's normals are not used.
VERTEX_FORMAT = {False: ("3f 3f", "in_position", "in_normal"), True: ("3f 3x4", "in_position")}


def shape(primitive: str) -> str | None:
    """The shape a primitive's program ray-casts, or None for a rasterised mesh."""
    return primitive if ray_cast(primitive) else None


def _shader(name: str, shape: str | None = None, prelude: str = "") -> str:
    """A shader's source; with a ray-cast ``shape``, its variant that ray-casts it."""
    text = resources.files(__package__).joinpath("shaders", name).read_text(encoding="utf-8")
    if not name.endswith((".frag", ".vert")):
        return text
    # Every fragment shader shades with lighting.glsl's block; a ray-cast one hits its shape
    # with ray_cast.glsl's helpers and the shape's own snippet. The prelude (its defines
    # first) goes above them all.
    version, _, body = text.partition("\n")
    extra = _shader("lighting.glsl") if name.endswith(".frag") else ""
    if shape is not None:
        if name.endswith(".frag"):
            extra = f"{_shader('ray_cast.glsl')}\n{get_primitive(shape).glsl}\n{extra}"
        extra = f"#define RAY_CAST\n#define HIT {shape}_hit\n{extra}"
    if prelude:
        extra = f"{prelude}\n{extra}"
    return f"{version}\n{extra}\n{body}"


def program(ctx: moderngl.Context, vertex: str, fragment: str,
            shape: str | None = None, prelude: str = "") -> moderngl.Program:
    """The program of a pair of shaders that draws meshes (``shape`` None) or ray-casts a
    round shape; ``prelude`` is GLSL put at the top of the fragment shader."""
    try:
        made = ctx.program(vertex_shader=_shader(vertex, shape),
                           fragment_shader=_shader(fragment, shape, prelude))
    except moderngl.Error as error:
        raise RenderError(f"the shaders {vertex} and {fragment} did not compile on this GL "
                          f"driver: {error}") from None
    made["Lighting"].binding = LIGHTING_BINDING
    return made


def _column_major(matrix: np.ndarray) -> bytes:
    """GLSL matrices are column-major; numpy's are row-major."""
    return np.asarray(matrix, dtype="f4").tobytes(order="F")


def mesh_vertices(primitive: str) -> np.ndarray:
    """Non-indexed triangles of a unit mesh, as (3F, 6) rows of position and face normal.

    Shared vertices would average their normals and smooth the box's edges away; repeating each
    vertex per face keeps every face flat.
    """
    return _facets(unit_mesh(primitive))


def flat_vertices(primitive: str) -> np.ndarray:
    """What the renderers draw for a primitive: its unit mesh's facets, or for a ray-cast
    primitive the proxy that reaches its pixels."""
    if ray_cast(primitive):
        return _facets(_proxy(primitive))
    return mesh_vertices(primitive)


def _proxy(primitive: str):
    """A convex solid around the unit shape (the shape's ``proxy``, else its bounding box),
    turned inside out: its far faces are the front ones, so that back-face culling keeps
    them, and they cover the shape's pixels even for a camera inside it."""
    shape = get_primitive(primitive)
    mesh = unit_mesh(primitive)
    solid = shape.proxy() if shape.proxy is not None else trimesh.creation.box(bounds=mesh.bounds)
    solid.invert()
    return solid


def _facets(mesh) -> np.ndarray:
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
        check_light(self.settings)
        self.ctx = gl_context()
        self._lighting = self.ctx.buffer(reserve=BLOCK_BYTES, dynamic=True)
        # Programs and meshes are made the first time a part needs them.
        self._programs: dict[str | None, moderngl.Program] = {}
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._vaos: dict[str, moderngl.VertexArray] = {}
        self._targets: dict[tuple[int, int], _Target] = {}
        self._released = False

    def render(self, parts: Iterable[Part], camera: Camera,
               settings: RenderSettings | None = None) -> tuple[np.ndarray, np.ndarray]:
        """RGB (H, W, 3) in [0, 1] and depth (H, W) in metres of ``camera.depth_type``,
        lit as ``settings`` say (default: the renderer's own; another's lighting may differ,
        as a hypothesis's latent lighting does)."""
        if self._released:
            raise RenderError("this renderer has been released")
        settings = settings or self.settings
        target = self._target(camera.width, camera.height)
        # The context is shared with other users in the process; set every state this pass
        # needs, the scissor test first (left on, it would restrict the clears).
        claim_state(self)
        self.ctx.scissor = None
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        background = tuple(float(c) * k for c, k in zip(settings.background, settings.balance))
        target.clear_colour.clear(*background, 1.0, depth=1.0)
        target.clear_depth.clear(float(camera.depth_max))

        target.scene.use()
        view = _column_major(camera.w2c)
        projection = _column_major(FLIP_Y @ camera.projection())
        parts = list(parts)
        check_light(settings)
        self._lighting.write(block(settings, caster_rows(parts) if settings.shadows else b""))
        self._lighting.bind_to_uniform_block(LIGHTING_BINDING)
        for kind in {shape(p.primitive) for p in parts}:
            program = self._program(kind)
            program["view"].write(view)
            program["projection"].write(projection)
            program["ray_depth"].value = camera.depth_type == "ray"
            program["depth_max"].value = float(camera.depth_max)
            if kind is not None:
                program["intrinsics"].value = (camera.fx, camera.fy, camera.cx, camera.cy)
                program["near"].value = float(camera.near)
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
        for obj in [*self._vaos.values(), *self._buffers.values(), *self._programs.values(),
                    self._lighting]:
            obj.release()
        self._targets, self._vaos, self._buffers, self._programs = {}, {}, {}, {}
        self._released = True

    def _draw(self, part: Part) -> None:
        vao = self._vaos.get(part.primitive)
        if vao is None:
            vao = self._upload(part.primitive)
        inverse = linear_inverse(np.asarray(part.matrix, dtype=float))
        if inverse is None:
            return  # a part scaled to zero thickness encloses nothing; the ray caster agrees
        program = self._programs[shape(part.primitive)]
        program["model"].write(_column_major(part.matrix))
        # The normal matrix is the inverse's transpose: column-major, the inverse row by row.
        program["normal_matrix"].write(np.array(inverse, dtype="f4").tobytes())
        program["colour"].value = tuple(float(c) for c in part.colour)
        vao.render(moderngl.TRIANGLES)

    def _upload(self, primitive: str) -> moderngl.VertexArray:
        """Upload a primitive's mesh (a mesh file's the first time a part uses it)."""
        try:
            vertices = flat_vertices(primitive)
        except KeyError as error:
            raise RenderError(error.args[0]) from None
        except ValueError as error:
            raise RenderError(f"cannot load the mesh {primitive[len(MESH_PREFIX):]}: {error}")
        buffer = self.ctx.buffer(vertices.tobytes())
        self._buffers[primitive] = buffer
        self._vaos[primitive] = self.ctx.vertex_array(
            self._program(shape(primitive)), [(buffer, *VERTEX_FORMAT[ray_cast(primitive)])]
        )
        return self._vaos[primitive]

    def _program(self, kind: str | None) -> moderngl.Program:
        found = self._programs.get(kind)
        if found is None:
            found = self._programs[kind] = program(self.ctx, "scene.vert", "scene.frag", kind)
        return found

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
