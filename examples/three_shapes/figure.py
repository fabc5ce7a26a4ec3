"""Each camera's observation beside the MAP scene rendered from the same camera.

    python examples/three_shapes/figure.py RUN_FOLDER [--out docs/images/three_shapes.png]

Reads the run's summary (its MAP scene) and the observation folder it was sampled from; depth
is drawn as grey levels, near is bright.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sppl import Renderer, load_model, load_observations, objects_from_dict

SCALE = 3  # pixels of the figure per pixel of the image


def _depth_image(depth: np.ndarray, depth_max: float) -> np.ndarray:
    grey = 1.0 - np.clip(np.nan_to_num(depth, nan=depth_max) / depth_max, 0.0, 1.0)
    return np.repeat(grey[..., None], 3, axis=-1)


def _tile(image: np.ndarray, label: str) -> Image.Image:
    im = Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8))
    im = im.resize((im.width * SCALE, im.height * SCALE), Image.NEAREST)
    out = Image.new("RGB", (im.width, im.height + 18), "white")
    out.paste(im, (0, 18))
    ImageDraw.Draw(out).text((4, 3), label, fill="black")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path)
    p.add_argument("--out", type=Path, default=Path("docs/images/three_shapes.png"))
    args = p.parse_args(argv)
    meta = json.loads((args.run / "run.json").read_text())
    summary = json.loads((args.run / "summary.json").read_text())
    model = load_model(meta["model"])
    obs = load_observations(meta["observations"])
    objects = objects_from_dict(model, summary["map"])
    renderer = Renderer(model.render)
    parts = [p for o in objects for p in o.parts]
    tiles = []
    for frame in obs.frames:
        rgb, depth = renderer.render(parts, frame.camera)
        if frame.rgb is not None:
            tiles += [_tile(frame.rgb, f"{frame.name}: observed"), _tile(rgb, "MAP render")]
        if frame.depth is not None:
            dmax = frame.camera.depth_max
            tiles += [_tile(_depth_image(frame.depth, dmax), f"{frame.name}: observed"),
                      _tile(_depth_image(depth, dmax), "MAP render")]
    width = sum(t.width for t in tiles) + 6 * (len(tiles) - 1)
    figure = Image.new("RGB", (width, max(t.height for t in tiles)), "white")
    x = 0
    for t in tiles:
        figure.paste(t, (x, 0))
        x += t.width + 6
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.save(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
