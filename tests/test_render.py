"""The OpenGL renderer against geometry computed by hand and against the numpy ray caster.

Hand-computed checks run on both renderers, so the oracle is itself checked before the GL path
is compared with it on random scenes.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from scipy import ndimage

from sppl.data.camera import Camera, look_at
from sppl.errors import RenderError
from sppl.model.geometry import PRIMITIVES, Part, rotation, scaling, translation
from sppl.model.types import RenderSettings
from sppl.render import Renderer, raycast
from sppl.render import context as context_module

SETTINGS = RenderSettings(background=(0.1, 0.2, 0.3), ambient=0.35, light=(0.4, -0.3, 1.0))
RED = (0.9, 0.1, 0.1)


@pytest.fixture(scope="module")
def gl_renderer(require_gl):
    renderer = Renderer(SETTINGS)
    yield renderer
    renderer.release()


@pytest.fixture(params=["gl", "raycast"])
def renderer_for(request):
    """A function settings -> render function (parts, camera) -> (rgb, depth), per renderer."""
    if request.param == "raycast":
        yield lambda settings=SETTINGS: lambda parts, camera: raycast(parts, camera, settings)
        return
    request.getfixturevalue("gl_renderer")  # skips (or fails on CI) without a GL context
    made = []

    def make(settings=SETTINGS):
        made.append(Renderer(settings))
        return made[-1].render

    yield make
    for renderer in made:
        renderer.release()


@pytest.fixture
def render(renderer_for):
    return renderer_for(SETTINGS)


def top_down(width=64, height=64, fx=100.0, fy=100.0, cx=None, cy=None, **kwargs) -> Camera:
    """A camera 5 m above the origin looking straight down, image up = world +y."""
    return Camera(
        "top",
        width,
        height,
        fx,
        fy,
        width / 2 if cx is None else cx,
        height / 2 if cy is None else cy,
        look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
        **kwargs,
    )


def unit_box(colour=RED) -> Part:
    return Part("box", np.eye(4), colour)


def pixel_bounds(depth: np.ndarray, depth_max: float) -> tuple[int, int, int, int]:
    """(first row, last row, first column, last column) of the pixels that hit something."""
    rows, cols = np.nonzero(depth < depth_max)
    return rows.min(), rows.max(), cols.min(), cols.max()


def covered(v0, v1, u0, u1) -> tuple[float, float, float, float]:
    """Roughly the pixel_bounds of a region spanning [u0, u1] x [v0, v1] continuously: the
    pixels whose centres (index + 0.5) lie inside, give or take one at each edge."""
    return v0 - 0.5, v1 - 0.5, u0 - 0.5, u1 - 0.5


# --- geometry computed by hand ---------------------------------------------------------------


def test_box_top_face_size_depth_and_shade(render):
    camera = top_down()
    rgb, depth = render([unit_box()], camera)
    assert rgb.shape == (64, 64, 3) and depth.shape == (64, 64)
    assert rgb.dtype == np.float32 and depth.dtype == np.float32
    # The top face (z = 1) is 4 m away: 1 m spans 100 * 1 / 4 = 25 px, centred on pixel 32,
    # so from 19.5 to 44.5 in continuous coordinates. The sides are hidden beneath it.
    bounds = pixel_bounds(depth, camera.depth_max)
    assert np.allclose(bounds, covered(19.5, 44.5, 19.5, 44.5), atol=1)
    assert depth[32, 32] == pytest.approx(4.0, abs=1e-4)
    light = np.asarray(SETTINGS.light) / np.linalg.norm(SETTINGS.light)
    shade = SETTINGS.ambient + (1 - SETTINGS.ambient) * light[2]
    assert np.allclose(rgb[32, 32], np.asarray(RED) * shade, atol=1e-5)


def test_background_pixels(render):
    camera = top_down(depth_max=7.5)
    rgb, depth = render([unit_box()], camera)
    for corner in [(0, 0), (0, -1), (-1, 0), (-1, -1)]:
        assert depth[corner] == camera.depth_max
        assert np.allclose(rgb[corner], SETTINGS.background)


def test_nothing_to_draw_gives_only_background(render):
    camera = top_down(width=20, height=10)
    rgb, depth = render([], camera)
    assert np.all(depth == camera.depth_max)
    assert np.allclose(rgb, SETTINGS.background)


def test_depth_is_clipped_at_depth_max(render):
    camera = top_down(depth_max=3.0)
    rgb, depth = render([unit_box()], camera)
    assert depth[32, 32] == pytest.approx(3.0)
    assert not np.allclose(rgb[32, 32], SETTINGS.background)  # still drawn, only clipped


def test_ray_depth_is_z_depth_over_cosine(render):
    camera = top_down(depth_type="ray")
    _, depth = render([unit_box()], camera)
    for i, j in [(32, 32), (22, 40), (41, 21), (20, 20)]:
        x = (j + 0.5 - camera.cx) / camera.fx
        y = (i + 0.5 - camera.cy) / camera.fy
        cosine = 1.0 / math.sqrt(1.0 + x * x + y * y)
        assert depth[i, j] == pytest.approx(4.0 / cosine, abs=1e-4)


def test_sphere_resting_on_the_ground_has_its_top_at_twice_its_radius(render):
    radius = 0.7
    camera = top_down(cx=32.5, cy=32.5)  # a pixel's ray straight down the axis
    _, depth = render([Part("sphere", scaling(radius, radius, radius), RED)], camera)
    assert 5.0 - depth[32, 32] == pytest.approx(2 * radius, abs=1e-3)


def test_off_centre_principal_point_shifts_the_image(render):
    # A small box whose top face is a square facing the camera, so its pixels are centred on
    # the projection of the face's centre.
    part = Part("box", translation(0.3, -0.2, 0.0) @ scaling(0.4, 0.4, 1.0), RED)
    top_centre = np.array([[0.3, -0.2, 1.0]])
    for cx, cy in [(32.0, 32.0), (20.0, 40.0), (45.5, 25.0)]:
        camera = top_down(cx=cx, cy=cy)
        _, depth = render([part], camera)
        rows, cols = np.nonzero(depth < camera.depth_max)
        uv, _ = camera.project(top_centre)
        assert cols.mean() + 0.5 == pytest.approx(uv[0, 0], abs=0.5)
        assert rows.mean() + 0.5 == pytest.approx(uv[0, 1], abs=0.5)


def test_non_square_image_with_unequal_focal_lengths(render):
    camera = top_down(width=80, height=48, fx=120.0, fy=80.0, cx=44.0, cy=22.0)
    rgb, depth = render([unit_box()], camera)
    assert rgb.shape == (48, 80, 3) and depth.shape == (48, 80)
    corners = np.array([[x, y, 1.0] for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    uv, _ = camera.project(corners)
    u0, u1, v0, v1 = uv[:, 0].min(), uv[:, 0].max(), uv[:, 1].min(), uv[:, 1].max()
    assert (u1 - u0, v1 - v0) == pytest.approx((30.0, 20.0))  # 1 m at 4 m, fx = 120, fy = 80
    assert np.allclose(pixel_bounds(depth, camera.depth_max), covered(v0, v1, u0, u1), atol=1)


# --- shading ---------------------------------------------------------------------------------


def test_faces_towards_the_light_are_brighter_and_faces_away_get_only_ambient(renderer_for):
    white = (1.0, 1.0, 1.0)
    eye = (4.0, -3.0, 2.5)
    camera = Camera("oblique", 64, 64, 60.0, 60.0, 32.0, 32.0, look_at(eye, (0.0, 0.0, 0.5)))
    face_centres = {"+x": (0.5, 0.0, 0.5), "-y": (0.0, -0.5, 0.5), "top": (0.0, 0.0, 1.0)}
    uv, _ = camera.project(np.array(list(face_centres.values())))
    pixels = {name: (int(v), int(u)) for name, (u, v) in zip(face_centres, uv)}

    settings = RenderSettings(background=(0, 0, 0), ambient=0.3, light=(1.0, 0.0, 0.0))
    rgb, _ = renderer_for(settings)([Part("box", np.eye(4), white)], camera)
    lit, side, top = (rgb[pixels[name]] for name in ("+x", "-y", "top"))
    assert np.allclose(lit, 1.0, atol=1e-5)  # facing the light
    assert np.allclose(side, 0.3, atol=1e-5) and np.allclose(top, 0.3, atol=1e-5)  # edge-on

    settings = RenderSettings(background=(0, 0, 0), ambient=0.3, light=(-1.0, 0.0, 0.0))
    rgb, _ = renderer_for(settings)([Part("box", np.eye(4), white)], camera)
    assert np.allclose(rgb[pixels["+x"]], 0.3, atol=1e-5)  # turned away: ambient only


def test_normals_follow_non_uniform_scale(renderer_for):
    # A box rotated and then stretched: its top face's normal is the inverse-transpose of the
    # linear map applied to +z (here nearly vertical), not the map itself (here 74 degrees off).
    linear = scaling(3.0, 1.0, 0.5) @ rotation((0.0, 1.0, 0.0), math.radians(30))
    part = Part("box", linear, (1.0, 1.0, 1.0))
    normal = np.linalg.inv(linear[:3, :3]).T @ (0.0, 0.0, 1.0)
    top_centre = linear[:3, :3] @ (0.0, 0.0, 1.0)
    above = np.eye(4)
    above[:3, 3] = top_centre + (0.0, 0.0, 5.0)
    camera = Camera("above", 64, 64, 100.0, 100.0, 32.5, 32.5, above)  # looks down -z
    settings = RenderSettings(background=(0, 0, 0), ambient=0.0, light=(0.0, 0.0, 1.0))
    rgb, _ = renderer_for(settings)([part], camera)
    assert rgb[32, 32, 0] == pytest.approx(normal[2] / np.linalg.norm(normal), abs=1e-4)


# --- the GL renderer against the ray caster --------------------------------------------------


def random_scene(rng: np.random.Generator) -> list[Part]:
    parts = []
    for _ in range(rng.integers(2, 5)):
        axis = rng.normal(size=3)
        matrix = (
            translation(*rng.uniform(-1.5, 1.5, 2), rng.uniform(-0.3, 0.5))
            @ rotation(axis / np.linalg.norm(axis), rng.uniform(0, 2 * np.pi))
            @ scaling(*rng.uniform(0.3, 1.2, 3))
        )
        colour = tuple(rng.uniform(0.2, 1.0, 3))
        parts.append(Part(PRIMITIVES[rng.integers(len(PRIMITIVES))], matrix, colour))
    return parts


def random_camera(rng: np.random.Generator, width: int, height: int, depth_type: str) -> Camera:
    eye = rng.normal(size=3)
    eye[2] = abs(eye[2]) + 0.5
    eye *= 5.0 / np.linalg.norm(eye)
    return Camera(
        "random",
        width,
        height,
        rng.uniform(30, 50),
        rng.uniform(30, 50),
        width / 2 + rng.uniform(-3, 3),
        height / 2 + rng.uniform(-3, 3),
        look_at(eye, (0.0, 0.0, 0.3)),
        depth_max=8.0,
        depth_type=depth_type,
    )


@pytest.mark.parametrize(
    "seed, size, depth_type",
    [(0, (32, 32), "z"), (1, (48, 40), "ray"), (2, (48, 40), "z"), (3, (32, 32), "ray"),
     (4, (48, 40), "z"), (5, (32, 32), "z")],
)
def test_gl_matches_the_ray_caster_on_random_scenes(gl_renderer, seed, size, depth_type):
    rng = np.random.default_rng(seed)
    parts = random_scene(rng)
    camera = random_camera(rng, *size, depth_type)
    rgb, depth = gl_renderer.render(parts, camera)
    rgb_ref, depth_ref = raycast(parts, camera, SETTINGS)

    hit, hit_ref = depth < camera.depth_max, depth_ref < camera.depth_max
    assert hit_ref.any(), "the scene should be in view"
    # Pixel centres within the rasteriser's sub-pixel precision of an edge may go either way.
    assert np.mean(hit != hit_ref) <= 0.02
    assert np.allclose(rgb[~hit], SETTINGS.background)

    # Depth must agree exactly except where one object occludes another, whose edges the
    # rasteriser may place a sub-pixel step differently (the background does not count).
    both = hit & hit_ref
    highest = ndimage.maximum_filter(np.where(hit_ref, depth_ref, -np.inf), 3)
    lowest = ndimage.minimum_filter(np.where(hit_ref, depth_ref, np.inf), 3)
    smooth = both & (highest - lowest < 0.5)
    assert smooth.sum() > 0.5 * both.sum()
    assert np.abs(depth - depth_ref)[smooth].max() <= 1e-3

    # Colours change at every edge between faces too (a box's, a cylinder's or cone's rim), so
    # a pixel centre on one may take either face's colour; all the others must agree.
    colour_error = np.abs(rgb - rgb_ref).max(axis=-1)[both]
    assert np.mean(colour_error > 0.02) <= 0.01


# --- spheres, cylinders and cones, which both renderers intersect exactly --------------------


def test_sphere_silhouette_is_a_circle_of_the_projected_radius(render):
    """Seen from straight above, a sphere of radius r at distance D covers the pixels whose
    rays pass within r of its centre: a disc of radius f r / sqrt(D^2 - r^2) pixels."""
    r, f = 0.5, 100.0
    camera = top_down(fx=f, fy=f)
    rgb, depth = render([Part("sphere", np.diag([r, r, r, 1.0]), RED)], camera)
    centre_distance = 5.0 - r
    radius_px = f * r / math.sqrt(centre_distance**2 - r**2)
    j, i = np.meshgrid(np.arange(64) + 0.5, np.arange(64) + 0.5)
    inside = np.hypot(j - 32, i - 32) < radius_px
    assert np.array_equal(depth < camera.depth_max, inside)
    # The top of the sphere is 2r above the ground, right below the camera.
    assert depth[31:33, 31:33] == pytest.approx(5.0 - 2 * r, abs=1e-3)


def test_cylinder_and_cone_seen_from_above(render):
    """From straight above, a cylinder of radius r and height h covers a disc of radius
    f r / (D - h) pixels (its top cap, D the camera's height) at depth D - h; a cone covers its
    base's disc, f r / D pixels, and its apex is h nearer than the ground, right below."""
    r, h, f = 0.5, 0.8, 100.0
    camera = top_down(fx=f, fy=f)
    j, i = np.meshgrid(np.arange(64) + 0.5, np.arange(64) + 0.5)
    from_axis = np.hypot(j - 32, i - 32)
    _, depth = render([Part("cylinder", scaling(r, r, h), RED)], camera)
    assert np.array_equal(depth < camera.depth_max, from_axis < f * r / (5.0 - h))
    assert np.allclose(depth[depth < camera.depth_max], 5.0 - h, atol=1e-4)
    _, depth = render([Part("cone", scaling(r, r, h), RED)], camera)
    assert np.array_equal(depth < camera.depth_max, from_axis < f * r / 5.0)
    # On the cone's side a point rho from the axis is h (1 - rho / r) high: a pixel k pixels
    # from the axis sees it at z-depth D - h (1 - rho / r), with rho = k (z-depth) / f.
    for i, j in [(31, 31), (32, 38), (26, 32)]:
        rho = from_axis[i, j] * depth[i, j] / f
        assert 5.0 - depth[i, j] == pytest.approx(h * (1.0 - rho / r), abs=1e-4)


def ray_cast_mismatches(renderer, primitive: str, depth_type: str, seed: int) -> int:
    """Posed parts of a ray-cast shape (rotated, non-uniformly scaled) with a box among them,
    drawn by the GL renderer and by the ray caster in double precision: asserts that they
    agree on depth, and returns the number of pixels whose coverage or shade differs."""
    rng = np.random.default_rng(seed)
    mismatched = 0
    for _ in range(12):
        axis = rng.normal(size=3)
        pose = (translation(*rng.uniform(-1, 1, 2), rng.uniform(-0.3, 0.5))
                @ rotation(axis / np.linalg.norm(axis), rng.uniform(0, 2 * np.pi))
                @ scaling(*rng.uniform(0.3, 1.2, 3)))
        parts = [Part(primitive, pose, tuple(rng.uniform(0.2, 1.0, 3))),
                 Part("box", translation(0.6, 0.4, 0.0) @ scaling(0.5, 0.5, 0.5), RED)]
        camera = random_camera(rng, 48, 40, depth_type)
        rgb, depth = renderer.render(parts, camera)
        rgb_ref, depth_ref = raycast(parts, camera, SETTINGS)
        hit, hit_ref = depth < camera.depth_max, depth_ref < camera.depth_max
        assert hit_ref.any()
        mismatched += int(np.sum(hit != hit_ref))
        both = hit & hit_ref
        # Where the box and the round shape meet, the rasterised box edge may fall either way:
        # a pixel or two, whose neighbours are left out of the comparison below.
        apart = np.abs(depth_ref - depth) > 1e-3
        assert np.sum(apart & both) <= 2
        edge = ndimage.binary_dilation(apart, iterations=1)
        assert np.abs(depth - depth_ref)[both & ~edge].max() <= 1e-4
        # A ray through a cylinder's or cone's rim may meet the side in one precision and the
        # cap in the other: the same depth, another shade. Only a grazing ray may.
        shade = np.abs(rgb - rgb_ref).max(axis=-1)[both & ~edge]
        mismatched += int(np.sum(shade > 1e-4))
    return mismatched


@pytest.mark.parametrize("primitive", ["sphere", "cylinder", "cone"])
@pytest.mark.parametrize("depth_type", ["z", "ray"])
def test_round_shapes_match_the_ray_caster_pixel_for_pixel(gl_renderer, primitive, depth_type):
    """The GL renderer's per-pixel intersection and the ray caster's double-precision one
    agree on every pixel's coverage, depth and shade."""
    # Of 12 x 1920 pixels: only a ray grazing a silhouette may differ.
    assert ray_cast_mismatches(gl_renderer, primitive, depth_type, seed=7) <= 2


def test_a_camera_inside_a_sphere_sees_its_far_side(renderer_for):
    """As with a mesh's back faces: from inside, every ray meets the sphere's inside."""
    part = Part("sphere", np.diag([2.0, 2.0, 2.0, 1.0]), RED)
    inside = np.eye(4)
    inside[:3, 3] = (0.0, 0.0, 2.0)  # the centre, looking down
    camera = Camera("in", 16, 16, 10.0, 10.0, 8.0, 8.0, inside, depth_max=8.0, depth_type="ray")
    _, depth = renderer_for(SETTINGS)([part], camera)
    assert depth == pytest.approx(np.full((16, 16), 2.0), abs=1e-4)


def test_a_camera_inside_a_cylinder_sees_its_far_cap_and_side(renderer_for):
    """Looking down from inside a cylinder of radius 2, 3 m above its bottom cap: the rays
    within 2 m of the axis at the cap's depth end there, the others on the side."""
    part = Part("cylinder", scaling(2.0, 2.0, 4.0), RED)
    inside = np.eye(4)
    inside[:3, 3] = (0.0, 0.0, 3.0)
    camera = Camera("in", 16, 16, 4.0, 4.0, 8.0, 8.0, inside, depth_max=8.0)
    _, depth = renderer_for(SETTINGS)([part], camera)
    j, i = np.meshgrid(np.arange(16) + 0.5 - 8.0, np.arange(16) + 0.5 - 8.0)
    off_axis = np.hypot(j, i) / 4.0  # metres from the axis per metre of z-depth
    on_cap = 3.0 * off_axis < 2.0
    assert depth[on_cap] == pytest.approx(np.full(on_cap.sum(), 3.0), abs=1e-4)
    assert depth[~on_cap] == pytest.approx(2.0 / off_axis[~on_cap], abs=1e-4)


# --- the renderer's bookkeeping --------------------------------------------------------------


def test_render_many_renders_each_camera_at_its_own_size(gl_renderer):
    cameras = [top_down(), top_down(width=80, height=48, fx=120.0, fy=80.0, depth_type="ray")]
    images = gl_renderer.render_many([unit_box()], cameras)
    assert [rgb.shape for rgb, _ in images] == [(64, 64, 3), (48, 80, 3)]
    assert [depth.shape for _, depth in images] == [(64, 64), (48, 80)]
    again = gl_renderer.render([unit_box()], cameras[0])
    assert np.array_equal(again[0], images[0][0]) and np.array_equal(again[1], images[0][1])


def test_framebuffers_are_reused_per_size(gl_renderer):
    camera = top_down(width=24, height=16)
    gl_renderer.render([unit_box()], camera)
    target = gl_renderer._targets[(24, 16)]
    gl_renderer.render([unit_box()], camera)
    assert gl_renderer._targets[(24, 16)] is target


def test_unknown_primitive_is_a_render_error(gl_renderer):
    with pytest.raises(RenderError, match="unknown primitive 'torus'"):
        gl_renderer.render([Part("torus", np.eye(4), RED)], top_down())


def test_released_renderer_refuses_to_render(gl_renderer):
    renderer = Renderer(SETTINGS)
    renderer.release()
    with pytest.raises(RenderError, match="released"):
        renderer.render([unit_box()], top_down())


def test_context_failure_names_the_packages_to_install(monkeypatch):
    def fail(**kwargs):
        raise Exception("requested device index 0, but found 0 devices")

    monkeypatch.setattr(context_module.moderngl, "create_context", fail)
    with pytest.raises(RenderError) as caught:
        context_module._create()
    message = str(caught.value)
    assert "found 0 devices" in message
    assert "libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri" in message


_THREADS = """
import os
from sppl.render.context import gl_context, renderer_string
gl_context()
names = [open(f"/proc/self/task/{t}/comm").read() for t in os.listdir("/proc/self/task")]
print(renderer_string().startswith("llvmpipe"), os.environ.get("LP_NUM_THREADS"),
      sum(n.startswith("llvmpipe") for n in names))
"""


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="needs Linux's /proc")
@pytest.mark.parametrize("given", [None, "2"])
def test_llvmpipe_rasterises_on_the_calling_thread_unless_told(require_gl, given):
    """sppl's context gets no llvmpipe rasteriser threads by default, the environment keeps no
    trace of that default, and a value the user gives wins."""
    import subprocess
    import sys
    from pathlib import Path

    import sppl

    env = {k: v for k, v in os.environ.items() if k != "LP_NUM_THREADS"}
    env["PYTHONPATH"] = os.pathsep.join(  # this checkout's sppl, whatever is installed
        [str(Path(sppl.__file__).resolve().parent.parent), env.get("PYTHONPATH", "")])
    if given is not None:
        env["LP_NUM_THREADS"] = given
    out = subprocess.run([sys.executable, "-c", _THREADS], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    if out[0] != "True":
        pytest.skip("the GL driver is not llvmpipe")
    assert out[1] == str(given)
    assert int(out[2]) == (0 if given is None else int(given))
