"""``sppl report``: one HTML page that shows what a run found and how far to trust it.

The page (``run/report/index.html``) needs no server and no network: its figures are PNG files
beside it, so it opens from the file system and the figures can be used on their own, and its
one interactive part, a WebGL view, loads three.js from a file beside it with its data inlined
(``sppl.output.report_view``). A paragraph above each part says, for a reader learning the method,
what it means (``EXPLAIN``). It shows, in order:

- a 3D view of the MAP scene, posterior samples as translucent ghosts, the cameras and (when
  known) the true scene, with a slider over each chain's best scene so far;
- for each camera: the observation, the MAP scene rendered from that camera, and the residual;
- for each camera: the observation beside simulations of it from a few posterior samples
  (rendered, with sensor noise at each sample's noise scale: the posterior predictive);
- the posterior over the number of objects and over each class's count;
- a top-down occupancy map: the probability that each ground cell is covered by an object,
  with the MAP's and (when known) the true footprints drawn over it;
- for each MAP object, the posterior of each of its parameters over the samples that contain
  a matching object (same class, within ``MATCH_RADIUS`` metres on the ground);
- trace plots of the log joint, the number of objects and the noise scales, one line a chain;
- acceptance rates per move type and per class; R-hat and bulk/tail ESS of the
  label-invariant quantities (``sppl.output.posterior``);
- when the true scene is known: the MAP against it (count, classes, position and size errors).
"""

from __future__ import annotations

import html
import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RenderError, SpplError
from ..model.types import RENDER_GROUP
from .compare import TOLERANCE, compare_scenes, match_objects
from .posterior import RunFiles, diagnostics, kept_samples, load_run, posterior_arrays

MATCH_RADIUS = 0.5  # metres: a sample's object is "the same" as a MAP object within this
OCCUPANCY_DRAWS = 300  # samples the occupancy map averages over (evenly spaced)
MARGINAL_DRAWS = 4000  # samples the marginals are taken from (evenly spaced)
PREDICTIVE_DRAWS = 3  # posterior samples simulated beside each camera's observation
DPI = 90
CHAIN_COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
                 "#7f7f7f", "#bcbd22", "#17becf"]


@dataclass
class Figure:
    file: str
    title: str
    caption: str


def _figure(width: float, height: float):
    from matplotlib.figure import Figure as MplFigure

    return MplFigure(figsize=(width, height), layout="constrained")


def _save(fig, folder: Path, name: str) -> str:
    fig.savefig(folder / name, dpi=DPI)
    return name


def _resolve(given: Path | None, recorded: str | None, what: str, option: str, run: Path) -> Path:
    if given is not None:
        return given
    if not recorded:
        raise SpplError(f"{run / 'run.json'} names no {what}; give it with {option}")
    path = Path(recorded)
    if not path.exists():
        raise SpplError(
            f"{run / 'run.json'} names the {what} {recorded}, which does not exist from here "
            f"(it is relative to where `sppl sample` ran); give it with {option}"
        )
    return path


def pooled_samples(run: RunFiles) -> list[dict[str, Any]]:
    """Every chain's samples after burn-in, pooled in chain order."""
    return [s for chain in kept_samples(run) for s in chain]


def evenly(items: Sequence, n: int) -> list:
    """At most ``n`` of ``items``, evenly spaced, the first and last among them."""
    if len(items) <= n:
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, n).round().astype(int)]


def _position_names(model, class_name: str) -> tuple[str, str]:
    try:
        return model.object_class(class_name).position or ("x", "y")
    except KeyError:
        return ("x", "y")


def _xy(model, o: dict[str, Any]) -> np.ndarray:
    px, py = _position_names(model, o["class"])
    return np.array([float(o["params"].get(px, 0.0)), float(o["params"].get(py, 0.0))])


# ----------------------------------------------------------------------------------------------
# Figures


def camera_figures(model, obs, map_objects, folder: Path, map_noise=None) -> list[Figure]:
    """Per camera: observation, MAP render and residual, a row for each modality it has; lit
    by the MAP's lighting (``map_noise``'s render group) where the model leaves it latent."""
    from ..model.simulate import objects_from_dict
    from ..render import Renderer

    objects = objects_from_dict(model, {"objects": map_objects}, "MAP scene")
    parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
    renderer = Renderer(model.render)
    settings = model.render.with_values((map_noise or {}).get(RENDER_GROUP))
    figures = []
    try:
        for frame in obs.frames:
            rgb, depth = renderer.render(parts, frame.camera, settings)
            rows = [m for m in ("rgb", "depth") if getattr(frame, m) is not None]
            fig = _figure(9.0, 2.9 * len(rows))
            axes = fig.subplots(len(rows), 3, squeeze=False)
            for row, modality in zip(axes, rows):
                if modality == "rgb":
                    residual = (frame.rgb - rgb).mean(axis=-1)
                    row[0].imshow(np.clip(frame.rgb, 0, 1), interpolation="nearest")
                    row[1].imshow(np.clip(rgb, 0, 1), interpolation="nearest")
                    unit, label = "", "RGB"
                else:
                    valid = (frame.depth_valid if frame.depth_valid is not None
                             else np.isfinite(frame.depth))
                    dmax = frame.camera.depth_max
                    shown = np.where(valid, frame.depth, np.nan)
                    for ax, d in ((row[0], shown), (row[1], depth)):
                        ax.imshow(d, cmap="viridis_r", vmin=0, vmax=dmax, interpolation="nearest")
                    residual = np.where(valid, frame.depth - depth, np.nan)
                    unit, label = " (m)", "depth"
                finite = residual[np.isfinite(residual)]
                rms = float(np.sqrt(np.mean(finite**2))) if finite.size else math.nan
                lim = float(np.nanmax(np.abs(finite))) if finite.size else 1.0
                im = row[2].imshow(residual, cmap="RdBu_r", vmin=-lim, vmax=lim,
                                   interpolation="nearest")
                fig.colorbar(im, ax=row[2], shrink=0.85)
                row[0].set_title(f"{frame.name}: observed {label}")
                row[1].set_title("MAP scene rendered")
                row[2].set_title(f"residual{unit}, RMS {rms:.3g}")
                for ax in row:
                    ax.set_xticks([])
                    ax.set_yticks([])
            name = _save(fig, folder, f"camera_{_safe(frame.name)}.png")
            figures.append(Figure(
                name, f"Camera {frame.name}",
                "Left, what the camera recorded; middle, the MAP scene rendered from the same "
                "camera; right, observed minus rendered (for RGB, the mean over the three "
                "channels). Where the MAP explains the data the residual is noise only.",
            ))
    finally:
        renderer.release()
    return figures


def predictive_figures(model, obs, samples, folder: Path,
                       draws: int = PREDICTIVE_DRAWS, seed: int = 0) -> list[Figure]:
    """Per camera: the observation beside simulations of it from ``draws`` posterior samples
    (evenly spaced), each rendered and given sensor noise at the sample's own noise scales,
    as ``sppl simulate`` makes observations. ``seed`` fixes the noise, so a report is
    reproducible."""
    from ..data.observations import CameraSpec
    from ..model.simulate import objects_from_dict, render_observations
    from ..render import Renderer

    chosen = evenly(samples, draws)
    specs = [CameraSpec(f.camera, f.modalities) for f in obs.frames]
    rng = np.random.default_rng(seed)
    renderer = Renderer(model.render)
    try:
        simulated = [render_observations(
            model, objects_from_dict(model, {"objects": s["objects"]}, "a stored sample"),
            s["noise"], specs, renderer, rng) for s in chosen]
    finally:
        renderer.release()
    figures = []
    for k, frame in enumerate(obs.frames):
        rows = [m for m in ("rgb", "depth") if getattr(frame, m) is not None]
        fig = _figure(2.4 * (len(chosen) + 1), 2.5 * len(rows))
        axes = fig.subplots(len(rows), len(chosen) + 1, squeeze=False)
        for row, modality in zip(axes, rows):
            for col, (ax, f) in enumerate(zip(row, [frame, *(sim[k] for sim in simulated)])):
                if modality == "rgb":
                    ax.imshow(np.clip(f.rgb, 0, 1), interpolation="nearest")
                else:
                    valid = f.depth_valid if f.depth_valid is not None else np.isfinite(f.depth)
                    ax.imshow(np.where(valid, f.depth, np.nan), cmap="viridis_r", vmin=0,
                              vmax=frame.camera.depth_max, interpolation="nearest")
                s = chosen[col - 1] if col else None
                ax.set_title(f"{frame.name}: observed {modality}" if s is None else
                             f"sample at sweep {s['step']}: {len(s['objects'])} object"
                             f"{'s' if len(s['objects']) != 1 else ''}", fontsize=9)
                ax.set_xticks([])
                ax.set_yticks([])
        figures.append(Figure(
            _save(fig, folder, f"predictive_{_safe(frame.name)}.png"),
            f"Camera {frame.name}: posterior predictive",
            f"Left, the observation; then {len(chosen)} posterior samples (evenly spaced over "
            "every chain after burn-in) rendered from this camera with sensor noise drawn at "
            "each sample's own noise scale, as sppl simulate makes observations.",
        ))
    return figures


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name)


def counts_figure(post, truth, folder: Path) -> Figure:
    n = post.variables["n_objects"].ravel()
    counts = post.variables["count"].reshape(-1, len(post.class_names))
    fig = _figure(9.0, 3.0)
    ax0, ax1 = fig.subplots(1, 2)
    ks = np.arange(0, max(int(n.max()), 1) + 1)
    probs = np.array([(n == k).mean() for k in ks])
    ax0.bar(ks, probs, color="#4c72b0")
    if truth is not None:
        ax0.axvline(len(truth), color="#c44e52", ls="--", label="true count")
        ax0.legend(frameon=False)
    ax0.set_xlabel("number of objects")
    ax0.set_ylabel("posterior probability")
    ax0.set_xticks(ks)
    ax0.set_ylim(0, 1)
    kmax = max(int(counts.max()), 1)
    width = 0.8 / max(len(post.class_names), 1)
    true_counts = Counter(o["class"] for o in truth) if truth is not None else None
    for i, c in enumerate(post.class_names):
        ks = np.arange(0, kmax + 1)
        p = [(counts[:, i] == k).mean() for k in ks]
        bars = ax1.bar(ks + (i - (len(post.class_names) - 1) / 2) * width, p, width, label=c)
        if true_counts is not None:
            t = true_counts.get(c, 0)
            ax1.plot([t + (i - (len(post.class_names) - 1) / 2) * width], [1.02], "v",
                     color=bars.patches[0].get_facecolor(), clip_on=False)
    ax1.set_xlabel("number of objects of the class")
    ax1.set_xticks(np.arange(0, kmax + 1))
    ax1.set_ylim(0, 1)
    ax1.legend(frameon=False, title="class" + (" (▼ truth)" if truth is not None else ""))
    return Figure(
        _save(fig, folder, "counts.png"), "How many objects, of which classes",
        "Posterior probability of the number of objects (left) and of each class's count "
        "(right), over every chain's samples after burn-in.",
    )


def _footprint(model, o: dict[str, Any]) -> np.ndarray | None:
    try:
        cls = model.object_class(o["class"])
        return np.asarray(cls.footprint(o["params"]), dtype=float)
    except Exception:  # noqa: BLE001 - a class without a footprint is drawn without one
        return None


def occupancy_grid(model, samples: Sequence[dict[str, Any]], extent, cells: int = 160):
    """P(ground cell covered by some object) over ``samples``: (cells, cells) array, rows y."""
    import shapely

    x0, x1, y0, y1 = extent
    xs = np.linspace(x0, x1, cells + 1)[:-1] + (x1 - x0) / cells / 2
    ys = np.linspace(y0, y1, cells + 1)[:-1] + (y1 - y0) / cells / 2
    gx, gy = np.meshgrid(xs, ys)
    total = np.zeros(gx.shape)
    cache: dict[str, Any] = {}
    for s in samples:
        covered = np.zeros(gx.shape, dtype=bool)
        for o in s["objects"]:
            key = json.dumps(o, sort_keys=True)
            if key not in cache:
                fp = _footprint(model, o)
                cache[key] = None if fp is None or len(fp) < 3 else shapely.Polygon(fp)
            poly = cache[key]
            if poly is not None:
                covered |= shapely.contains_xy(poly, gx, gy)
        total += covered
    return total / max(len(samples), 1)


def _extent(model, objects: list[dict[str, Any]], cameras) -> tuple[float, float, float, float]:
    pts = [np.zeros(2)]
    for o in objects:
        fp = _footprint(model, o)
        pts += list(fp) if fp is not None else [_xy(model, o)]
    lo, hi = np.min(pts, axis=0) - 1.0, np.max(pts, axis=0) + 1.0
    for cam in cameras:  # cameras near the scene are drawn too
        c = cam.position[:2]
        if np.all(np.abs(c - (lo + hi) / 2) < 6.0):
            lo, hi = np.minimum(lo, c - 0.3), np.maximum(hi, c + 0.3)
    centre, half = (lo + hi) / 2, max(hi - lo) / 2
    return (centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half)


def plot_occupancy(ax, model, samples, map_objects, truth, cameras, extent=None):
    """Draw the occupancy map on ``ax``; returns the image for a colour bar."""
    extent = extent or _extent(model, list(map_objects) + list(truth or []), cameras)
    grid = occupancy_grid(model, samples, extent)
    im = ax.imshow(grid, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1)
    for objs, style, label in ((map_objects, {"color": "#1f77b4", "ls": "--", "lw": 1.4}, "MAP"),
                               (truth or [], {"color": "#d62728", "ls": "-", "lw": 1.4}, "truth")):
        first = True
        for o in objs:
            fp = _footprint(model, o)
            if fp is None:
                continue
            ring = np.vstack([fp, fp[:1]])
            ax.plot(ring[:, 0], ring[:, 1], label=label if first else None, **style)
            first = False
    for cam in cameras:
        c, forward = cam.position, -cam.c2w[:3, 2]
        if extent[0] <= c[0] <= extent[1] and extent[2] <= c[1] <= extent[3]:
            ax.plot(c[0], c[1], marker="^", color="#2ca02c")
            ax.annotate(cam.name, (c[0], c[1]), textcoords="offset points", xytext=(4, 4),
                        fontsize=8, color="#2ca02c")
            f = forward[:2] / (np.linalg.norm(forward[:2]) or 1.0)
            ax.arrow(c[0], c[1], 0.5 * f[0], 0.5 * f[1], color="#2ca02c", width=0.01,
                     head_width=0.08)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    return im


def occupancy_figure(model, samples, map_objects, truth, cameras, folder: Path) -> Figure:
    fig = _figure(6.0, 5.2)
    ax = fig.subplots()
    draws = evenly(samples, OCCUPANCY_DRAWS)
    im = plot_occupancy(ax, model, draws, map_objects, truth, cameras)
    fig.colorbar(im, ax=ax, label="P(covered)", shrink=0.85)
    return Figure(
        _save(fig, folder, "occupancy.png"), "Where the objects are: a top-down occupancy map",
        f"Grey level: the fraction of {len(draws)} posterior samples in which an object's "
        "footprint covers that point of the ground. Dashed blue: the MAP scene's footprints"
        + ("; solid red: the true ones" if truth else "")
        + "; green: the cameras (those within the map) and where they look.",
    )


def match_to_map(model, map_objects, samples, radius: float = MATCH_RADIUS):
    """For each MAP object, the matching object of each sample (or None): optimal assignment
    by ground distance among objects of the same class, within ``radius`` metres."""
    from scipy.optimize import linear_sum_assignment

    matches: list[list[dict[str, Any] | None]] = [[] for _ in map_objects]
    map_xy = [_xy(model, o) for o in map_objects]
    for s in samples:
        objs = s["objects"]
        found: list[dict | None] = [None] * len(map_objects)
        if objs and map_objects:
            big = 1e6
            cost = np.full((len(map_objects), len(objs)), big)
            for i, m in enumerate(map_objects):
                for j, o in enumerate(objs):
                    if o["class"] == m["class"]:
                        d = float(np.linalg.norm(_xy(model, o) - map_xy[i]))
                        if d <= radius:
                            cost[i, j] = d
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols):
                if cost[r, c] < big:
                    found[r] = objs[c]
        for i in range(len(map_objects)):
            matches[i].append(found[i])
    return matches


def marginal_figures(model, map_objects, samples, truth, folder: Path) -> list[Figure]:
    from matplotlib.ticker import MaxNLocator

    draws = evenly(samples, MARGINAL_DRAWS)
    matches = match_to_map(model, map_objects, draws)
    true_of = {}
    if truth:
        for e, t, _ in match_objects(map_objects, truth, max_distance=MATCH_RADIUS):
            true_of[e] = truth[t]
    figures = []
    for k, (m, found) in enumerate(zip(map_objects, matches)):
        hits = [o for o in found if o is not None]
        names = list(m["params"])
        fig = _figure(2.4 * max(len(names), 2), 2.5)
        axes = np.atleast_1d(fig.subplots(1, max(len(names), 1)))
        t = true_of.get(k)
        for ax, name in zip(axes, names):
            values = [o["params"][name] for o in hits if name in o["params"]]
            if isinstance(m["params"][name], str):
                levels = sorted(set(values) | {m["params"][name]})
                freq = Counter(values)
                ax.bar(levels, [freq[v] / max(len(values), 1) for v in levels], color="#4c72b0")
                ax.set_ylim(0, 1)
                if t is not None and name in t["params"]:
                    ax.set_title(f"{name} (true: {t['params'][name]})", fontsize=9)
                else:
                    ax.set_title(name, fontsize=9)
            else:
                marks = [float(m["params"][name])]
                if t is not None and name in t["params"]:
                    marks.append(float(t["params"][name]))
                lo, hi = min([*values, *marks]), max([*values, *marks])
                pad = max(0.08 * (hi - lo), 0.01 * max(1.0, abs(hi)))
                if values:
                    ax.hist(values, bins=np.linspace(lo - pad, hi + pad, 41), color="#4c72b0",
                            alpha=0.85)
                ax.axvline(marks[0], color="black", ls="--", lw=1.2, label="MAP")
                if len(marks) > 1:
                    ax.axvline(marks[1], color="#d62728", lw=1.4, label="truth")
                ax.set_xlim(lo - pad, hi + pad)
                ax.set_title(name, fontsize=9)
                ax.set_yticks([])
                # A panel is 2.4 in wide: at most four ticks, or their labels run together.
                ax.xaxis.set_major_locator(MaxNLocator(nbins=3))
                ax.tick_params(axis="x", labelsize=8)
        continuous = [ax for ax, name in zip(axes, names) if not isinstance(m["params"][name], str)]
        if continuous:
            continuous[0].legend(fontsize=7, frameon=False)
        fig.suptitle(f"MAP object {k}: {m['class']}; a matching object in "
                     f"{len(hits) / max(len(draws), 1):.0%} of samples", fontsize=10)
        figures.append(Figure(
            _save(fig, folder, f"object_{k}_{_safe(m['class'])}.png"),
            f"MAP object {k}: {m['class']}",
            f"The posterior of each parameter over the samples that hold an object of class "
            f"{m['class']} within {MATCH_RADIUS} m of this one (one per sample, by optimal "
            "assignment). Dashed: the MAP value" + ("; red: the true value." if t else "."),
        ))
    return figures


def trace_figure(run: RunFiles, folder: Path) -> Figure:
    return Figure(
        _save(trace_plot(run), folder, "traces.png"), "Traces",
        "Each stored sweep of each chain (one colour a chain). The dotted line is the end of "
        "burn-in: only samples after it enter the posterior summaries. Chains that have "
        "converged wander over the same range; one stuck elsewhere shows as a separate band.",
    )


def trace_plot(run: RunFiles):
    """The trace figure: one row each for the log joint, the number of objects and each
    noise scale, one line a chain in that chain's colour (``CHAIN_COLOURS``)."""
    noise_names = [(kind, name) for kind, ps in run.chains[0].samples[0]["noise"].items()
                   for name in ps] if run.chains[0].samples else []
    rows = ["log joint", "number of objects", *[f"{k}.{n}" for k, n in noise_names]]
    fig = _figure(9.0, 1.9 * len(rows))
    axes = np.atleast_1d(fig.subplots(len(rows), 1, sharex=True))
    burn = run.burn
    lp_tail = []
    for i, chain in enumerate(run.chains):
        colour = CHAIN_COLOURS[i % len(CHAIN_COLOURS)]
        steps = np.array([s["step"] for s in chain.samples])
        series = [np.array([s["score"] for s in chain.samples]),
                  np.array([len(s["objects"]) for s in chain.samples])]
        series += [np.array([s["noise"][k][n] for s in chain.samples]) for k, n in noise_names]
        lp_tail += list(series[0][steps >= burn // 2])
        for j, (ax, y) in enumerate(zip(axes, series)):
            if j == 1:
                ax.step(steps, y, where="post", color=colour, lw=0.8, alpha=0.85,
                        label=f"chain {i}")
            else:
                ax.plot(steps, y, color=colour, lw=0.7, alpha=0.85)
    if lp_tail:  # the first sweeps climb from far below; show the part that matters
        lo, hi = np.percentile(lp_tail, [0.5, 100])
        pad = 0.1 * (hi - lo) + 1.0
        axes[0].set_ylim(lo - pad, hi + pad)
    for ax, label in zip(axes, rows):
        ax.set_ylabel(label, fontsize=9)
        if burn:
            ax.axvline(burn, color="grey", ls=":", lw=1)
    axes[-1].set_xlabel("sweep")
    if len(run.chains) > 1:
        axes[1].legend(fontsize=7, ncol=min(len(run.chains), 6), frameon=False, loc="upper right")
    return fig


def acceptance_figure(summary: dict[str, Any], folder: Path) -> Figure:
    table = _acceptance_table(summary)
    moves = list(table)
    labels = sorted({lab for m in table.values() for lab in m if lab != "all"})
    fig = _figure(max(5.0, 1.1 * len(moves) + 2), 3.0)
    ax = fig.subplots()
    width = 0.8 / max(len(labels), 1)
    for i, lab in enumerate(labels):
        xs = [k + (i - (len(labels) - 1) / 2) * width for k in range(len(moves))]
        ys = [table[m][lab][1] / table[m][lab][0] if lab in table[m] and table[m][lab][0] else 0
              for m in moves]
        ax.bar(xs, ys, width, label=lab)
    ax.set_xticks(range(len(moves)), moves)
    ax.set_ylabel("acceptance rate")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, frameon=False, ncol=3)
    return Figure(
        _save(fig, folder, "acceptance.png"), "Acceptance rates",
        "The fraction of proposals of each move type accepted, per class (objects) or sensor "
        "(noise), over all sweeps of all chains.",
    )


def _acceptance_table(summary: dict[str, Any]) -> dict[str, dict[str, tuple[int, int]]]:
    table: dict[str, dict[str, tuple[int, int]]] = {}
    for key, c in summary["acceptance_by_class"].items():
        move, _, label = key.partition("/")
        row = table.setdefault(move, {})
        row[label or "-"] = (c["proposed"], c["accepted"])
        n, a = row.get("all", (0, 0))
        row["all"] = (n + c["proposed"], a + c["accepted"])
    # Face moves beside the random walk whose steps they complement; moves not named here
    # (the fitted jumps) after these, by name.
    order = ["birth", "death", "change", "parameters", "face", "noise", "render"]
    return dict(sorted(table.items(), key=lambda kv: (order.index(kv[0]) if kv[0] in order else 99,
                                                       kv[0])))


# ----------------------------------------------------------------------------------------------
# Tables


def _rate(n: int, a: int) -> str:
    return f"{a / n:.3f} <small>({a}/{n})</small>" if n else "–"


def acceptance_html(summary: dict[str, Any]) -> str:
    """Two tables: the object moves by class, and the noise moves by sensor (one table for
    both had a column per class and per sensor, half of them empty in every row)."""
    table = _acceptance_table(summary)
    objects = {m: cells for m, cells in table.items() if m != "noise"}
    noise = {m: cells for m, cells in table.items() if m == "noise"}
    return (_rates_table("move", objects, "class") + _rates_table("move", noise, "sensor"))


def _rates_table(corner: str, table: dict[str, dict[str, tuple[int, int]]], per: str) -> str:
    if not table:
        return ""
    labels = sorted({lab for m in table.values() for lab in m if lab != "all"})
    head = "".join(f"<th>{html.escape(lab)}</th>" for lab in [*labels, "all"])
    rows = []
    for move, cells in table.items():  # a class a move never reached: proposed 0 times
        tds = "".join(f"<td>{_rate(*cells.get(lab, (0, 0)))}</td>" for lab in [*labels, "all"])
        rows.append(f"<tr><th>{html.escape(move)}</th>{tds}</tr>")
    return (f"<table><tr><th>{corner} \\ {per}</th>{head}</tr>{''.join(rows)}</table>")


def diagnostics_html(diag: dict[str, dict[str, float | None]], n_chains: int) -> str:
    def f(v, spec):
        return "–" if v is None else format(v, spec)

    rows = []
    for name, d in diag.items():
        bad = d["rhat"] is not None and d["rhat"] > 1.01
        cls = ' class="warn"' if bad else ""
        rows.append(
            f"<tr{cls}><th>{html.escape(name)}</th><td>{f(d['mean'], '.4g')}</td>"
            f"<td>{f(d['sd'], '.3g')}</td><td>{f(d['rhat'], '.3f')}</td>"
            f"<td>{f(d['ess_bulk'], '.0f')}</td><td>{f(d['ess_tail'], '.0f')}</td></tr>"
        )
    note = ("" if n_chains > 1 else
            "<p class='note'>R-hat compares chains: run with <code>--chains 4</code> "
            "to get it.</p>")
    return (
        "<table><tr><th>quantity</th><th>mean</th><th>sd</th><th>R-hat</th>"
        f"<th>bulk ESS</th><th>tail ESS</th></tr>{''.join(rows)}</table>{note}"
    )


def truth_rows(model, map_objects, truth) -> dict[str, Any]:
    """The MAP against the truth: summary numbers and one row per true or MAP object."""
    errors = compare_scenes(map_objects, truth)
    pairs = match_objects(map_objects, truth)
    rows = []
    matched_e, matched_t = set(), set()
    for e, t, d in pairs:
        matched_e.add(e)
        matched_t.add(t)
        me, tt = map_objects[e], truth[t]
        px, py = _position_names(model, tt["class"])
        sizes = {}
        for name, v in tt["params"].items():
            if name in (px, py) or isinstance(v, str) or name not in me["params"]:
                continue
            p = _parameter(model, tt["class"], name)
            if p is not None and "periodic" in type(p.domain).__name__.lower():
                continue  # an angle, not a size
            sizes[name] = float(me["params"][name]) - float(v)
        cats = {k: (me["params"].get(k), v) for k, v in tt["params"].items() if isinstance(v, str)}
        rows.append({"true": t, "map": e, "true_class": tt["class"], "map_class": me["class"],
                     "categories": cats, "position_error": d, "size_errors": sizes})
    missed = [truth[t] for t in range(len(truth)) if t not in matched_t]
    extra = [map_objects[e] for e in range(len(map_objects)) if e not in matched_e]
    return {"errors": errors, "rows": rows, "missed": missed, "extra": extra}


def _parameter(model, class_name, name):
    try:
        return model.object_class(class_name).parameter(name)
    except KeyError:
        return None


def truth_html(model, map_objects, truth, tolerance: float = TOLERANCE) -> str:
    t = truth_rows(model, map_objects, truth)
    e = t["errors"]
    verdict = "right" if e.correct(tolerance) else "not right"
    head = (
        f"<p>Objects: MAP {e.n_estimated}, true {e.n_true}; matched pairs with the wrong class: "
        f"{e.wrong_class}, with the wrong colour (or other category): {e.wrong_category}; "
        f"largest position error {e.max_position_error:.3f} m. By the benchmark's criterion "
        f"(right count, classes and colours, every position within {tolerance:g} m) the MAP scene is "
        f"<b>{verdict}</b>.</p>"
    )
    rows = []
    for r in t["rows"]:
        cats = ", ".join(f"{k}: {html.escape(str(a))} / {html.escape(str(b))}"
                         for k, (a, b) in r["categories"].items())
        sizes = ", ".join(f"{k}: {v:+.3f}" for k, v in r["size_errors"].items())
        ok = "" if r["true_class"] == r["map_class"] else ' class="warn"'
        rows.append(
            f"<tr{ok}><td>{r['true']}</td><td>{html.escape(r['true_class'])}</td>"
            f"<td>{html.escape(r['map_class'])}</td><td>{cats}</td>"
            f"<td>{r['position_error']:.3f}</td><td>{sizes}</td></tr>"
        )
    for o in t["missed"]:
        rows.append(f"<tr class='warn'><td></td><td>{html.escape(o['class'])}</td><td>missed</td>"
                    "<td></td><td></td><td></td></tr>")
    for o in t["extra"]:
        rows.append(f"<tr class='warn'><td></td><td>none</td><td>{html.escape(o['class'])} "
                    "(extra)</td><td></td><td></td><td></td></tr>")
    return head + (
        "<table><tr><th>true object</th><th>true class</th><th>MAP class</th>"
        "<th>category (MAP / true)</th><th>position error (m)</th>"
        "<th>size error, MAP − true (m)</th></tr>" + "".join(rows) + "</table>"
    )


# ----------------------------------------------------------------------------------------------
# The page

CSS = """
body { font-family: system-ui, sans-serif; max-width: 1000px; margin: 2em auto; padding: 0 1em;
       color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ddd; }
img { max-width: 100%; display: block; margin: 0.5em 0; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; }
tr.warn td, tr.warn th { background: #fde8e8; }
.partial { background: #fde8e8; border: 2px solid #c00; padding: 0.5em; font-weight: bold; }
pre { background: #f6f6f6; padding: 0.8em; font-size: 0.85em; white-space: pre-wrap;
      overflow-wrap: anywhere; }  /* long summary lines wrap, never cut off */
.caption, .note { color: #555; font-size: 0.92em; }
.explain { background: #f3f7fb; border-left: 3px solid #4c72b0; padding: 0.5em 0.8em; }
"""


# What each part of the page means, for a reader learning the method: one paragraph each,
# shown above the part it explains.
EXPLAIN = {
    "intro": (
        "sppl does not return one answer but a <b>posterior</b>: many complete guesses at the "
        "scene (the <b>samples</b>), each a set of objects with classes, positions, sizes and "
        "colours, drawn by Markov chain Monte Carlo so that a scene appears among them in "
        "proportion to its posterior probability: how well it explains the images, times how "
        "plausible the model's prior finds it. A question about the scene is answered by "
        "counting over the samples (\"is there a cube on the left?\" is the fraction of samples "
        "that have one). The <b>MAP</b> scene, the most probable one the chains visited, is a "
        "convenient summary, not the answer."
    ),
    "view": (
        "Solid: the MAP scene. Translucent <b>ghosts</b>: posterior samples (evenly spaced over "
        "every chain after burn-in), each drawn faintly, so that an object on which all the "
        "samples agree stacks up into a nearly solid shape while one they disagree about is a "
        "faint cloud. Ghosts spread where the images do not pin the scene down: along a "
        "camera's line of sight (an RGB camera sees direction well but distance poorly), "
        "behind other objects, and outside every camera's view (the green frusta), where no "
        "image says anything and the prior alone decides whether an object is there. Black "
        "edges: the true scene, when the observation folder has one. The slider replays a "
        "chain: each step is a sweep at which the chain found a scene better (a higher log "
        "joint) than any before, from its start to its best. Drag to turn the view, "
        "shift-drag or right-drag to move it, scroll to zoom, double-click to go back; "
        "\"look through\" puts you where a camera is."
    ),
    "cameras": (
        "The <b>residual</b> is what the MAP scene leaves unexplained. If the MAP were the "
        "truth it would be the sensor noise alone: a fine speckle with no shape, its RMS close "
        "to the inferred noise scale (in the summary above). A shape in it is a mistake: a "
        "blob where an object was missed, a pair of opposite-signed crescents at the edges of "
        "a misplaced one, a rim around one of the wrong size."
    ),
    "predictive": (
        "A <b>posterior predictive</b> check: if the model fits and the chains have converged, "
        "observations simulated from posterior samples look like the real one, noise "
        "included. Differences between the simulations show the posterior's uncertainty (an "
        "object present in some samples and not others); a difference all of them share "
        "with the observation shows something the model, or the sampler, gets wrong."
    ),
    "counts": (
        "The fraction of samples with each number of objects, and of each class. Objects "
        "that no camera sees cost the likelihood nothing, so where the prior allows objects "
        "outside the cameras' view, samples keep some there: the total count can be larger "
        "and less certain than the number of objects the images show."
    ),
    "traces": (
        "A chain starts from a scene that explains nothing (an empty one, or only the objects "
        "a model says are always there) and climbs; the first sweeps (<b>burn-in</b>, "
        "before the dotted line) still remember that start and are left out of every summary. "
        "After it, a chain that has converged wanders over a steady band. Several chains "
        "started independently should wander over the same band: one on a band of its own is "
        "stuck in another explanation of the images (a <b>mode</b>), and the summaries that mix "
        "it in cannot be trusted yet."
    ),
    "convergence": (
        "A move rarely accepted barely moves the chain; one almost always accepted takes steps "
        "too small to go far. Births and deaths are accepted rarely once the images are "
        "explained, which is expected: most objects proposed at random contradict them. "
        "<b>R-hat</b> compares the spread between chains with the spread within each: when "
        "every chain explores the same distribution they are equal and R-hat is 1; above 1.01 "
        "the chains disagree, so run longer (or more chains) and look at the traces. "
        "<b>ESS</b> (effective sample size) is how many independent draws the chain's "
        "correlated samples are worth: an estimate from an ESS of 20 is as rough as one from "
        "20 draws, however many sweeps were run."
    ),
}


def _explain(key: str) -> str:
    return f"<p class='explain'>{EXPLAIN[key]}</p>"


def _figure_html(f: Figure) -> str:
    return (f"<figure><img src=\"{html.escape(f.file)}\" alt=\"{html.escape(f.title)}\">"
            f"<figcaption class='caption'>{html.escape(f.caption)}</figcaption></figure>")


def load_truth(truth: Path | bool | None, obs_root: Path) -> list[dict[str, Any]] | None:
    if truth is False:
        return None
    path = Path(truth) if truth not in (None, True) else obs_root / "scene.json"
    if truth in (None, True) and not path.exists():
        return None
    try:
        return json.loads(path.read_text())["objects"]
    except FileNotFoundError:
        raise SpplError(f"{path}: no such scene file") from None
    except (json.JSONDecodeError, KeyError, TypeError):
        raise SpplError(f"{path}: not a scene file ({{\"objects\": [...]}})") from None


def seen_html(summary: dict[str, Any]) -> str:
    """The posterior over the number of objects some camera sees, in all and per class, as a
    table, with the unseen objects the prior adds (``sppl.render.seen``); "" without seen marks."""
    if "n_seen" not in summary:
        return ""
    rows = {"all classes": summary["n_seen"], **summary["seen_class_counts"]}
    ks = sorted({int(k) for d in rows.values() for k in d})
    head = "".join(f"<th>{k}</th>" for k in ks)
    body = "".join(
        f"<tr><td>{html.escape(name)}</td>"
        + "".join(f"<td>{d.get(str(k), 0.0):.2f}</td>" for k in ks) + "</tr>"
        for name, d in rows.items())
    u = summary["unseen"]
    return (
        "<h2>What the cameras see</h2><p class='note'>Posterior probability of the number of "
        "objects that some camera sees (at least one pixel, after occlusion). Objects no "
        "camera sees are the prior's alone: the prior adds "
        f"{u['mean']:.2f} of them on average (none in {u['p_none']:.0%} of samples).</p>"
        f"<table><tr><th>objects seen</th>{head}</tr>{body}</table>"
    )


def write_report(
    run_folder: str | Path,
    *,
    out: str | Path | None = None,
    truth: Path | bool | None = None,
    model_path: Path | None = None,
    obs_path: Path | None = None,
) -> Path:
    """Write ``out/index.html`` (default ``run_folder/report``) and its figures; return the
    page's path. ``truth``: a scene file, False for none, None for ``obs/scene.json`` if any."""
    from ..data.observations import load_observations
    from ..lang import load_model

    run_folder = Path(run_folder)
    run = load_run(run_folder)
    model = load_model(_resolve(model_path, run.meta.get("model"), "model", "--model", run_folder))
    obs = load_observations(
        _resolve(obs_path, run.meta.get("observations"), "observation folder", "--obs", run_folder))
    true_objects = load_truth(truth, obs.root)
    folder = Path(out) if out is not None else run_folder / "report"
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("*.png"):
        old.unlink()

    summary = run.summary
    map_objects = (summary.get("map") or {}).get("objects", [])
    post = posterior_arrays(run)
    diag = diagnostics(post)
    samples = pooled_samples(run)
    sections: list[str] = []

    from .report_view import GHOST_DRAWS, view_data, view_html

    extent = _extent(model, list(map_objects) + list(true_objects or []), obs.cameras)
    view = view_data(model, run, map_objects, true_objects, evenly(samples, GHOST_DRAWS),
                     obs.cameras, extent)
    sections.append("<h2>The scene in 3D: the MAP and posterior samples</h2>"
                    + _explain("view") + view_html(view, folder))
    try:
        cams = camera_figures(model, obs, map_objects, folder,
                              (summary.get("map") or {}).get("noise"))
        cam_html = "".join(_figure_html(f) for f in cams)
        predictive = predictive_figures(model, obs, samples, folder)
        predictive_html = "".join(_figure_html(f) for f in predictive)
    except RenderError as e:
        cam_html = predictive_html = f"<p class='note'>No renders: {html.escape(str(e))}</p>"
    sections.append(f"<h2>The cameras: observed, MAP, residual</h2>{_explain('cameras')}"
                    f"{cam_html}")
    sections.append("<h2>Posterior predictive: simulated observations beside the real "
                    f"ones</h2>{_explain('predictive')}{predictive_html}")
    sections.append(seen_html(summary))
    sections.append("<h2>The posterior over counts</h2>" + _explain("counts")
                    + _figure_html(counts_figure(post, true_objects, folder)))
    sections.append("<h2>Occupancy</h2>" + _figure_html(
        occupancy_figure(model, samples, map_objects, true_objects, obs.cameras, folder)))
    marg = marginal_figures(model, map_objects, samples, true_objects, folder)
    sections.append("<h2>Each MAP object's parameters</h2>"
                    + ("".join(_figure_html(f) for f in marg) or "<p>The MAP scene is empty.</p>"))
    sections.append("<h2>Traces</h2>" + _explain("traces")
                    + _figure_html(trace_figure(run, folder)))
    sections.append(
        "<h2>Moves and convergence</h2>" + _explain("convergence")
        + "<h3>Acceptance rates</h3>" + acceptance_html(summary)
        + _figure_html(acceptance_figure(summary, folder))
        + "<h3>R-hat and effective sample size</h3>"
        "<p class='note'>Computed only for quantities that do not depend on how the objects "
        "are numbered (the scene is a set). R-hat compares the chains: near 1 (below 1.01) "
        "means they agree; ESS is how many independent draws the correlated samples are "
        "worth (bulk: for the mean and median; tail: for the 5% and 95% quantiles).</p>"
        + diagnostics_html(diag, post.n_chains)
    )
    if true_objects is not None:
        sections.append("<h2>The MAP scene against the truth</h2>"
                        + truth_html(model, map_objects, true_objects))

    from .report_view import VIEW_CSS
    from .samples import format_summary

    meta = run.meta
    n_chains = len(run.chains)
    info = (
        f"<p>Model <code>{html.escape(str(meta.get('model')))}</code>, observations "
        f"<code>{html.escape(str(meta.get('observations')))}</code> "
        f"({len(obs.frames)} camera{'s' if len(obs.frames) != 1 else ''}); {n_chains} "
        f"chain{'s' if n_chains != 1 else ''} of {meta.get('steps')} sweeps, seed "
        f"{html.escape(json.dumps(meta.get('seed')))}; {post.n_draws} draws per chain after "
        f"burn-in of {run.burn} sweeps.</p>"
    )
    # A run with too few samples after burn-in says so before anything else (sppl.output.samples).
    partial = (f"<p class='partial'>PARTIAL SUMMARY: {html.escape(summary['partial'])}</p>"
               if summary.get("partial") else "")
    page = (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>sppl report: {html.escape(run_folder.name)}</title>"
        f"<style>{CSS}{VIEW_CSS}</style></head>"
        f"<body><h1>sppl report: {html.escape(str(run_folder))}</h1>"
        f"{partial}{info}{_explain('intro')}"
        f"<pre>{html.escape(format_summary(summary))}</pre>{''.join(sections)}</body></html>\n"
    )
    index = folder / "index.html"
    index.write_text(page, encoding="utf-8")
    return index
