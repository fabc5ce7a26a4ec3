"""Render a scene of an sppl model with Blender's Cycles into an observation folder.

    pip install '.[cycles]'     # bpy (Blender as a Python module) and openexr
    python benchmarks/testbed/render_cycles.py models/blocks.scn CAMERAS.json SCENE.json OUT/

The scene file is the one ``sppl simulate --scene`` reads (``{"objects": [{"class": ...,
"params": {...}}]}``), with optionally ``"renderer": {"light": [x, y, z]}``, the direction
towards the sun (default: the model's ``render { light }``); the cameras file is ``sppl
simulate``'s (``transforms.json`` without images, each frame naming its modalities). OUT gets what ``sppl sample --obs`` reads: 8-bit PNG
images, 16-bit millimetre PNG depth maps, ``transforms.json`` in nerfstudio's OpenGL axes, and
the true scene as ``scene.json`` with the sensors' true noise scales.

What differs from sppl's own renderer, on purpose (it is what a real camera sees): a path tracer
with a sun that casts shadows and light bounced off the floor and the objects, matte rubber and
glossy metal (Principled BSDF, metal where an object's ``material`` is ``metal``), edges
anti-aliased by Cycles' pixel filter, Monte Carlo noise, and mixed depth pixels at edges as
Cycles' Z pass leaves them. What matches the model: every part's shape, size and pose (each
part's own world-from-unit matrix on the unit shapes of ``sppl.model.geometry``), the ground, and
the colours, which are the palette's values taken as sRGB: converted to linear for Blender's
base colours, and the linear render converted back to sRGB (Blender's "Standard" view), so a
surface lit at unit strength shows the palette's very values. sppl reads the PNGs as they are
(no gamma), as it reads any camera's.

Depth is Cycles' Z pass, the distance along the optical axis (``depth_type`` ``"z"``), clipped
at the camera's ``depth_max`` (sky pixels, where the Z pass holds 1e10, read ``depth_max``,
as sppl's renderer draws them). The Z pass is not a filtered mean of a pixel's samples: an
edge pixel holds the depth of one side of the edge, near enough always the side its centre
sees. Then Gaussian sensor noise (``--sigma``) is added to both modalities, drawn from a
generator seeded by ``--seed`` in the order ``sppl simulate`` draws it (RGB, then depth), so
``sppl simulate --seed`` with the same seed makes the same noise over sppl's rendering.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from sppl.data.observations import Frame, load_cameras, write_observations  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.model.geometry import unit_mesh  # noqa: E402
from sppl.model.simulate import load_scene, scene_dict  # noqa: E402

SAMPLES = 128  # Cycles' samples per pixel
SENSOR_SIGMA = 0.02  # the sensors' true noise: RGB in [0, 1], depth in metres
SUN_STRENGTH = 2.6  # W/m^2; with the world's light, a lit floor about as bright as sppl's
SUN_ANGLE = math.radians(4.0)  # the sun's disc: slightly soft shadow edges
WORLD_LIGHT = 0.12  # radiance of the sky that lights the scene (linear), sppl's "ambient"
RUBBER_ROUGHNESS, METAL_ROUGHNESS = 0.75, 0.25


def srgb_to_linear(c):
    c = np.asarray(c, dtype=float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c):
    c = np.clip(np.asarray(c, dtype=float), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def _material(bpy, name, colour, metal):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*srgb_to_linear(colour), 1.0)
    bsdf.inputs["Metallic"].default_value = 1.0 if metal else 0.0
    bsdf.inputs["Roughness"].default_value = METAL_ROUGHNESS if metal else RUBBER_ROUGHNESS
    return mat


def _mesh(bpy, primitive):
    """The unit shape of sppl.model.geometry as a Blender mesh: round ones smooth-shaded."""
    if primitive in bpy.data.meshes:
        return bpy.data.meshes[primitive]
    tri = unit_mesh(primitive)
    if primitive == "sphere":  # finer than sppl's bounding icosphere: sppl ray-casts the sphere
        import trimesh

        tri = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
        tri.apply_translation((0.0, 0.0, 1.0))
    mesh = bpy.data.meshes.new(primitive)
    mesh.from_pydata(tri.vertices.tolist(), [], tri.faces.tolist())
    mesh.update()
    if primitive in ("sphere", "cylinder", "cone"):
        mesh.shade_smooth()
        if primitive != "sphere":
            mesh.set_sharp_from_angle(angle=math.radians(30))
    return mesh


def _base_colour(model, obj, part):
    """The palette colour an object's colour parameter names (sppl's part colour may be
    shaded by the model, as blocks.scn brightens metal); the part's colour otherwise."""
    for value in obj.values.values():
        if isinstance(value, str) and value in model.colours:
            return model.colours[value]
    return part.colour


def build_scene(bpy, model, objects, cameras, samples, light=None):
    from mathutils import Matrix, Vector

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.seed = 0
    scene.render.film_transparent = False
    scene.view_layers[0].use_pass_z = True
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    scene.render.resolution_percentage = 100

    # The sky: the model's background colour where a camera ray sees it, a dim light elsewhere.
    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    nodes.clear()
    seen = nodes.new("ShaderNodeBackground")
    seen.inputs["Color"].default_value = (*srgb_to_linear(model.render.background), 1.0)
    lighting = nodes.new("ShaderNodeBackground")
    lighting.inputs["Color"].default_value = (WORLD_LIGHT, WORLD_LIGHT, WORLD_LIGHT, 1.0)
    path = nodes.new("ShaderNodeLightPath")
    mix = nodes.new("ShaderNodeMixShader")
    out = nodes.new("ShaderNodeOutputWorld")
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(lighting.outputs["Background"], mix.inputs[1])
    links.new(seen.outputs["Background"], mix.inputs[2])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])

    # The sun shines from the model's light direction (sppl's renderer lights along it too),
    # unless the scene file's "renderer" names another (a lower sun, for long shadows).
    sun = bpy.data.lights.new("sun", type="SUN")
    sun.energy = SUN_STRENGTH
    sun.angle = SUN_ANGLE
    sun_obj = bpy.data.objects.new("sun", sun)
    sun_obj.rotation_euler = Vector(light or model.render.light).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun_obj)

    parts = [(None, p) for p in model.static_parts] + [(o, p) for o in objects for p in o.parts]
    for i, (obj, part) in enumerate(parts):
        if obj is None:  # the ground, a table: matte, in the part's colour
            mat = _material(bpy, f"static{i}", part.colour, metal=False)
        else:
            metal = obj.values.get("material") == "metal"
            mat = _material(bpy, f"part{i}", _base_colour(model, obj, part), metal)
        mesh = _mesh(bpy, part.primitive)
        if not mesh.materials:  # a slot on the shared mesh; each object links its own material
            mesh.materials.append(mat)
        ob = bpy.data.objects.new(f"part{i}", mesh)
        ob.material_slots[0].link = "OBJECT"
        ob.material_slots[0].material = mat
        ob.matrix_world = Matrix(np.asarray(part.matrix, dtype=float).tolist())
        scene.collection.objects.link(ob)

    cams = []
    for spec in cameras:
        cam = spec.camera
        if abs(cam.fx - cam.fy) > 1e-6 * cam.fx:
            raise SystemExit(f"camera {cam.name}: Blender needs square pixels (fl_x == fl_y)")
        data = bpy.data.cameras.new(cam.name)
        size = max(cam.width, cam.height)
        data.sensor_fit = "HORIZONTAL" if cam.width >= cam.height else "VERTICAL"
        data.sensor_width = data.sensor_height = 36.0
        data.lens = cam.fx * 36.0 / size
        # Blender's shift is in units of the larger side; +x moves the principal point left.
        data.shift_x = (cam.width / 2 - cam.cx) / size
        data.shift_y = (cam.cy - cam.height / 2) / size
        data.clip_start = min(cam.near, 0.01)
        data.clip_end = 1000.0
        ob = bpy.data.objects.new(cam.name, data)
        # Blender's cameras have OpenGL axes (look along -z, +y up): the matrix as it is.
        ob.matrix_world = Matrix(np.asarray(cam.c2w, dtype=float).tolist())
        scene.collection.objects.link(ob)
        cams.append((spec, ob))
    return scene, cams


def render(scene, camera_object, spec, work: Path):
    """Linear RGB (H, W, 3) and the Z pass (H, W) of one camera."""
    import bpy
    import OpenEXR

    cam = spec.camera
    scene.camera = camera_object
    scene.render.resolution_x, scene.render.resolution_y = cam.width, cam.height
    path = work / f"{cam.name}.exr"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(str(path)) as f:
        channels = {name: np.array(c.pixels) for name, c in f.channels().items()}
    rgb = next(v for k, v in channels.items() if k.endswith("Combined") or k == "RGBA")
    z = next(v for k, v in channels.items() if k.endswith("Depth.Z") or k.endswith("Depth"))
    return np.asarray(rgb, dtype=float)[..., :3], np.asarray(z, dtype=float).reshape(cam.height, cam.width)


def render_folder(model_path, cameras_path, scene_path, out, *, seed=0, samples=SAMPLES,
                  sigma=SENSOR_SIGMA) -> Path:
    import bpy

    model = load_model(model_path)
    objects, _ = load_scene(model, scene_path)
    light = json.loads(Path(scene_path).read_text()).get("renderer", {}).get("light")
    specs = load_cameras(cameras_path)
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    scene, cams = build_scene(bpy, model, objects, specs, samples, light)
    frames = []
    with tempfile.TemporaryDirectory() as work:
        for spec, ob in cams:
            linear, z = render(scene, ob, spec, Path(work))
            cam = spec.camera
            rgb = depth = valid = None
            if "rgb" in spec.modalities:
                rgb = linear_to_srgb(linear) + rng.normal(0.0, sigma, linear.shape)
                rgb = np.clip(rgb, 0.0, 1.0).astype(np.float32)
            if "depth" in spec.modalities:
                z = np.minimum(np.where(np.isfinite(z), z, cam.depth_max), cam.depth_max)
                depth = np.clip(z + rng.normal(0.0, sigma, z.shape), 0.0, cam.depth_max)
                depth = depth.astype(np.float32)
                valid = np.ones(depth.shape, dtype=bool)
            frames.append(Frame(camera=cam, rgb=rgb, depth=depth, depth_valid=valid))
    out = Path(out)
    write_observations(out, frames, depth_format="png")
    truth = scene_dict(objects, {"image": {"sigma": sigma}, "depth": {"sigma": sigma}})
    truth["renderer"] = {"name": "cycles", "blender": bpy.app.version_string,
                         "samples": samples, "seed": seed,
                         "light": list(light or model.render.light)}
    (out / "scene.json").write_text(json.dumps(truth, indent=2) + "\n")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("model", type=Path)
    p.add_argument("cameras", type=Path)
    p.add_argument("scene", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    p.add_argument("--samples", type=int, default=SAMPLES, help="Cycles' samples per pixel")
    p.add_argument("--sigma", type=float, default=SENSOR_SIGMA,
                   help="the sensors' Gaussian noise (RGB and metres)")
    args = p.parse_args(argv)
    try:
        import bpy  # noqa: F401
    except ImportError:
        raise SystemExit("render_cycles.py needs Blender's bpy: pip install '.[cycles]'") from None
    render_folder(args.model, args.cameras, args.scene, args.out, seed=args.seed,
                  samples=args.samples, sigma=args.sigma)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
