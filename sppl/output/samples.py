"""Samples on disk, and the summary of a run.

Samples are streamed to ``samples.jsonl`` as they are drawn, one JSON object a line, each
handed to the operating system as soon as it is written: a run killed at any moment (even by
SIGKILL) loses at most the sweep it was drawing, and leaves a file whose complete lines are all
valid samples (a torn last line is skipped on reading). ``sync`` also forces them to the disk,
which a checkpoint does first, so that a power cut loses nothing before the last checkpoint. ``summary.json`` holds what a user
asks first: the posterior over the number of objects some camera sees (each sample's objects
are marked seen or not), the MAP scene, the posterior over the number of objects and over
classes, the acceptance rate per move type, and the noise scales.

The posterior parts of a summary are made of the samples after burn-in only, never of the
warm-up's (``sppl.infer.warmup``: its adapted, annealed sweeps do not target the posterior). A run
that has too few of them (stopped during its warm-up, or given fewer ``--steps`` than its
burn-in) gets a summary marked ``partial``, with the reason, in ``summary.json``, at the top of
``summary.txt`` and of the report, and in ``posterior.nc``'s attributes; with none at all it
has no posterior numbers, only the MAP scene and the move counts.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..model.trace import Trace


class SampleWriter:
    """Appends samples to a ``samples.jsonl``, flushing each one to the operating system.

    A flush is one ``write`` system call of a few hundred bytes, negligible beside a sweep's
    renders, and it makes what a SIGKILL loses exactly the samples not yet drawn.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.file = open(path, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())
        self.last_step = 0  # the step of the last sample handed to the operating system

    def write(self, step: int, trace: Trace, seen: list[bool] | None = None) -> None:
        """One sample; ``seen`` marks which of its objects some camera sees."""
        record = {
            "step": step,
            "score": trace.score,
            "log_likelihood": trace.log_likelihood,
            **trace.as_dict(seen),
        }
        self.file.write(json.dumps(record) + "\n")
        self.file.flush()
        self.last_step = step

    def sync(self) -> None:
        """Force every sample written so far onto the disk."""
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.flush()
        self.file.close()


def truncate_samples(path: Path, last_step: int) -> int:
    """Cut ``samples.jsonl`` after the last sample of a step <= ``last_step`` (a resumed chain
    draws the later ones again), dropping a torn last line too. Returns the samples kept."""
    if not path.exists():
        return 0
    kept = end = 0
    with open(path, "rb") as f:
        for line in f:
            try:
                if not line.endswith(b"\n") or json.loads(line)["step"] > last_step:
                    break
            except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError):
                break
            kept += 1
            end += len(line)
    os.truncate(path, end)
    return kept


def read_samples(path: str | Path) -> list[dict[str, Any]]:
    """All complete samples of a ``samples.jsonl`` (a half-written last line is ignored)."""
    out = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                break
    return out


# A summary of fewer samples after burn-in than this is marked partial: its posterior shares are
# multiples of 1/n too coarse to read (10% steps at 10), and R-hat and ESS are not computed below
# 4 draws a chain.
MIN_SAMPLES = 10


def partial_reason(n: int, burn: int) -> str | None:
    """Why a summary of ``n`` samples after a burn-in of ``burn`` steps is partial, or None."""
    if n == 0:
        return (f"no samples after the burn-in of {burn} steps, so no posterior: the run ended "
                "before its burn-in did (more --steps, or --resume the run with more)")
    if n < MIN_SAMPLES:
        return (f"only {n} sample{'s' if n != 1 else ''} after the burn-in of {burn} steps "
                f"(fewer than {MIN_SAMPLES}): the posterior below is rough")
    return None


def _class_key(objects: Iterable[dict]) -> str:
    names = sorted(o["class"] for o in objects)
    return " + ".join(names) if names else "(empty)"


def summarise(
    samples: list[dict[str, Any]],
    class_names: Iterable[str],
    map_sample: dict[str, Any] | None,
    move_stats: dict[str, dict[str, int]],
    *,
    burn: int = 0,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The run's summary from its samples after ``burn`` steps (the MAP is over all steps).
    Samples before ``burn`` never enter it, however few are left (see ``partial_reason``)."""
    kept = [s for s in samples if s["step"] >= burn]
    n = len(kept)
    count_post = Counter(len(s["objects"]) for s in kept)
    per_class = {
        c: dict(sorted(Counter(sum(o["class"] == c for o in s["objects"]) for s in kept).items()))
        for c in class_names
    }
    configs = Counter(_class_key(s["objects"]) for s in kept)
    seen = seen_summary(kept, class_names)
    noise: dict[str, dict[str, dict[str, float]]] = {}
    for s in kept:
        for kind, params in s["noise"].items():
            for name, v in params.items():
                noise.setdefault(kind, {}).setdefault(name, []).append(v)
    noise_summary = {
        kind: {name: {"mean": float(np.mean(v)), "sd": float(np.std(v))} for name, v in ps.items()}
        for kind, ps in noise.items()
    }
    by_move: dict[str, list[int]] = {}
    for key, c in move_stats.items():
        move = key.split("/")[0]
        acc = by_move.setdefault(move, [0, 0, 0])
        acc[0] += c["proposed"]
        acc[1] += c["accepted"]
        acc[2] += c.get("nan", 0)  # rejected because their ratio was NaN
    return {
        **(extra or {}),
        "samples_used": n,
        "burn": burn,
        "partial": partial_reason(n, burn),
        "map": map_sample,
        **seen,
        "n_objects": {str(k): v / n for k, v in sorted(count_post.items())} if n else {},
        "class_counts": {c: {str(k): v / n for k, v in d.items()} for c, d in per_class.items()},
        "class_sets": {k: v / n for k, v in configs.most_common(10)} if n else {},
        "acceptance": {
            m: {"proposed": a, "accepted": b, "rate": (b / a if a else math.nan),
                **({"nan": nan} if nan else {})}
            for m, (a, b, nan) in sorted(by_move.items())
        },
        "acceptance_by_class": move_stats,
        "noise": noise_summary,
    }


def seen_summary(kept: list[dict[str, Any]], class_names: Iterable[str]) -> dict[str, Any]:
    """The posterior over the number of objects some camera sees, in all and per class, and
    the mean number no camera sees, from samples whose objects are marked (``sppl.render.seen``);
    empty where any sample is not marked (samples of an older sppl)."""
    if not kept or any("seen" not in o for s in kept for o in s["objects"]):
        return {}
    n = len(kept)
    n_seen = Counter(sum(o["seen"] for o in s["objects"]) for s in kept)
    per_class = {
        c: Counter(sum(o["seen"] and o["class"] == c for o in s["objects"]) for s in kept)
        for c in class_names
    }
    unseen = [sum(not o["seen"] for o in s["objects"]) for s in kept]
    return {
        "n_seen": {str(k): v / n for k, v in sorted(n_seen.items())},
        "seen_class_counts": {c: {str(k): v / n for k, v in sorted(d.items())}
                              for c, d in per_class.items()},
        "unseen": {"mean": float(np.mean(unseen)),
                   "p_none": sum(u == 0 for u in unseen) / n},
    }


def _shares(d: dict[str, float], sep: str = ", ") -> str:
    return sep.join(f"{k}: {v:.2f}" for k, v in d.items())


def format_summary(summary: dict[str, Any]) -> str:
    """The summary as a few lines of text for the terminal."""
    lines = []
    if summary.get("partial"):
        lines.append(f"PARTIAL SUMMARY: {summary['partial']}")
    if summary.get("interrupted"):
        lines.append(f"interrupted after {summary.get('steps_done')} steps; samples so far:")
    elif summary.get("chains", 1) > 1:
        lines.append(f"{summary['chains']} chains of {summary.get('steps_done')} steps in "
                     f"{summary.get('seconds', 0):.1f} s")
    else:
        lines.append(f"{summary.get('steps_done')} steps in {summary.get('seconds', 0):.1f} s")
    lines.append(f"samples used: {summary['samples_used']} (after {summary['burn']} burn-in steps)")
    if "n_seen" in summary:
        # What the observations settle first: objects no camera sees are the prior's alone.
        lines.append("objects the cameras see: " + _shares(summary["n_seen"]))
        for c, d in summary["seen_class_counts"].items():
            lines.append(f"  {c}: " + _shares(d))
        u = summary["unseen"]
        lines.append(f"unseen objects the prior adds: {u['mean']:.2f} on average "
                     f"(none in {u['p_none']:.0%} of samples)")
    m = summary.get("map")
    if m:
        where = f"chain {m['chain']}, step {m['step']}" if "chain" in m else f"step {m['step']}"
        lines.append(f"MAP scene (log joint {m['score']:.1f}, {where}):")
        for o in m["objects"]:
            params = ", ".join(
                f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in o["params"].items()
            )
            unseen = "  (no camera sees it)" if o.get("seen") is False else ""
            lines.append(f"  {o['class']}: {params}{unseen}")
        if not m["objects"]:
            lines.append("  (no objects)")
    if not summary["samples_used"]:
        lines.append("posterior: none (no samples after burn-in)")
    else:
        lines += _posterior_lines(summary)
    lines.append(
        "acceptance: "
        + ", ".join(
            f"{m}: {a['rate']:.3f} ({a['accepted']}/{a['proposed']}"
            + (f", {a['nan']} NaN" if a.get("nan") else "") + ")"
            for m, a in summary["acceptance"].items()
        )
    )
    for kind, ps in summary["noise"].items():
        for name, s in ps.items():
            lines.append(f"noise {kind}.{name}: {s['mean']:.4f} ± {s['sd']:.4f}")
    diag = summary.get("diagnostics")
    if diag:
        def fmt(v, spec):
            return "n/a" if v is None else format(v, spec)

        lines.append("convergence (R-hat, bulk ESS, tail ESS; R-hat needs 2+ chains, aim < 1.01):")
        for name, d in diag.items():
            lines.append(f"  {name}: R-hat {fmt(d['rhat'], '.3f')}, "
                         f"ESS {fmt(d['ess_bulk'], '.0f')} / {fmt(d['ess_tail'], '.0f')}")
    return "\n".join(lines)


def _posterior_lines(summary: dict[str, Any]) -> list[str]:
    lines = []
    seen_too = " (seen or not)" if "n_seen" in summary else ""
    lines.append(f"number of objects{seen_too}: " + _shares(summary["n_objects"]))
    for c, d in summary["class_counts"].items():
        lines.append(f"  {c}: " + _shares(d))
    lines.append("classes: " + "; ".join(f"{k}: {v:.2f}" for k, v in summary["class_sets"].items()))
    return lines
