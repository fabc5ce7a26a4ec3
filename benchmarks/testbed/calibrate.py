"""Fit blocks.scn's appearance to Cycles: how bright rubber and metal are drawn, how much of
the light ignores orientation and how much grey sheen every surface shows, chosen to bring
sppl's renders of the test bed's true scenes closest to Cycles' renders of them; then count
the objects whose true material and colour a wrong pair outscores.

    python benchmarks/testbed/calibrate.py            # the grid below, about four minutes
    python benchmarks/testbed/calibrate.py --check 0.8 1.2 0.35 --no-shadows   # one setting
    python benchmarks/testbed/calibrate.py --check 1 0.7 0.6 --sheen 0.05

blocks.scn draws an object of palette colour c as ``shade(c, f)`` with ``f`` its material's
factor, lit as ``c f (ambient + intensity (1 - ambient) lambert) + sheen``. For each ambient
share and sheen the light's intensity is set so that the lit floor keeps its brightness (the
floor is what pins the exposure: Cycles' and sppl's floors agree, docs/testbed.md), so the fit
is over four numbers: the rubber factor, the metal factor, the ambient share and the sheen.
The score is the mean squared RGB error over every pixel of the RGB camera, summed over the
blocks.scn scenes with objects (the low-sun scene is rendered with its own sun, as a latent
light would find it).

The check renders each true scene again with one object's (material, colour) replaced by each of
the 15 others and counts the objects for which some wrong pair scores higher under a Gaussian of
scale ``--sigma``: where that happens, no sampler finds the true scene as the MAP.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from sppl.lang import compile_model
from sppl.observations import load_observations
from sppl.render import Renderer
from sppl.simulate import objects_from_dict

MODEL = ROOT / "models" / "blocks.scn"
LAMBERT_FLOOR = 0.894  # the floor's lambert term under blocks.scn's light (0.4, -0.3, 1)
FLOOR = 0.6  # blocks.scn's floor grey
MATERIAL = "select(material, rubber: 1, metal: 0.6)"  # as shipped; replaced by each candidate


def model_with(rubber: float, metal: float):
    text = MODEL.read_text()
    if MATERIAL not in text:
        raise SystemExit(f"{MODEL}: no `{MATERIAL}` to vary: update calibrate.py's MATERIAL")
    text = text.replace(MATERIAL, f"select(material, rubber: {rubber}, metal: {metal})")
    return compile_model(text, MODEL)


def lighting(model, ambient: float, shadows: bool, scene: dict, sheen: float = 0.0):
    """The model's lighting at this ambient share and sheen, the intensity keeping the lit
    floor's brightness of the old (ambient 0.35, intensity 1, no sheen) setting, the sun the
    scene's."""
    floor = 0.35 + 0.65 * LAMBERT_FLOOR
    intensity = (floor - sheen / FLOOR - ambient) / ((1 - ambient) * LAMBERT_FLOOR)
    light = scene.get("renderer", {}).get("light", model.render.light)
    return replace(model.render, ambient=ambient, intensity=intensity, sheen=sheen,
                   shadows=shadows, light=tuple(light), latent=())


def scenes():
    index = json.loads((HERE / "scenes.json").read_text())
    out = []
    for e in index:
        if e["model"] != "models/blocks.scn" or not e["scene"]["objects"]:
            continue
        folder = HERE / e["name"] / "cycles"
        frames = [f for f in load_observations(folder).frames if f.rgb is not None]
        out.append((e["name"], e["scene"], frames))
    return out


def render_error(renderer, model, settings, scene, frames, sigma=None):
    """Mean squared error over the RGB frames' pixels, or (with sigma) the Gaussian log
    likelihood of the frames given the scene."""
    objects = objects_from_dict(model, scene)
    parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
    total = 0.0
    for f in frames:
        rgb, _ = renderer.render(parts, f.camera, settings)
        d = rgb.astype(np.float64) - f.rgb
        total += float(np.mean(d * d)) if sigma is None else float(-0.5 * np.sum((d / sigma) ** 2))
    return total


def mean_error(cases, renderer, model, ambient, sheen, shadows=True):
    return sum(render_error(renderer, model, lighting(model, ambient, shadows, scene, sheen),
                            scene, frames) for _, scene, frames in cases) / len(cases)


def fit(cases, renderer, grid):
    rows = []
    for rubber, metal in itertools.product(grid["rubber"], grid["metal"]):
        model = model_with(rubber, metal)
        for ambient, sheen in itertools.product(grid["ambient"], grid["sheen"]):
            rows.append((mean_error(cases, renderer, model, ambient, sheen),
                         rubber, metal, ambient, sheen))
    return sorted(rows)


def check(cases, renderer, rubber, metal, ambient, shadows, sigma, sheen=0.0):
    model = model_with(rubber, metal)
    colours = ["gray", "red", "blue", "green", "brown", "purple", "cyan", "yellow"]  # clevr
    wrong = 0
    total = 0
    for name, scene, frames in cases:
        settings = lighting(model, ambient, shadows, scene, sheen)
        base = render_error(renderer, model, settings, scene, frames, sigma)
        for k, o in enumerate(scene["objects"]):
            best = None
            for material, c in itertools.product(("rubber", "metal"), colours):
                if (material, c) == (o["params"]["material"], o["params"]["c"]):
                    continue
                other = json.loads(json.dumps(scene))
                other["objects"][k]["params"].update(material=material, c=c)
                d = render_error(renderer, model, settings, other, frames, sigma) - base
                if best is None or d > best[0]:
                    best = (d, material, c)
            total += 1
            wrong += best[0] > 0
            print(f"  {name:18s} {o['class']:9s} {o['params']['material']:6s} "
                  f"{o['params']['c']:7s} best wrong pair: {best[1]} {best[2]:7s} "
                  f"{best[0]:+10.1f} nats")
    print(f"objects whose true (material, colour) a wrong pair outscores: {wrong}/{total}")
    return wrong


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", type=float, nargs=3, metavar=("RUBBER", "METAL", "AMBIENT"),
                   help="check one setting instead of fitting")
    p.add_argument("--sheen", type=float, default=0.0, help="with --check: the sheen (default 0)")
    p.add_argument("--no-shadows", action="store_true", help="with --check: no cast shadows")
    p.add_argument("--sigma", type=float, default=0.03, help="the check's Gaussian scale")
    args = p.parse_args(argv)
    if not 0.0 <= args.sheen <= 1.0:
        p.error(f"--sheen is a grey level in [0, 1], got {args.sheen:g}")
    cases = scenes()
    renderer = Renderer(model_with(1, 1).render)
    if args.check:
        rubber, metal, ambient = args.check
        check(cases, renderer, rubber, metal, ambient, not args.no_shadows, args.sigma,
              args.sheen)
        return 0
    # Around the setting fitted without a sheen (rubber 1, metal 0.7, ambient 0.6): the sheen
    # takes over part of what the ambient share drew.
    grid = {"rubber": [0.8, 0.9, 1.0, 1.1], "metal": [0.5, 0.6, 0.7, 0.8],
            "ambient": [0.35, 0.45, 0.5, 0.55, 0.6, 0.7], "sheen": [0.0, 0.03, 0.05, 0.07, 0.09]}
    rows = fit(cases, renderer, grid)
    print("mean squared RGB error per scene: rubber factor, metal factor, ambient share, sheen")
    for err, rubber, metal, ambient, sheen in rows[:8]:
        print(f"  {err:.5f}  rubber {rubber}  metal {metal}  ambient {ambient}  sheen {sheen}")
    for (rubber, metal, ambient, sheen), label in [((0.8, 1.2, 0.35, 0.0), "the first blocks.scn"),
                                                   ((1.0, 0.7, 0.6, 0.0), "fitted without a sheen")]:
        err = mean_error(cases, renderer, model_with(rubber, metal), ambient, sheen)
        print(f"  {err:.5f}  rubber {rubber}  metal {metal}  ambient {ambient}  sheen {sheen} "
              f"({label})")
    _, rubber, metal, ambient, sheen = rows[0]
    print(f"\nthe best setting, rubber {rubber}, metal {metal}, ambient {ambient}, sheen {sheen}:")
    check(cases, renderer, rubber, metal, ambient, True, args.sigma, sheen)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
