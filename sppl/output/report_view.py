"""The report's interactive 3D view: the ground, the cameras and posterior samples, in WebGL.

The view is for a reader learning what a posterior is: it draws the MAP scene solid and other
posterior samples as translucent "ghosts" (so that where the samples agree the ghosts stack up
into a near-solid shape, and where they disagree they smear out), the cameras as frusta, and,
under a slider, each chain's best-so-far scene over the sweeps, so the climb from an empty scene
to the MAP can be replayed.

Everything the view needs travels with the page, because the report opens from the file
system with no server and no network:
- three.js (``report_assets/three.min.js``, three r149, MIT, licence in its header and in
  ``three.LICENSE``) is copied beside ``index.html`` and loaded as a *classic* script. r149 is
  the last release that ships a single-file browser build: later ones ship ES modules only,
  and Chromium refuses to load a module from a ``file://`` page (CORS).
- the scene is embedded in the page as JSON: every part of every object as its primitive, its
  4x4 world-from-unit matrix (the one sppl's renderer draws) and its colour, so the 3D view
  shows exactly the shapes sppl scored. A mesh part carries its triangles, up to
  ``MESH_FACES_MAX`` of them; a larger mesh is drawn as the box of its bounds (a proxy).
- the view's own script (``report_assets/view.js``) and markup (``view.html``) are inlined.

The page sets ``window.spplViewReady`` once the first frame is drawn and exposes a small test
hook, ``window.spplView`` (see view.js), which tests/test_report.py drives in headless Chromium.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

ASSETS = Path(__file__).parent / "report_assets"
THREE_JS = "three.min.js"
GHOST_DRAWS = 30  # posterior samples drawn as ghosts (evenly spaced over all chains)
# The ghosts' opacity is chosen so that an object present in every ghost sample, in the same
# place, reaches this opacity: ghosts that stack up look solid, a lone one is faint.
GHOST_STACK_OPACITY = 0.9
TIMELINE_FRAMES = 120  # the most best-so-far scenes a chain's slider holds
MESH_FACES_MAX = 20_000  # a mesh with more triangles is drawn as its bounding box
DIGITS = 4  # decimals kept of each number in the page (0.1 mm: far below a pixel)
VIEW_CSS = (ASSETS / "view.css").read_text(encoding="utf-8")


def _round(a) -> list:
    return np.round(np.asarray(a, dtype=float), DIGITS).ravel().tolist()


def _column_major(matrix: np.ndarray) -> list[float]:
    """three.js's Matrix4.fromArray reads column by column."""
    return _round(np.asarray(matrix, dtype=float).T)


class _Meshes:
    """The meshes a scene's parts use, each embedded once, by file."""

    def __init__(self) -> None:
        self.table: dict[str, dict[str, list]] = {}
        self.proxies: set[str] = set()

    def part(self, primitive: str, matrix: np.ndarray) -> tuple[str, np.ndarray]:
        """The primitive the view draws for a mesh part, and its matrix (a box proxy for a
        mesh too large to embed)."""
        from ..model.geometry import scaling, translation, unit_mesh

        mesh = unit_mesh(primitive)
        if len(mesh.faces) <= MESH_FACES_MAX:
            if primitive not in self.table:
                self.table[primitive] = {"v": _round(mesh.vertices),
                                         "f": np.asarray(mesh.faces, dtype=int).ravel().tolist()}
            return primitive, matrix
        self.proxies.add(primitive)
        lo, hi = mesh.bounds
        centre = (lo + hi) / 2
        box = translation(centre[0], centre[1], lo[2]) @ scaling(*np.maximum(hi - lo, 1e-9))
        return "box", matrix @ box


def _parts(parts, meshes: _Meshes) -> list[dict[str, Any]]:
    from ..model.geometry import MESH_PREFIX

    out = []
    for p in parts:
        primitive, matrix = p.primitive, p.matrix
        if primitive.startswith(MESH_PREFIX):
            primitive, matrix = meshes.part(primitive, matrix)
        out.append({"p": primitive, "m": _column_major(matrix), "c": _round(p.colour)})
    return out


class _Scenes:
    """Scenes as lists of objects with their parts, each distinct scene stored once and
    referred to by its index (a chain's best-so-far repeats scenes; ghosts share none)."""

    def __init__(self, model) -> None:
        self.model, self.meshes = model, _Meshes()
        self.scenes: list[list[dict[str, Any]]] = []
        self.index: dict[str, int] = {}

    def add(self, objects: Sequence[dict[str, Any]]) -> int:
        from ..model.simulate import objects_from_dict

        key = json.dumps(objects, sort_keys=True)
        if key not in self.index:
            built = objects_from_dict(self.model, {"objects": list(objects)}, "a stored sample")
            self.index[key] = len(self.scenes)
            self.scenes.append([{"class": o.cls.name, "parts": _parts(o.parts, self.meshes)}
                                for o in built])
        return self.index[key]


def timeline(samples: Sequence[dict[str, Any]], frames: int = TIMELINE_FRAMES) -> list[int]:
    """Indices into one chain's stored samples of the sweeps where its best-so-far scene
    improved: the first sample, then each new best, at most ``frames`` of them, kept evenly
    among the improvements and always with the last (the chain's best stored scene)."""
    changes, best = [], -np.inf
    for i, s in enumerate(samples):
        if s["score"] > best:
            best = s["score"]
            changes.append(i)
    if len(changes) <= frames:
        return changes
    picks = np.unique(np.linspace(0, len(changes) - 1, frames).round().astype(int))
    return [changes[k] for k in picks]


def _camera(cam) -> dict[str, Any]:
    return {"name": cam.name, "c2w": _column_major(cam.c2w), "fx": cam.fx, "fy": cam.fy,
            "cx": cam.cx, "cy": cam.cy, "w": cam.width, "h": cam.height}


def view_data(model, run, map_objects, truth, ghost_samples, cameras, extent) -> dict[str, Any]:
    """What the view draws, as plain JSON: the static scenery, the cameras, the MAP, the
    ghosts (``ghost_samples``), the truth (or None) and each chain's best-so-far frames,
    scenes referred to by their index in ``scenes``."""
    scenes = _Scenes(model)
    ghosts = [scenes.add(s["objects"]) for s in ghost_samples]
    summary_map = run.summary.get("map") or {}
    map_chain = int(summary_map.get("chain", 0))
    chains = []
    for i, chain in enumerate(run.chains):
        frames = [{"step": int(chain.samples[k]["step"]), "score": float(chain.samples[k]["score"]),
                   "n": len(chain.samples[k]["objects"]),
                   "scene": scenes.add(chain.samples[k]["objects"])}
                  for k in timeline(chain.samples)]
        # With thinning the chain's best may be a sweep it did not store: end on it.
        if (i == map_chain and summary_map.get("objects") is not None
                and (not frames or summary_map["score"] > frames[-1]["score"])):
            frames.append({"step": int(summary_map.get("step", 0)),
                           "score": float(summary_map["score"]), "n": len(map_objects),
                           "scene": scenes.add(map_objects)})
        if frames:
            chains.append({"chain": i, "frames": frames})
    static = _parts(model.static_parts, scenes.meshes)
    n_ghosts = max(len(ghosts), 1)
    return {
        "extent": _round(extent),
        "static": static,
        "cameras": [_camera(c) for c in cameras],
        "map": scenes.add(map_objects),
        "map_chain": map_chain,
        "ghosts": ghosts,
        "ghost_opacity": round(1.0 - (1.0 - GHOST_STACK_OPACITY) ** (1.0 / n_ghosts), DIGITS),
        "truth": scenes.add(truth) if truth is not None else None,
        "chains": chains,
        "scenes": scenes.scenes,
        "meshes": scenes.meshes.table,
        "proxies": sorted(scenes.meshes.proxies),
    }


def _embed_json(data: Any) -> str:
    """JSON safe inside a <script> element: no "</" can close it early."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def view_html(data: dict[str, Any], folder: Path) -> str:
    """The view's HTML (markup, data and script) for the page; copies three.js beside it."""
    shutil.copyfile(ASSETS / THREE_JS, Path(folder) / THREE_JS)
    markup = (ASSETS / "view.html").read_text(encoding="utf-8")
    script = (ASSETS / "view.js").read_text(encoding="utf-8")
    proxies = ""
    if data["proxies"]:
        names = ", ".join(Path(p.split(":", 1)[1]).name for p in data["proxies"])
        proxies = (f"<p class='note'>Meshes with more than {MESH_FACES_MAX} triangles are drawn "
                   f"as their bounding boxes here: {names}.</p>")
    return (markup.replace("<!--PROXIES-->", proxies)
            + f"<script src=\"{THREE_JS}\"></script>\n"
            + f"<script type=\"application/json\" id=\"sppl-view-data\">{_embed_json(data)}"
            + f"</script>\n<script>\n{script}</script>\n")
