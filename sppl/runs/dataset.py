"""Many scenes, many chains: ``sppl sample`` over a data set of observation folders.

A data set is a folder whose sub-folders are observation folders (each with its
``transforms.json``), or a text file naming observation folders, one a line. Every (scene,
chain) pair is a task, and a task runs one chain exactly as ``sppl sample`` runs it for that
scene alone: scene ``S``'s folder in the output, ``OUT/S/``, is the run folder that
``sppl sample model.scn --obs S --out OUT/S`` with the same ``--seed``, ``--chains``,
``--steps``, ``--thin`` and ``--burn`` writes, sample for sample. Every scene uses the same
seed: the scenes are separate analyses, and so each scene's run can be repeated on its own.

Tasks run on an executor (``sppl.runs.executors``): local worker processes by default, or a Ray
cluster. A task writes its chain's folder itself (a cluster's workers must see ``OUT`` on a
shared file system) and checkpoints as any chain does, so a task whose worker is lost is run
again from its last checkpoint and draws the samples the lost worker would have drawn.
Running the same command again skips the finished tasks and resumes the stopped ones.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._version import __version__
from ..data.observations import load_observations
from ..errors import ObservationError, Span, SpplError, UsageError
from ..model.types import Model
from ..output.compare import TOLERANCE
from .checkpoint import model_fingerprint, observations_fingerprint
from .run import CHECKPOINT_SECONDS
from .tasks import Task, task_state

DATASET_RECORD = "dataset.json"
TRANSFORMS = "transforms.json"


@dataclass(frozen=True)
class Scene:
    """One observation folder of a data set, and the name of its run folder in the output."""

    name: str
    obs: Path


# ----------------------------------------------------------------------------------------------
# Finding the scenes


def is_dataset(path: Path) -> bool:
    """Whether ``--obs PATH`` names a data set rather than one observation folder: a list
    file, or a folder without ``transforms.json`` whose sub-folders hold one."""
    if path.is_file():
        return path.name != TRANSFORMS
    return (path.is_dir() and not (path / TRANSFORMS).exists()
            and any((p / TRANSFORMS).is_file() for p in path.iterdir() if p.is_dir()))


def find_scenes(path: Path) -> list[Scene]:
    """The scenes of a data set, in a fixed order: a folder's sub-folders that hold a
    ``transforms.json`` sorted by name, or a list file's folders in the file's order (paths
    relative to the list file; blank lines and ``#`` comments ignored)."""
    if path.is_file():
        scenes = []
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            entry = line.split("#", 1)[0].strip()
            if not entry:
                continue
            folder = (path.parent / entry)
            if not (folder / TRANSFORMS).is_file():
                raise ObservationError(
                    f"{entry!r} is not an observation folder (it has no {TRANSFORMS})",
                    path=path, span=Span(number, line.index(entry) + 1),
                    hint="name one observation folder a line, relative to this file")
            scenes.append(Scene(folder.name, folder))
        if not scenes:
            raise ObservationError("the list names no observation folder", path=path,
                                   hint="write one observation folder a line")
    else:
        scenes = [Scene(p.name, p) for p in sorted(path.iterdir())
                  if p.is_dir() and (p / TRANSFORMS).is_file()]
    seen: dict[str, Path] = {}
    for s in scenes:
        if s.name in seen:
            raise ObservationError(
                f"two scenes would share the run folder {s.name!r} ({seen[s.name]} and {s.obs})",
                path=path, hint="give the observation folders different names")
        seen[s.name] = s.obs
    return scenes


# ----------------------------------------------------------------------------------------------
# Tasks


def scene_tasks(scene: Scene, out: Path, *, chains: int, steps: int, seed: int, thin: int,
                burn: int | None, checkpoint_seconds: float) -> list[Task]:
    """A scene's tasks: one chain into ``out`` itself, several into ``out/chain_<i>/``, as
    ``run_chains`` lays them out."""
    from .run import chain_folder

    return [Task(scene.name, str(scene.obs),
                 str(out if chains == 1 else chain_folder(out, i)), i, chains, steps, seed, thin,
                 burn, checkpoint_seconds)
            for i in range(chains)]


# ----------------------------------------------------------------------------------------------
# The data set's record and summary


def _dataset_record(model: Model, dataset: Path, scenes: list[Scene], fingerprints: list[str], *,
                    chains: int, steps: int, seed: int, thin: int, burn: int | None) -> dict:
    return {
        "sppl_version": __version__,
        "model": str(model.path) if model.path else None,
        "model_sha256": model_fingerprint(model),
        "dataset": str(dataset),
        "scenes": [{"name": s.name, "observations": str(s.obs), "observations_sha256": f}
                   for s, f in zip(scenes, fingerprints)],
        "chains": chains, "steps": steps, "seed": seed, "thin": thin, "burn": burn,
    }


# What must match for a rerun to continue a data set's run rather than mix two of them.
_SAME = (("model_sha256", "the model"), ("scenes", "the scenes or their observations"),
         ("chains", "--chains"), ("seed", "--seed"), ("thin", "--thin"), ("burn", "--burn"))


def _check_continues(out: Path, old: dict, new: dict) -> None:
    for key, what in _SAME:
        if old.get(key) != new.get(key):
            raise UsageError(f"{out} holds a data-set run whose {what} differ from this one's; "
                             "rerun it with its own inputs to continue it, add --force to "
                             "start over, or choose another --out")


def _scene_result(scene: Scene, out: Path) -> dict[str, Any]:
    """One line of the data-set summary: the scene's MAP, its posterior over the number of
    objects, and against its true scene (``scene.json`` in its observation folder) whether
    the MAP is right."""
    from ..output.compare import compare_scenes

    s = json.loads((out / "summary.json").read_text())
    counts = {int(k): v for k, v in s["n_objects"].items()}
    mode = max(counts, key=counts.get) if counts else None
    result: dict[str, Any] = {
        "scene": scene.name, "observations": str(scene.obs), "run": str(out),
        "steps_done": s["steps_done"], "interrupted": s["interrupted"],
        "seconds": s["seconds"],
        "map_objects": s["map"]["objects"] if s.get("map") else [],
        "map_log_joint": s["map"]["score"] if s.get("map") else None,
        "n_objects_mode": mode, "p_n_objects_mode": counts.get(mode),
    }
    truth = scene.obs / "scene.json"
    if truth.is_file():
        true_objects = json.loads(truth.read_text()).get("objects", [])
        errors = compare_scenes(result["map_objects"], true_objects)
        result["true_n_objects"] = len(true_objects)
        result["recovered"] = errors.correct()
        result["max_position_error"] = errors.max_position_error
    return result


def summarise_dataset(out: Path, scenes: list[Scene], failures: dict[str, str], *,
                      seconds: float, interrupted: bool) -> dict[str, Any]:
    """``OUT/summary.json`` and ``OUT/summary.txt``: per scene its MAP and counts and, where
    a true scene is given, whether the MAP recovers it; in all, how many were recovered."""
    rows = []
    for scene in scenes:
        folder = out / scene.name
        if scene.name in failures:
            rows.append({"scene": scene.name, "observations": str(scene.obs),
                         "error": failures[scene.name]})
        elif (folder / "summary.json").exists():
            rows.append(_scene_result(scene, folder))
        else:
            rows.append({"scene": scene.name, "observations": str(scene.obs),
                         "error": "not run yet"})
    judged = [r for r in rows if "recovered" in r]
    summary = {
        "scenes": len(scenes),
        "finished": sum("error" not in r and not r["interrupted"] for r in rows),
        "failed": len(failures),
        "with_truth": len(judged),
        "recovered": sum(r["recovered"] for r in judged),
        "tolerance": TOLERANCE,
        "seconds": seconds,
        "interrupted": interrupted,
        "per_scene": rows,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "summary.txt").write_text(format_dataset_summary(summary) + "\n")
    return summary


def format_dataset_summary(summary: dict[str, Any]) -> str:
    lines = [f"{summary['finished']} of {summary['scenes']} scenes finished in "
             f"{summary['seconds']:.1f} s" + (f", {summary['failed']} failed"
                                               if summary["failed"] else "")]
    if summary["with_truth"]:
        lines.append(f"recovered (right count, classes and categories; positions within "
                     f"{summary.get('tolerance', TOLERANCE):g} m): "
                     f"{summary['recovered']} of {summary['with_truth']} scenes with a true scene")
    for r in summary["per_scene"]:
        if "error" in r:
            lines.append(f"  {r['scene']}: {r['error']}")
            continue
        classes = ", ".join(sorted(o["class"] for o in r["map_objects"])) or "no objects"
        line = (f"  {r['scene']}: MAP {len(r['map_objects'])} objects ({classes}); "
                f"P({r['n_objects_mode']} objects) = {r['p_n_objects_mode']:.2f}")
        if "recovered" in r:
            line += (f"; truth {r['true_n_objects']}: "
                     + ("recovered" if r["recovered"] else "not recovered"))
        if r["interrupted"]:
            line += f" (stopped after {r['steps_done']} steps)"
        lines.append(line)
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Running a data set


@dataclass
class DatasetResult:
    summary: dict[str, Any]
    scenes: list[Scene]


def run_dataset(
    model: Model,
    dataset: Path,
    out: Path,
    *,
    chains: int,
    steps: int,
    seed: int,
    thin: int = 1,
    burn: int | None = None,
    executor=None,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
    progress: bool | None = None,
    on_scene: Callable[[str, str], None] | None = None,
    prepare_out: Callable[[], None] | None = None,
) -> DatasetResult:
    """Run every task of a data set on ``executor`` (local worker processes by default) into
    ``out``, continuing what an earlier run of the same inputs left there, and write the
    data-set summary. ``on_scene(name, line)`` hears of each scene as its last chain ends.
    A failed task fails its scene, not the run: the summary names it and the others go on.
    ``prepare_out()``, if given, is called once every scene's observations have loaded and
    before anything is written (the command line makes ``out`` there)."""
    from tqdm import tqdm

    from ..output.posterior import POSTERIOR_FILE, write_posterior
    from .chains import combine_chains, write_chains_record
    from .executors import LocalExecutor, TaskFailed

    scenes = find_scenes(dataset)
    observations = {s.name: load_observations(s.obs) for s in scenes}  # every folder checked now
    fingerprints = [observations_fingerprint(observations[s.name]) for s in scenes]
    record = _dataset_record(model, dataset, scenes, fingerprints, chains=chains, steps=steps,
                             seed=seed, thin=thin, burn=burn)
    if prepare_out is not None:
        prepare_out()
    out.mkdir(parents=True, exist_ok=True)
    if (out / DATASET_RECORD).exists():
        _check_continues(out, json.loads((out / DATASET_RECORD).read_text()), record)
    (out / DATASET_RECORD).write_text(json.dumps(record, indent=2))

    tasks: dict[str, list[Task]] = {}
    for s in scenes:
        if chains > 1:
            write_chains_record(model, observations[s.name], out / s.name, chains=chains,
                                steps=steps, seed=seed, thin=thin, burn=burn, resume=True)
        tasks[s.name] = scene_tasks(s, out / s.name, chains=chains, steps=steps, seed=seed,
                                    thin=thin, burn=burn, checkpoint_seconds=checkpoint_seconds)
    del observations  # the workers load their own
    todo = [t for s in scenes for t in tasks[s.name] if task_state(t) != "done"]
    remaining = {s.name: sum(task_state(t) != "done" for t in tasks[s.name]) for s in scenes}
    failures: dict[str, str] = {}
    stopped: set[str] = set()
    executor = executor or LocalExecutor()
    t0 = time.monotonic()
    by_scene = {s.name: s for s in scenes}

    def finish_scene(name: str) -> None:
        folder = out / name
        if chains > 1:
            combine_chains(folder)
        try:
            write_posterior(folder)
        except SpplError:
            pass  # too few samples for a posterior file; the summary says what there is
        if on_scene is not None:
            row = _scene_result(by_scene[name], folder)
            on_scene(name, format_dataset_summary(
                {"scenes": 1, "finished": 1, "failed": 0, "with_truth": 0, "seconds": 0,
                 "per_scene": [row]}).splitlines()[1].strip())

    bar = tqdm(total=len(todo), disable=None if progress is None else not progress,
               unit="task", dynamic_ncols=True, leave=False)
    interrupted = False
    results = executor.run(model.source, str(model.path) if model.path else None, todo)
    try:
        for task, result in results:
            bar.update(1)
            if isinstance(result, TaskFailed):
                failures.setdefault(task.scene, f"{task.label} failed: {result.message}")
                continue
            if result["interrupted"]:
                stopped.add(task.scene)
            remaining[task.scene] -= 1
            if remaining[task.scene] == 0 and task.scene not in failures.keys() | stopped:
                finish_scene(task.scene)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        results.close()  # the workers stop (a running chain after its sweep, saved)
        bar.close()
    for s in scenes:  # a rerun after a crash between a scene's last chain and its pooling
        folder = out / s.name
        if (not interrupted and remaining[s.name] == 0 and s.name not in failures
                and not ((folder / "summary.json").exists()
                         and (folder / POSTERIOR_FILE).exists())):
            finish_scene(s.name)
    summary = summarise_dataset(out, scenes, failures, seconds=time.monotonic() - t0,
                                interrupted=interrupted or bool(stopped))
    return DatasetResult(summary, scenes)
