"""The thesis's renderer, for comparison: Panda3D offscreen through EGL, reading colour and depth
back to numpy and scoring there (Gaussian statistics of every pixel, as the reference path).

Optional: ``pip install panda3d`` (or the ``bench`` extra). ``available()`` says why not when
it cannot be used. It draws sppl's unit meshes (spheres as their 1280-triangle icosphere,
which sppl ray-casts instead), with Panda3D's own lighting.

Panda3D makes its own GL context current on the thread that renders, which would redirect
moderngl's calls, so it runs in a worker process of its own (``Worker``).
"""

from __future__ import annotations

import numpy as np

from sppl.render.renderer import mesh_vertices

_WHY_NOT: str | None = None
try:
    from panda3d.core import loadPrcFileData

    loadPrcFileData("", "load-display p3headlessgl\nwindow-type offscreen\n"
                        "audio-library-name null\nsync-video false\nnotify-level fatal")
    from panda3d.core import (
        AmbientLight,
        DirectionalLight,
        FrameBufferProperties,
        Geom,
        GeomNode,
        GeomTriangles,
        GeomVertexData,
        GeomVertexFormat,
        GraphicsEngine,
        GraphicsOutput,
        GraphicsPipe,
        GraphicsPipeSelection,
        LMatrix4f,
        MatrixLens,
        NodePath,
        Texture,
        WindowProperties,
    )
    from panda3d.core import Camera as PandaCamera
except ImportError as error:  # pragma: no cover - depends on the machine
    _WHY_NOT = f"panda3d is not installed ({error}); `pip install panda3d` adds it"

# Panda3D's camera looks along +y with z up; sppl's (OpenGL's) along -z with y up.
_GL_FROM_PANDA = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])


def available() -> str | None:
    """None when the Panda3D path can run, else why it cannot."""
    return _WHY_NOT


def _mat(m: np.ndarray) -> LMatrix4f:
    """Panda3D multiplies row vectors: its matrices are the transposes of ours."""
    return LMatrix4f(*np.asarray(m, dtype=float).T.ravel())


def _geom(primitive: str) -> GeomNode:
    vertices = mesh_vertices(primitive)
    data = GeomVertexData(primitive, GeomVertexFormat.get_v3n3(), Geom.UH_static)
    data.unclean_set_num_rows(len(vertices))
    memoryview(data.modify_array(0)).cast("B").cast("f")[:] = vertices.ravel()
    triangles = GeomTriangles(Geom.UH_static)
    triangles.add_next_vertices(len(vertices))
    geom = Geom(data)
    geom.add_primitive(triangles)
    node = GeomNode(primitive)
    node.add_geom(geom)
    return node


class PandaScorer:
    """Renders parts for several cameras in one Panda3D frame and scores them in numpy."""

    def __init__(self, settings, cameras, observed) -> None:
        engine = self.engine = GraphicsEngine.get_global_ptr()
        pipe = GraphicsPipeSelection.get_global_ptr().make_module_pipe("p3headlessgl")
        if pipe is None:
            raise RuntimeError("Panda3D found no headless GL pipe")
        self.root = NodePath("render")
        light = np.asarray(settings.light, dtype=float)
        sun = self.root.attach_new_node(DirectionalLight("sun"))
        sun.look_at(*(-light))
        ambient = self.root.attach_new_node(AmbientLight("ambient"))
        ambient.node().set_color((settings.ambient,) * 3 + (1.0,))
        self.root.set_light(sun)
        self.root.set_light(ambient)
        self.background = tuple(settings.background) + (1.0,)
        self.cameras, self.observed = list(cameras), list(observed)
        self.outputs = []
        for i, cam in enumerate(self.cameras):
            fb = FrameBufferProperties()
            fb.set_rgba_bits(8, 8, 8, 8)
            fb.set_depth_bits(24)
            buffer = engine.make_output(pipe, f"camera{i}", 0, fb,
                                        WindowProperties.size(cam.width, cam.height),
                                        GraphicsPipe.BF_refuse_window, None, None)
            if buffer is None:
                raise RuntimeError("Panda3D could not open an offscreen buffer")
            buffer.set_clear_color(self.background)
            colour, depth = Texture(), Texture()
            depth.set_format(Texture.F_depth_component32)
            buffer.add_render_texture(colour, GraphicsOutput.RTM_copy_ram,
                                      GraphicsOutput.RTP_color)
            buffer.add_render_texture(depth, GraphicsOutput.RTM_copy_ram,
                                      GraphicsOutput.RTP_depth)
            lens = MatrixLens()
            lens.set_user_mat(_mat(cam.projection() @ _GL_FROM_PANDA))
            node = PandaCamera(f"camera{i}", lens)
            camera_path = self.root.attach_new_node(node)
            camera_path.set_mat(_mat(cam.c2w @ np.linalg.inv(_GL_FROM_PANDA)))
            region = buffer.make_display_region()
            region.set_camera(camera_path)
            self.outputs.append((buffer, colour, depth))
        self.geoms = {}
        self.nodes: list[NodePath] = []

    def close(self) -> None:
        """Remove this scorer's buffers: the engine renders every open output each frame."""
        for buffer, _, _ in self.outputs:
            self.engine.remove_window(buffer)
        self.outputs = []
        self.root.remove_node()

    def statistics(self, parts) -> list[tuple[float, float]]:
        """Per camera, the Gaussian statistics (sum of squared residuals) of RGB and depth."""
        while len(self.nodes) < len(parts):
            self.nodes.append(self.root.attach_new_node("part"))
        for node, part in zip(self.nodes, parts):
            geom = self.geoms.get(part.primitive)
            if geom is None:
                geom = self.geoms[part.primitive] = _geom(part.primitive)
            if node.get_num_children() == 0 or node.get_child(0).node() is not geom:
                node.get_children().detach()
                node.attach_new_node(geom)
            node.set_mat(_mat(part.matrix))
            node.set_color(*part.colour, 1.0)
            node.show()
        for node in self.nodes[len(parts):]:
            node.hide()
        self.engine.render_frame()
        out = []
        for cam, (rgb_obs, depth_obs), (_, colour, depth) in zip(
            self.cameras, self.observed, self.outputs
        ):
            h, w = cam.height, cam.width
            bgra = np.frombuffer(colour.get_ram_image(), np.uint8).reshape(h, w, 4)[::-1]
            rgb = bgra[..., 2::-1].astype(np.float32) / 255.0
            window = np.frombuffer(depth.get_ram_image(), np.float32).reshape(h, w)[::-1]
            n = cam.near
            f = max(cam.depth_max, n) * 2.0 + 1.0
            z = 2.0 * f * n / ((f + n) - (2.0 * window - 1.0) * (f - n))
            z = np.minimum(z, cam.depth_max)
            r = (rgb_obs - rgb).ravel() if rgb_obs is not None else np.zeros(0, np.float32)
            valid = np.isfinite(depth_obs) if depth_obs is not None else None
            d = (depth_obs[valid] - z[valid]) if valid is not None else np.zeros(0, np.float32)
            out.append((float(r @ r), float(d @ d)))
        return out


def _serve(conn) -> None:
    """The worker's loop: ("setup", settings, cameras, observed), ("rate", parts list, seconds)."""
    import time

    scorer = None
    while True:
        message = conn.recv()
        if message[0] == "setup":
            if scorer is not None:
                scorer.close()
            scorer = PandaScorer(*message[1:])
            conn.send(None)
        elif message[0] == "rate":
            hypotheses, seconds = message[1], message[2]
            for parts in hypotheses[:3]:
                scorer.statistics(parts)
            calls, start = 0, time.perf_counter()
            while True:
                for parts in hypotheses:
                    scorer.statistics(parts)
                calls += len(hypotheses)
                elapsed = time.perf_counter() - start
                if elapsed >= seconds:
                    break
            conn.send(calls / elapsed)
        else:
            return


class Worker:
    """A process that holds a PandaScorer and measures its evaluations per second.

    ``lp_threads``, when given, is the worker's LP_NUM_THREADS: how many rasteriser threads
    Mesa's llvmpipe runs (0: rasterise on the calling thread, as sppl does by default). None
    leaves the environment as it is (llvmpipe's default: a thread per core)."""

    def __init__(self, lp_threads: str | None = None) -> None:
        import multiprocessing
        import os

        ctx = multiprocessing.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(child,), daemon=True)
        # A spawned process starts with the environment as it is now.
        before = os.environ.get("LP_NUM_THREADS")
        if lp_threads is not None:
            os.environ["LP_NUM_THREADS"] = lp_threads
        try:
            self.process.start()
        finally:
            if before is None:
                os.environ.pop("LP_NUM_THREADS", None)
            else:
                os.environ["LP_NUM_THREADS"] = before

    def setup(self, settings, cameras, observed) -> None:
        self.conn.send(("setup", settings, cameras, observed))
        self.conn.recv()

    def rate(self, hypotheses, seconds: float) -> float:
        self.conn.send(("rate", hypotheses, seconds))
        return self.conn.recv()

    def close(self) -> None:
        self.conn.send(("stop",))
        self.process.join(timeout=10)
