"""The test bed's figure: per scene, Cycles' render beside sppl's render of the true scene
beside sppl's render of the MAP scene that benchmarks/testbed.py found in Cycles' render.

    python benchmarks/testbed.py --json RUN.json ...
    python benchmarks/testbed/figure.py RUN.json [--scenes blocks_metal ...] [--out docs/images/testbed.png]

Columns: the RGB camera as Cycles rendered it, as sppl rendered the true scene (the sibling
``sppl/`` folder), and sppl's rendering of the MAP; then the depth camera the same three ways
(grey levels, near is bright).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

from PIL import Image

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

# The tiles of examples/three_shapes/figure.py (an image at a scale, with a label above it).
_spec = importlib.util.spec_from_file_location(
    "three_shapes_figure", ROOT / "examples" / "three_shapes" / "figure.py")
tiles = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tiles)
tiles.SCALE = 2
_tile, _depth_image = tiles._tile, tiles._depth_image

from sppl.data.observations import load_observations  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.model.simulate import objects_from_dict  # noqa: E402
from sppl.render import Renderer  # noqa: E402

SCENES = ("blocks_metal", "blocks_shadows", "blocks_occlusion")


def row(entry: dict, found: dict) -> list[Image.Image]:
    model = load_model(ROOT / entry["model"])
    cycles = load_observations(HERE / entry["name"] / "cycles").frames
    sppl = load_observations(HERE / entry["name"] / "sppl").frames
    objects = objects_from_dict(model, found["map"])
    renderer = Renderer(model.render)
    try:
        parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
        rendered = [renderer.render(parts, f.camera) for f in cycles]
    finally:
        renderer.release()
    verdict = "recovered" if found["recovered"] else "not recovered"
    tiles = []
    for c, s, (rgb, depth) in zip(cycles, sppl, rendered):
        if c.rgb is not None:
            tiles += [_tile(c.rgb, f"{entry['name']}: Cycles"), _tile(s.rgb, "sppl, truth"),
                      _tile(rgb, f"MAP ({verdict})")]
        if c.depth is not None:
            dmax = c.camera.depth_max
            tiles += [_tile(_depth_image(c.depth, dmax), "depth: Cycles"),
                      _tile(_depth_image(s.depth, dmax), "sppl, truth"),
                      _tile(_depth_image(depth, dmax), "MAP")]
    return tiles


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=Path, nargs="+", help="benchmarks/testbed.py --json files")
    p.add_argument("--scenes", nargs="+", default=list(SCENES))
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "testbed.png")
    args = p.parse_args(argv)
    found = {r["scene"]: r for path in args.runs for r in json.loads(path.read_text())
             if r["renderer"] == "cycles"}
    index = {e["name"]: e for e in json.loads((HERE / "scenes.json").read_text())}
    rows = [row(index[name], found[name]) for name in args.scenes]
    w, h = rows[0][0].size
    sheet = Image.new("RGB", (w * max(map(len, rows)), h * len(rows)), "white")
    for i, tiles in enumerate(rows):
        for j, tile in enumerate(tiles):
            sheet.paste(tile, (j * w, i * h))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out, optimize=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
