"""Fit blocks.scn's appearance to Cycles: how bright rubber and metal are drawn, how much of
the light ignores orientation and how much grey sheen every surface shows, chosen to bring
sppl's renders of the test bed's true scenes closest to Cycles' renders of them; then count
the objects whose true material and colour a wrong pair outscores.

    python benchmarks/testbed/calibrate.py            # the grid below, about two minutes
    python benchmarks/testbed/calibrate.py --check 1 0.7 0.6 --sheen 0.03   # one setting
    python benchmarks/testbed/calibrate.py --check 0.8 1.2 0.35 --no-shadows --sigma 0.03

blocks.scn draws an object of palette colour c as ``shade(c, f)`` with ``f`` its material's
factor, lit as ``c f (ambient + intensity (1 - ambient) lambert) + sheen``. For each ambient
share and sheen the light's intensity is set so that the lit floor keeps its brightness (the
floor is what pins the exposure: Cycles' and sppl's floors agree, docs/testbed.md), so the fit
is over four numbers: the rubber factor, the metal factor, the ambient share and the sheen.
The score is what the sampler weighs: the model's own image likelihood (blocks.scn's
mixture) at the sensor's noise (NOISE), summed over the RGB camera's pixels of the blocks.scn
scenes with objects (the low-sun scene is rendered with its own sun, as a latent light would
find it). The mean squared error is printed beside it: it chose worse settings, since it is
ruled by the few pixels no setting draws (highlights, reflections, edges), which the mixture
leaves to its outlier share.

The check renders each true scene again with one object's (material, colour) replaced by each of
the 15 others and counts the objects for which some wrong pair scores higher (under the model's
likelihood, or a Gaussian of scale ``--sigma``): where that happens, no sampler finds the true
scene as the MAP.
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

from sppl.data.observations import load_observations
from sppl.lang import compile_model
from sppl.model.likelihoods import get_likelihood
from sppl.model.simulate import objects_from_dict
from sppl.render import Renderer

MODEL = ROOT / "models" / "blocks.scn"
LAMBERT_FLOOR = 0.894  # the floor's lambert term under blocks.scn's light (0.4, -0.3, 1)
FLOOR = 0.6  # blocks.scn's floor grey
MATERIAL = "select(material, rubber: 1, metal: 0.7)"  # as shipped; replaced by each candidate
# The image noise the likelihood is scored at: the sensor's true scale, and about the outlier
# share the chains infer on the test bed's Cycles renders.
NOISE = {"sigma": 0.02, "outlier": 0.02}


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


def render_score(renderer, model, settings, scene, frames, sigma=None):
    """The log likelihood of the RGB frames given the scene: the model's image likelihood at
    NOISE, or (with sigma) a Gaussian's of that scale (its constant left out)."""
    objects = objects_from_dict(model, scene)
    parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
    sensor = model.sensors["image"]
    likelihood = get_likelihood(sensor.likelihood, sensor.options)
    total = 0.0
    for f in frames:
        rgb, _ = renderer.render(parts, f.camera, settings)
        if sigma is None:
            total += likelihood.log_density(f.rgb, rgb, None, NOISE)
        else:
            d = rgb.astype(np.float64) - f.rgb
            total += float(-0.5 * np.sum((d / sigma) ** 2))
    return total


def render_error(renderer, model, settings, scene, frames):
    """The mean squared error over the RGB frames' pixels."""
    objects = objects_from_dict(model, scene)
    parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
    total = 0.0
    for f in frames:
        rgb, _ = renderer.render(parts, f.camera, settings)
        d = rgb.astype(np.float64) - f.rgb
        total += float(np.mean(d * d))
    return total


def totals(cases, renderer, model, ambient, sheen, shadows=True):
    """The log likelihood summed over the scenes, and the mean squared error per scene."""
    score = error = 0.0
    for _, scene, frames in cases:
        settings = lighting(model, ambient, shadows, scene, sheen)
        score += render_score(renderer, model, settings, scene, frames)
        error += render_error(renderer, model, settings, scene, frames)
    return score, error / len(cases)


def fit(cases, renderer, grid):
    rows = []
    for rubber, metal in itertools.product(grid["rubber"], grid["metal"]):
        model = model_with(rubber, metal)
        for ambient, sheen in itertools.product(grid["ambient"], grid["sheen"]):
            rows.append((*totals(cases, renderer, model, ambient, sheen),
                         rubber, metal, ambient, sheen))
    return sorted(rows, key=lambda row: -row[0])


def check(cases, renderer, rubber, metal, ambient, shadows, sigma, sheen=0.0):
    model = model_with(rubber, metal)
    colours = ["gray", "red", "blue", "green", "brown", "purple", "cyan", "yellow"]  # clevr
    wrong = 0
    total = 0
    for name, scene, frames in cases:
        settings = lighting(model, ambient, shadows, scene, sheen)
        base = render_score(renderer, model, settings, scene, frames, sigma)
        for k, o in enumerate(scene["objects"]):
            best = None
            for material, c in itertools.product(("rubber", "metal"), colours):
                if (material, c) == (o["params"]["material"], o["params"]["c"]):
                    continue
                other = json.loads(json.dumps(scene))
                other["objects"][k]["params"].update(material=material, c=c)
                d = render_score(renderer, model, settings, other, frames, sigma) - base
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
    p.add_argument("--sigma", type=float, default=None,
                   help="with --check: score by a Gaussian of this scale instead of the model's "
                        "likelihood")
    args = p.parse_args(argv)
    if not 0.0 <= args.sheen <= 1.0:
        p.error(f"--sheen is a grey level in [0, 1], got {args.sheen:g}")
    if args.sigma is not None and not args.sigma > 0.0:
        p.error(f"--sigma is a positive scale, got {args.sigma:g}")
    cases = scenes()
    renderer = Renderer(model_with(1, 1).render)
    if args.check:
        rubber, metal, ambient = args.check
        check(cases, renderer, rubber, metal, ambient, not args.no_shadows, args.sigma,
              args.sheen)
        return 0
    grid = {"rubber": [0.9, 0.95, 1.0, 1.05, 1.1], "metal": [0.6, 0.65, 0.7, 0.75, 0.8],
            "ambient": [0.45, 0.5, 0.55, 0.6, 0.65, 0.7],
            "sheen": [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.07]}
    rows = fit(cases, renderer, grid)
    print("image log likelihood over the scenes (nats), mean squared RGB error per scene: "
          "rubber factor, metal factor, ambient share, sheen")

    def show(score, error, rubber, metal, ambient, sheen, label=""):
        print(f"  {score:10.1f}  {error:.5f}  rubber {rubber}  metal {metal}  "
              f"ambient {ambient}  sheen {sheen}{label}")

    for row in rows[:8]:
        show(*row)
    for (rubber, metal, ambient, sheen), label in [
            ((0.8, 1.2, 0.35, 0.0), "the first blocks.scn"),
            ((1.0, 0.7, 0.6, 0.0), "the best without a sheen by squared error"),
            ((1.0, 0.6, 0.45, 0.07), "the best with a sheen by squared error")]:
        show(*totals(cases, renderer, model_with(rubber, metal), ambient, sheen),
             rubber, metal, ambient, sheen, f" ({label})")
    best = max((r for r in rows if r[5] == 0.0), key=lambda row: row[0])
    show(*best, " (the best without a sheen)")
    _, _, rubber, metal, ambient, sheen = rows[0]
    print(f"\nthe best setting, rubber {rubber}, metal {metal}, ambient {ambient}, sheen {sheen}:")
    check(cases, renderer, rubber, metal, ambient, True, args.sigma, sheen)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
