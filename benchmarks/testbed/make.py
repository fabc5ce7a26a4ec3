"""Make the test bed: scenes of the shipped models rendered by Blender's Cycles, and the same
scenes rendered by sppl, each as an observation folder with its true scene.

    pip install '.[cycles]'
    python benchmarks/testbed/make.py              # every scene (about a minute)
    python benchmarks/testbed/make.py --only blocks_shadows
    python benchmarks/testbed/make.py --sppl-only  # sppl's renders only, after a model changes

Scenes: for each model, a few drawn from its prior with a fixed seed, with 1 to 5 objects
whose centres are all inside both cameras' images (the prior conditioned on the count and
on the objects being in view: ``drawn_scenes``), and a few written by hand for what the prior
rarely draws: an empty floor, metal objects, long cast shadows (a low sun), and an object
partly hidden behind another from the RGB camera. Each scene NAME gets

    benchmarks/testbed/NAME/cycles/   rendered by render_cycles.py (Cycles), with scene.json
    benchmarks/testbed/NAME/sppl/     rendered by `sppl simulate --scene` (sppl's own renderer)

with the cameras of ``examples/models/MODEL/cameras.json`` (one RGB and one depth camera,
96x96) and the same sensor noise (Gaussian, 0.02 in RGB and 0.02 m in depth). The list of
scenes is written to ``benchmarks/testbed/scenes.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from scenes_in_view import draw_in_view

from sppl.cli import main as sppl
from sppl.data.observations import load_cameras
from sppl.lang import load_model

SEED = 2024
MAX_OBJECTS = 5
# How many scenes each model draws from its prior.
DRAWN = {"blocks": 5, "shapes": 2}
SIGMA = 0.02
# The ambient share with which sppl's shading comes closest to Cycles' sky light (render_cycles'
# WORLD_LIGHT) on the test bed's blocks.scn scenes, the light's intensity set to keep the lit
# floor as bright (benchmarks/testbed/calibrate.py); blocks.scn ships the same values.
CYCLES_AMBIENT = 0.6

# What the prior rarely draws, by hand. "renderer": {"light": ...} moves Cycles' sun.
LOW_SUN = [-0.2, 1.0, 0.55]  # from the far side, 29 degrees up: shadows fall towards the cameras
CASES = {
    "blocks": {
        "empty": {"objects": []},
        "metal": {"objects": [
            {"class": "sphere", "params": {"x": 0.6, "y": -0.6, "size": "large",
                                           "material": "metal", "c": "gray"}},
            {"class": "cylinder", "params": {"x": -0.7, "y": 0.2, "size": "large",
                                             "material": "metal", "c": "blue"}},
            {"class": "cube", "params": {"x": 0.5, "y": 0.9, "a": 0.4, "size": "small",
                                         "material": "metal", "c": "yellow"}}]},
        "shadows": {"renderer": {"light": LOW_SUN}, "objects": [
            {"class": "cube", "params": {"x": 0.2, "y": -0.3, "a": 0.2, "size": "large",
                                         "material": "rubber", "c": "green"}},
            {"class": "cylinder", "params": {"x": -0.9, "y": -0.9, "size": "small",
                                             "material": "rubber", "c": "purple"}}]},
        # From the RGB camera at (3, -2.6) the small sphere is partly behind the large cube.
        "occlusion": {"objects": [
            {"class": "cube", "params": {"x": 0.9, "y": -0.7, "a": 0.0, "size": "large",
                                         "material": "rubber", "c": "brown"}},
            {"class": "sphere", "params": {"x": 0.4, "y": 0.55, "size": "small",
                                           "material": "rubber", "c": "cyan"}}]},
    },
    # shapes.scn has no ground (nothing to cast a shadow on): a low sun only shades differently.
    "shapes": {
        "lowsun": {"renderer": {"light": LOW_SUN}, "objects": [
            {"class": "cone", "params": {"x": 0.3, "y": -0.2, "r": 0.4, "h": 0.9, "c": "red"}},
            {"class": "sphere", "params": {"x": -0.9, "y": 0.6, "r": 0.3, "c": "blue"}}]},
        "occlusion": {"objects": [
            {"class": "cube", "params": {"x": 0.9, "y": -0.7, "a": 0.1, "s": 0.8, "c": "green"}},
            {"class": "sphere", "params": {"x": 0.0, "y": 0.2, "r": 0.25, "c": "red"}}]},
    },
}


def cameras_of(model_name: str) -> Path:
    return ROOT / "examples" / "models" / model_name / "cameras.json"


def drawn_scenes(model_name: str, n: int, seed: int) -> dict[str, dict]:
    """``n`` scenes from the model's prior conditioned on their objects being in view, with
    1, 2, ... objects (the count is set, not drawn: the prior conditioned on view holds
    mostly empty scenes, and the hand-written cases have an empty one); see
    benchmarks/scenes_in_view.py."""
    model = load_model(ROOT / "models" / f"{model_name}.scn")
    cameras = load_cameras(cameras_of(model_name))
    rng = np.random.default_rng(np.random.SeedSequence([seed, sorted(DRAWN).index(model_name)]))
    scenes = {}
    while len(scenes) < n:
        objects = draw_in_view(model, cameras, 1 + len(scenes) % MAX_OBJECTS, rng)
        scenes[f"prior{len(scenes)}"] = {"objects": [o.as_dict() for o in objects]}
    return scenes


def all_scenes(seed: int = SEED) -> list[dict]:
    index = []
    for model_name in sorted(DRAWN):
        cases = {**drawn_scenes(model_name, DRAWN[model_name], seed), **CASES[model_name]}
        for case, scene in cases.items():
            index.append({"name": f"{model_name}_{case}", "model": f"models/{model_name}.scn",
                          "cameras": str(cameras_of(model_name).relative_to(ROOT)),
                          "scene": {**scene, "noise": {"image": {"sigma": SIGMA},
                                                       "depth": {"sigma": SIGMA}}}})
    return index


def simulation_noise(model, scene: dict) -> dict:
    """The noise and lighting values ``sppl simulate`` renders the scene with: the sensors'
    true Gaussian scale, no outliers (a robust likelihood's outlier share at 0 draws exactly
    the Gaussian noise Cycles' folder has), and, where the model leaves the lighting latent,
    the light Cycles' sun shines from and the ambient share that matches its sky (CYCLES_AMBIENT)."""
    from sppl.model.types import RENDER_GROUP

    noise = {}
    for kind, parameters in model.noise_groups:
        if kind == RENDER_GROUP:
            light = np.asarray(scene.get("renderer", {}).get("light", model.render.light), float)
            x, y, z = light / np.linalg.norm(light)
            direction = {"azimuth": float(np.arctan2(y, x)), "elevation": float(np.arcsin(z)),
                         "ambient": CYCLES_AMBIENT}
            noise[kind] = {p.name: direction[p.name] if p.name in direction
                           else getattr(model.render, p.name) for p in parameters}
        else:
            noise[kind] = {p.name: SIGMA if p.name == "sigma" else 0.0 for p in parameters}
    return noise


def make(entry: dict, out: Path, seed: int, cycles: bool = True) -> None:
    folder = out / entry["name"]
    with tempfile.TemporaryDirectory() as tmp:
        scene_file = Path(tmp) / "scene.json"
        scene_file.write_text(json.dumps(entry["scene"]))
        log = io.StringIO()
        if cycles:
            from render_cycles import render_folder

            if folder.exists():
                shutil.rmtree(folder)
            # Blender prints every sample's progress on the C side: it goes to the terminal.
            render_folder(ROOT / entry["model"], ROOT / entry["cameras"], scene_file,
                          folder / "cycles", seed=seed, sigma=SIGMA)
        model = load_model(ROOT / entry["model"])
        scene_file.write_text(json.dumps({**entry["scene"],
                                          "noise": simulation_noise(model, entry["scene"])}))
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            code = sppl(["simulate", str(ROOT / entry["model"]), "--cameras",
                         str(ROOT / entry["cameras"]), "--scene", str(scene_file), "--out",
                         str(folder / "sppl"), "--seed", str(seed), "--depth-format", "png",
                         "--force"])
        if code:
            raise SystemExit(f"sppl simulate failed for {entry['name']}:\n{log.getvalue()}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=HERE)
    p.add_argument("--only", nargs="+", help="scene names (default: every one)")
    p.add_argument("--seed", type=int, default=SEED)
    p.add_argument("--sppl-only", action="store_true",
                   help="render the sppl/ folders only (no bpy needed): after a model's "
                        "appearance or lighting changes; Cycles' renders do not depend on them")
    args = p.parse_args(argv)
    index = all_scenes(args.seed)
    (args.out / "scenes.json").write_text(json.dumps(index, indent=2) + "\n")
    for i, entry in enumerate(index):
        if args.only and entry["name"] not in args.only:
            continue
        make(entry, args.out, args.seed + i, cycles=not args.sppl_only)
        print(f"{entry['name']}: {len(entry['scene']['objects'])} objects", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
