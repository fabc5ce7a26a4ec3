"""Does `sppl sample` recover a scene simulated from each shipped model?

    python examples/models/recover.py                    # every model, 10,000 sweeps each
    python examples/models/recover.py --models tabletop  # one model
    python examples/models/recover.py --steps 200        # a smoke test (recovers nothing)

For each model, ``examples/models/MODEL/scene.json`` is a true scene written for it (a few
objects in view of both cameras, and the sensors' noise) and ``MODEL/cameras.json`` the
cameras that see it: one RGB and one depth camera at 96x96 pixels. The script runs what a
user would type,

    sppl simulate models/MODEL.scn --cameras examples/models/MODEL/cameras.json \\
        --scene examples/models/MODEL/scene.json --out RUN/MODEL/obs --seed SEED
    sppl sample models/MODEL.scn --obs RUN/MODEL/obs --steps STEPS --seed SEED --out RUN/MODEL/run

and compares the MAP scene that `sample` reports with the truth (``sppl.output.compare``: objects
matched by their ground position). A model is recovered when the MAP has as many objects as
the truth, every matched pair has the same class and the same categorical values (colours,
sizes, materials), and every position is within the model's tolerance. It prints a table
(docs/models.md shows one) and exits with status 1 if a model was not recovered.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(ROOT))

from sppl import compare_scenes  # noqa: E402
from sppl.cli import main as sppl  # noqa: E402

MODELS = ("shapes", "blocks", "tabletop", "shapes_plus")
# How far (metres, on the ground plane) a MAP object may be from the true one: a tenth of the
# spacing of the true objects, about. Tabletop objects are a few centimetres across.
TOLERANCE = {"shapes": 0.1, "blocks": 0.1, "tabletop": 0.03, "shapes_plus": 0.1}


def _quiet(argv: list[str], log: Path) -> int:
    """Run an sppl command with its output in ``log``."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = sppl(argv)
    log.write_text(out.getvalue())
    return code


def _names(objects, order) -> str:
    """How many of each class, classes in ``order`` (the truth's) first."""
    counts: dict[str, int] = {c: 0 for c in order}
    for o in objects:
        counts[o["class"]] = counts.get(o["class"], 0) + 1
    return ", ".join(f"{n} {c}" if n > 1 else c for c, n in counts.items() if n) or "none"


def recover(model: str, out: Path, steps: int, seed: int, chains: int = 1) -> dict:
    folder = out / model
    folder.mkdir(parents=True, exist_ok=True)
    scn = ROOT / "models" / f"{model}.scn"
    truth = json.loads((HERE / model / "scene.json").read_text())["objects"]
    if _quiet(["simulate", str(scn), "--cameras", str(HERE / model / "cameras.json"),
               "--scene", str(HERE / model / "scene.json"), "--out", str(folder / "obs"),
               "--seed", str(seed), "--force"], folder / "simulate.log"):
        raise SystemExit(f"sppl simulate failed for {model}: see {folder / 'simulate.log'}")
    t0 = time.monotonic()
    if _quiet(["sample", str(scn), "--obs", str(folder / "obs"), "--steps", str(steps),
               "--seed", str(seed), "--chains", str(chains), "--out", str(folder / "run"),
               "--force", "-q"],
              folder / "sample.log"):
        raise SystemExit(f"sppl sample failed for {model}: see {folder / 'sample.log'}")
    seconds = time.monotonic() - t0
    best = json.loads((folder / "run" / "summary.json").read_text())["map"]
    errors = compare_scenes(best["objects"], truth)
    return {"model": model, "truth": truth, "map": best["objects"], "errors": errors,
            "seconds": seconds, "tolerance": TOLERANCE[model],
            "recovered": errors.correct(TOLERANCE[model]),
            "gap": best["score"] - truth_log_joint(scn, folder / "obs")}


def truth_log_joint(scn: Path, obs: Path) -> float:
    """The log joint density of the true scene and noise given the observations, scored as the
    sampler scores its states. A MAP below it means the chain did not reach the truth's
    density (the sampler's shortfall); a wrong MAP above it, that the observations prefer
    another scene (the model's)."""
    import numpy as np

    from sppl import Renderer, Sampler, Scorer, load_model, load_observations, load_scene

    model = load_model(scn)
    renderer = Renderer(model.render)
    try:
        sampler = Sampler(model, Scorer(model, load_observations(obs), renderer),
                          np.random.default_rng(0))
        objects, noise = load_scene(model, obs / "scene.json")
        return sampler.make_trace(objects, noise).score
    finally:
        renderer.release()


def table(rows: list[dict], steps: int, seed: int, chains: int = 1) -> str:
    head = ("model", "true objects", "MAP objects", "count", "classes", "categories",
            "max position error", "tolerance", "log joint, MAP - truth", "seconds", "recovered")
    lines = [
        "| " + " | ".join(head) + " |",
        "| " + " | ".join("---" for _ in head) + " |",
    ]
    for r in rows:
        e = r["errors"]
        matched = min(e.n_true, e.n_estimated)
        order = [o["class"] for o in r["truth"]]
        cells = (
            f"`{r['model']}.scn`", _names(r["truth"], order), _names(r["map"], order),
            "right" if e.n_true == e.n_estimated else f"wrong ({e.n_estimated} of {e.n_true})",
            "right" if e.wrong_class == 0 else f"{e.wrong_class} of {matched} wrong",
            "right" if e.wrong_category == 0 else f"{e.wrong_category} of {matched} wrong",
            f"{e.max_position_error:.3f} m", f"{r['tolerance']:g} m", f"{r['gap']:+,.0f}",
            f"{r['seconds']:.0f}",
            "yes" if r["recovered"] else "**no**",
        )
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    runs = "one chain" if chains == 1 else f"{chains} chains (the MAP is the best of them)"
    lines.append(f"`sppl sample` with {runs} of {steps} sweeps per model, seed {seed}; seconds "
                 "are its wall time.")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--models", nargs="+", choices=MODELS, default=list(MODELS))
    p.add_argument("--steps", type=int, default=10_000, help="sweeps per model (default 10,000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--chains", type=int, default=1,
                   help="chains per model; the MAP is the best over all of them (default 1)")
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "recover",
                   help="where the observations and runs go (default runs/recover)")
    args = p.parse_args(argv)
    rows = []
    for model in args.models:
        print(f"{model}: simulating and sampling {args.steps} sweeps ...", flush=True)
        rows.append(recover(model, args.out, args.steps, args.seed, args.chains))
    print()
    print(table(rows, args.steps, args.seed, args.chains))
    return 0 if all(r["recovered"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
