"""The ``sppl`` command: check, simulate, sample and verify.

Exit status: 0 on success, 1 on an error in the user's input (one message on stderr, no
traceback unless ``--debug``) or when a check of ``sppl verify`` fails, 2 on a usage error, 130
when interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import shutil
import sys
from pathlib import Path

from ._version import __version__
from .errors import SpplError, UsageError

DEFAULT_STEPS = 20000
CHECKPOINT_SECONDS = 30.0  # sppl.runs.run.CHECKPOINT_SECONDS, without importing the engine for --help
VERIFY_STEPS = 20000

EPILOG = """\
exit status: 0 success, 1 bad input (model, observations, options) or a failed verify check,
2 usage, 130 interrupted.
Documentation: docs/ in the source tree (tutorial, language, inference, observations)."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sppl",
        description="Bayesian scene understanding: posteriors over the objects in a scene, "
        "from a scene model (.scn) and calibrated RGB and depth observations.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"sppl {__version__}")
    p.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser("check", help="parse and validate a model file, list its classes")
    c.add_argument("model", type=Path, help="the model file (.scn)")

    f = sub.add_parser("fmt", help="print a model file in canonical form (comments kept)")
    f.add_argument("models", type=Path, nargs="+", metavar="model", help="model files (.scn)")
    how = f.add_mutually_exclusive_group()
    how.add_argument("--check", action="store_true",
                     help="print nothing; exit 1 if a file is not in canonical form")
    how.add_argument("--write", "-w", action="store_true", help="rewrite the files in place")

    s = sub.add_parser(
        "simulate",
        help="draw a scene (or take one), render every camera, add sensor noise, write obs/",
    )
    s.add_argument("model", type=Path)
    s.add_argument("--cameras", type=Path, required=True,
                   help="cameras file (transforms.json layout; frames need no image files)")
    s.add_argument("--out", type=Path, required=True, help="observation folder to write")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--scene", type=Path, help="a scene file to render instead of a prior draw")
    s.add_argument("--depth-format", choices=("npy", "png"), default="npy",
                   help="depth files: float32 metres (npy) or uint16 millimetres (png)")
    s.add_argument("--force", action="store_true",
                   help="replace --out if it is an observation folder `sppl simulate` wrote")

    r = sub.add_parser("sample", help="draw posterior samples of the scene given observations")
    r.add_argument("model", type=Path, nargs="?",
                   help="the model file (.scn); with --resume, default: the run's")
    r.add_argument("--obs", type=Path,
                   help="observation folder (transforms.json); with --resume, default: the run's")
    r.add_argument("--out", type=Path, default=None,
                   help="run folder to write (default: run)")
    r.add_argument("--steps", type=int, default=None,
                   help=f"sweeps of the sampler in all (default: {DEFAULT_STEPS}; with --resume, "
                   "the run's)")
    r.add_argument("--seed", type=int, default=None, help="(default: 0)")
    r.add_argument("--thin", type=int, default=None, help="keep every n-th sweep (default: 1)")
    r.add_argument("--burn", type=int, default=None,
                   help="sweeps left out of the posterior summary (default: half)")
    r.add_argument("--force", action="store_true",
                   help="replace --out if it is a run folder `sppl sample` wrote")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    r.add_argument("--chains", type=int, default=None,
                   help="independent chains, run in parallel processes, each into "
                   "OUT/chain_<i>/ with its own stream of --seed; OUT/summary.json pools them "
                   "and gives R-hat (default: 1, written straight into OUT)")
    r.add_argument("--lockstep", action="store_true", default=None,
                   help="run the --chains in this one process instead, advanced together and "
                   "their hypotheses rendered in one pass; the same samples as in processes")
    r.add_argument("--resume", type=Path, default=None, metavar="RUN",
                   help="continue the stopped run in RUN from its checkpoints, with its model, "
                   "observations, seed, thin and chains, up to --steps sweeps in all; the samples "
                   "are exactly those of an uninterrupted run")
    r.add_argument("--checkpoint-every", type=float, default=CHECKPOINT_SECONDS,
                   metavar="SECONDS",
                   help="save each chain's full state this often, for --resume "
                   f"(default: {CHECKPOINT_SECONDS:g})")
    r.add_argument("--workers", type=int, default=None,
                   help="with a data set (--obs naming a folder of observation folders, or a "
                   "list file): how many tasks (scene x chain) run at once on this machine "
                   "(default: one per CPU core)")
    r.add_argument("--cluster", default=None, metavar="WHERE",
                   help="with a data set: where its tasks run: local (worker processes, the "
                   "default), ray (the Ray cluster in RAY_ADDRESS or on this machine, else a "
                   "private one), ray://HOST:PORT or HOST:PORT")

    v = sub.add_parser(
        "verify",
        help="check that the sampler derived from a model is correct: prior recovery, "
        "move reverses and a short Geweke test, as a table",
    )
    v.add_argument("model", type=Path)
    v.add_argument("--steps", type=int, default=VERIFY_STEPS,
                   help=f"sweeps of the prior-recovery chain (default: {VERIFY_STEPS})")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--geweke", action=argparse.BooleanOptionalAction, default=True,
                   help="run the Geweke test, which renders (default: on)")
    v.add_argument("--geweke-chains", type=int, default=100,
                   help="independent Geweke chains (default: 100)")
    v.add_argument("--geweke-length", type=int, default=20,
                   help="sweeps per Geweke chain (default: 20)")
    v.add_argument("--size", type=int, default=8,
                   help="width and height in pixels of the Geweke test's images (default: 8)")
    v.add_argument("--alpha", type=float, default=0.01,
                   help="family-wise false-alarm rate of the whole table (default: 0.01)")
    v.add_argument("--proposal-draws", type=int, default=30,
                   help="draws per check of a proposal that looks at the observations "
                   "(sampler against density; 0: leave those checks out; default: 30)")
    v.add_argument("--strict", action="store_true",
                   help="fail (exit 1) when a check is left untested, not only when one fails")

    e = sub.add_parser(
        "export",
        help="write a run's samples as an ArviZ-readable posterior file (NetCDF4)",
    )
    e.add_argument("run", type=Path, help="the run folder that `sppl sample` wrote")
    e.add_argument("--out", type=Path, default=None,
                   help="the file to write (default: RUN/posterior.nc)")

    rep = sub.add_parser(
        "report",
        help="write an HTML page of a run: renders, residuals, counts, occupancy map, "
        "marginals, traces, acceptance rates, R-hat and ESS, and errors against a true scene",
    )
    rep.add_argument("run", type=Path, help="the run folder that `sppl sample` wrote")
    rep.add_argument("--out", type=Path, default=None,
                     help="folder for index.html and its PNG figures (default: RUN/report)")
    rep.add_argument("--truth", type=Path, default=None,
                     help="the true scene (default: scene.json in the observation folder, if any)")
    rep.add_argument("--no-truth", action="store_true", help="ignore any true scene")
    rep.add_argument("--model", type=Path, default=None,
                     help="the model file (default: the one named in RUN/run.json)")
    rep.add_argument("--obs", type=Path, default=None,
                     help="the observation folder (default: the one named in RUN/run.json)")
    return p


# What each command writes in its --out folder: --force deletes a folder only if it holds
# these and nothing else, and at least one of the markers (so an empty-looking folder of
# someone else's is not taken for one of ours).
OUT_KINDS = {
    "run": {
        "what": "a run folder", "writer": "`sppl sample`",
        "markers": {"run.json", "samples.jsonl", "summary.json", "checkpoint.json"},
        "files": {"run.json", "samples.jsonl", "summary.json", "summary.txt", "checkpoint.json",
                  "checkpoint.json.tmp", "posterior.nc", "task.json", ".sppl-write-test",
                  ".sppl-lock"},
        "folders": {"report"},  # and chain_<i>/, each a run folder of one chain
        "chains": True,
    },
    "dataset": {
        "what": "a data-set run folder", "writer": "`sppl sample` on a data set",
        "markers": {"dataset.json"},
        "files": {"dataset.json", "summary.json", "summary.txt", ".sppl-write-test",
                  ".sppl-lock"},
        "folders": set(),  # and one run folder a scene
        "chains": False,
        "scenes": True,
    },
    "obs": {
        "what": "an observation folder", "writer": "`sppl simulate`",
        "markers": {"transforms.json"},
        "files": {"transforms.json", "scene.json", ".sppl-write-test", ".sppl-lock"},
        "folders": {"images", "depth"},
        "chains": False,
    },
}


def _is_chain_folder(name: str) -> bool:
    return name.startswith("chain_") and name[len("chain_"):].isdigit()


def _not_ours(folder: Path, kind: str, prefix: str = "") -> str | None:
    """Why ``folder`` does not look like a ``kind`` output folder of sppl's, or None."""
    spec = OUT_KINDS[kind]
    names = []
    for entry in sorted(folder.iterdir()):
        name = prefix + entry.name
        names.append(entry.name)
        if entry.is_symlink():
            return f"it holds {name}, a symbolic link"
        if entry.is_dir() and spec["chains"] and not prefix and _is_chain_folder(entry.name):
            inner = _not_ours(entry, kind, prefix=f"{entry.name}/")
            if inner:
                return inner
        elif entry.is_dir() and spec.get("scenes"):
            inner = _not_ours(entry, "run")
            if inner:
                return f"{entry.name}/ is not a run folder: {inner}"
        elif entry.name not in (spec["folders"] if entry.is_dir() else spec["files"]):
            return f"it holds {name}, which {spec['writer']} does not write"
    if not prefix and not set(names) & spec["markers"] and not any(map(_is_chain_folder, names)):
        return f"it has none of {', '.join(sorted(spec['markers']))}"
    return None


def _within(path: Path, folder: Path) -> bool:
    """Whether ``path`` is ``folder`` or inside it (both resolved)."""
    return path == folder or folder in path.parents


def _prepare_out(out: Path, force: bool, *, kind: str = "run",
                 inputs: dict[str, Path | None] | None = None) -> None:
    """Make ``out`` an empty folder that can be written. An existing non-empty ``out`` is
    refused without ``force``; with it, it is deleted only if it looks like a ``kind``
    output folder of sppl's (``OUT_KINDS``) and holds neither the current folder nor any of
    the ``inputs`` (what the command reads, by the option that names it)."""
    from .runs.lock import LOCK_FILE, FolderInUse, held, holder

    if out.is_symlink() or (out.exists() and (
            not out.is_dir() or any(e.name != LOCK_FILE for e in out.iterdir()))):
        if not force:
            raise UsageError(f"{out} already exists; choose another --out or add --force to replace it")
        spec = OUT_KINDS[kind]
        if out.is_symlink() or not out.is_dir():
            this = "a symbolic link" if out.is_symlink() else "a file"
            raise UsageError(f"{out}: --force replaces only {spec['what']} that {spec['writer']} "
                             f"wrote, and this is {this}; remove it yourself or choose another "
                             "--out")
        folder, here = out.resolve(), Path.cwd().resolve()
        if _within(here, folder):
            where = ("the current folder" if folder == here
                     else "a folder that holds the current one")
            raise UsageError(f"{out}: --force would delete {where}; choose another --out")
        for option, path in (inputs or {}).items():
            if path is not None and _within(Path(path).resolve(), folder):
                raise UsageError(f"{out}: --force would delete {path}, which {option} reads; "
                                 "choose another --out")
        why = _not_ours(out, kind)
        if why:
            raise UsageError(f"{out}: --force replaces only {spec['what']} that {spec['writer']} "
                             f"wrote, and this does not look like one ({why}); remove it yourself "
                             "or choose another --out")
        # Never delete what a live process writes: the folder, or a chain's folder in it
        # (whose worker may outlive a killed parent).
        for folder in (out, *(e for e in out.iterdir() if e.is_dir())):
            pid = None if held(folder) else holder(folder)
            if pid:
                raise FolderInUse(f"another sppl process (pid {pid}) is writing {folder}; "
                                  "--force does not delete it", path=out,
                                  hint="wait for it to finish or stop it, or choose another --out")
        _empty(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UsageError(f"{out}: cannot create the output folder ({e.strerror}); choose "
                         "another --out") from None
    probe = out / ".sppl-write-test"
    try:  # fail now, not when the first sample is written
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise UsageError(f"{out}: cannot write in the output folder ({e.strerror}); choose "
                         "another --out") from None


def _empty(folder: Path) -> None:
    """Delete everything in ``folder`` but its lock file, which its writer holds."""
    from .runs.lock import LOCK_FILE

    for entry in folder.iterdir():
        if entry.name == LOCK_FILE:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


class _Claim:
    """An output folder this command holds the lock of; ``discard()`` asks for what it wrote
    to be removed when the command ends (a command that fails leaves nothing half-written)."""

    def __init__(self, out: Path, created: list[Path]) -> None:
        self.out, self.created, self.discarding = out, created, False

    def discard(self) -> None:
        self.discarding = True


@contextlib.contextmanager
def _claim_out(out: Path):
    """Hold ``out``'s lock (``sppl.runs.lock``) for the block, making the folder if it is missing;
    a second writer meets a one-line error naming this process. A path that is a file or a
    link is left to ``_prepare_out`` to refuse."""
    from .runs.lock import FolderInUse, held, hold, holder

    for folder in out.resolve().parents:  # a run's chain_<i>/ is its run's to write
        pid = None if held(folder) else holder(folder)
        if pid:
            raise FolderInUse(f"{out} is inside {folder}, which another sppl process (pid {pid}) "
                              "is writing", hint="choose another --out")
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        yield _Claim(out, [])
        return
    created = [p for p in (out, *out.parents) if not p.exists() and not p.is_symlink()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UsageError(f"{out}: cannot create the output folder ({e.strerror}); choose "
                         "another --out") from None
    claim = _Claim(out, created)
    try:
        try:
            lock = hold(out)
            lock.__enter__()
        except OSError as e:
            raise UsageError(f"{out}: cannot write in the output folder ({e.strerror}); choose "
                             "another --out") from None
        try:
            yield claim
        except BaseException:
            if claim.discarding:
                _empty(out)
            raise
        finally:
            lock.__exit__(None, None, None)
    except BaseException:
        for folder in created:  # innermost first; only those this command made, once empty
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _wrote_samples(out: Path) -> bool:
    return any(p.stat().st_size > 0 for p in (*out.glob("samples.jsonl"),
                                               *out.glob("chain_*/samples.jsonl")))


SEED_MAX = 2**63 - 1  # a 64-bit integer: what run.json, checkpoints and posterior.nc store


def _check_seed(seed: int | None) -> None:
    if seed is not None and not 0 <= seed <= SEED_MAX:
        raise UsageError(f"--seed must be a whole number from 0 to 2**63 - 1 ({SEED_MAX}), "
                         f"got {seed}")


def cmd_check(args) -> int:
    from .lang import load_model
    from .model.region import region_text

    model = load_model(args.model)
    print(f"{args.model}: {len(model.classes)} classes, sensors: {', '.join(model.sensors) or 'none'}")
    for cls in model.classes:
        if cls.count is not None:
            count = f"count = {cls.count}"
        else:
            count = f"count ~ poisson({cls.rate:g})"
            count += "" if cls.max_count is None else f", at most {cls.max_count}"
        print(f"class {cls.name}  ({count}{', floating' if cls.floating else ''})")
        for p in cls.parameters:
            print(f"  {p.name:<10} {p.domain.describe():<24} ~ {p.prior}")
    for kind, s in model.sensors.items():
        noise = ", ".join(f"{p.name} ~ {p.prior}" for p in s.noise)
        options = ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                            for k, v in s.options.items())
        options = f"({options})" if options else ""
        print(f"sensor {kind}: likelihood {s.likelihood}{options}; {noise}")
    if model.render.latent:
        print("render: " + ", ".join(f"{p.name} ~ {p.prior}" for p in model.render.latent))
    if model.render.shadows:
        print("render: parts cast shadows")
    if model.no_overlap:
        print("constraint: no two footprints overlap")
    if model.max_objects is not None:
        print(f"constraint: at most {model.max_objects} objects in all")
    if model.region is not None:
        print(f"region: {region_text(model)}")
    if model.static_parts:
        print(f"static scene: {len(model.static_parts)} fixed parts")
    return 0


def cmd_fmt(args) -> int:
    from .lang.compile import read_source
    from .lang.pretty import format_source

    changed = []
    for path in args.models:
        text = read_source(path)
        canonical = format_source(text, str(path))
        if args.check:
            if canonical != text:
                changed.append(path)
                print(f"{path}: not in canonical form (sppl fmt --write {path} fixes it)",
                      file=sys.stderr)
        elif args.write:
            if canonical != text:
                path.write_text(canonical, encoding="utf-8")
                print(f"reformatted {path}", file=sys.stderr)
        else:
            sys.stdout.write(canonical)
    return 1 if changed else 0


def cmd_simulate(args) -> int:
    import numpy as np

    from .data.observations import load_cameras, write_observations
    from .lang import load_model
    from .model.simulate import (
        load_scene,
        render_observations,
        sample_noise,
        sample_objects,
        scene_dict,
    )
    from .render import Renderer

    _check_seed(args.seed)
    model = load_model(args.model)
    cameras = load_cameras(args.cameras)
    rng = np.random.default_rng(np.random.SeedSequence(args.seed))
    if args.scene:
        objects, noise = load_scene(model, args.scene)
        noise = noise or sample_noise(model, rng)
        if any(group not in noise for group, _ in model.noise_groups):
            # A scene that gives the sensors' noise but not the lighting: draw what is missing.
            noise = {**sample_noise(model, rng), **noise}
    else:
        objects = sample_objects(model, rng, progress=_still_drawing)
        noise = sample_noise(model, rng)
    with _claim_out(args.out) as claim:
        _prepare_out(args.out, args.force, kind="obs",
                     inputs={"the model argument": args.model, "--cameras": args.cameras,
                             "--scene": args.scene})
        try:  # the folder is empty (but for its lock): whatever is in it now is this command's
            frames = render_observations(model, objects, noise, cameras,
                                         Renderer(model.render), rng)
            write_observations(args.out, frames, depth_format=args.depth_format)
            scene = scene_dict(objects, noise)
            (args.out / "scene.json").write_text(json.dumps(scene, indent=2) + "\n")
        except BaseException:
            claim.discard()
            raise
    print(f"wrote {len(frames)} frames and the true scene ({len(objects)} objects) to {args.out}")
    return 0


def cmd_sample(args) -> int:
    if args.resume is not None:
        if not args.resume.is_dir():
            from .runs.run import read_run

            read_run(args.resume)  # its error says what --resume takes
        with _claim_out(args.resume):  # no other process may write it while it is read
            _resume_settings(args)
            return _sample(args)
    return _sample(args)


def _still_drawing(tries: int, seconds: float) -> None:
    print(f"still drawing a scene from the prior that keeps the model's constraints: {tries} "
          f"draws rejected in {seconds:.0f} s", file=sys.stderr, flush=True)


def _sample(args) -> int:
    from .data.observations import load_observations
    from .lang import load_model
    from .output.posterior import write_posterior
    from .output.samples import MIN_SAMPLES, format_summary
    from .runs.chains import run_chains
    from .runs.dataset import is_dataset
    from .runs.run import effective_burn

    if args.resume is None:
        if args.model is None or args.obs is None:
            raise UsageError("sample needs a model file and --obs (or --resume RUN)")
        args.out = args.out or Path("run")
        args.steps = DEFAULT_STEPS if args.steps is None else args.steps
        args.seed = 0 if args.seed is None else args.seed
        args.thin = 1 if args.thin is None else args.thin
        args.chains = 1 if args.chains is None else args.chains
        args.lockstep = bool(args.lockstep)
    if args.steps < 1 or args.thin < 1 or args.chains < 1:
        raise UsageError("--steps, --thin and --chains must be at least 1")
    if args.burn is not None and args.burn < 0:
        raise UsageError("--burn is a number of sweeps, 0 or more")
    if not args.checkpoint_every >= 0:
        raise UsageError("--checkpoint-every is a number of seconds, 0 or more")
    if args.burn is not None and args.burn < 0:
        raise UsageError("--burn is a number of sweeps, 0 or more")
    _check_seed(args.seed)
    model = load_model(args.model)
    burn = effective_burn(model, args.steps, args.burn)
    first = -(-max(burn, 1) // args.thin) * args.thin  # the first kept step: thin divides it
    planned = args.chains * len(range(first, args.steps + 1, args.thin))
    # Said before the run, when the warm-up or --burn leaves too few samples (a short run with
    # the default burn-in of half its steps is a quick look, and its summary says so after).
    if planned < MIN_SAMPLES and (args.burn is not None or burn > args.steps // 2):
        warmup = model.inference
        why = ("--burn" if args.burn is not None and args.burn >= burn
               else f"the warm-up: adapt {warmup.adapt}, anneal {warmup.anneal}")
        print(f"warning: --steps {args.steps} leaves {planned} samples after the burn-in of {burn} "
              f"({why}): the summary will be partial; give more --steps, or --resume the run "
              "with more later", file=sys.stderr)
    if args.resume is None and is_dataset(args.obs):
        return _sample_dataset(args, model)
    if args.workers is not None or args.cluster is not None:
        raise UsageError("--workers and --cluster run the tasks of a data set; --obs names one "
                         "observation folder (see docs/datasets.md)")
    obs = load_observations(args.obs)
    with _claim_out(args.out) as claim:
        if args.resume is None:
            _prepare_out(args.out, args.force, kind="run",
                         inputs={"the model argument": args.model, "--obs": args.obs})
        try:  # a new run's folder is empty now: whatever comes into it is this run's
            result = run_chains(
                model, obs, args.out, chains=args.chains, steps=args.steps, seed=args.seed,
                thin=args.thin, burn=args.burn, progress=False if args.quiet else None,
                resume=args.resume is not None, checkpoint_seconds=args.checkpoint_every,
                lockstep=args.lockstep,
            )
        except BaseException:
            if args.resume is None and not _wrote_samples(args.out):
                claim.discard()  # it failed before its first sample: leave nothing behind
            raise
        print(format_summary(result.summary))
        samples = args.out / ("samples.jsonl" if args.chains == 1 else "chain_*/samples.jsonl")
        print(f"samples: {samples}; summary: {args.out / 'summary.json'}")
        try:
            print(f"posterior (ArviZ): {write_posterior(args.out)}")
        except SpplError as e:
            print(f"no posterior file: {e}", file=sys.stderr)
        if result.summary.get("partial"):
            print(f"warning: partial summary: {result.summary['partial']}", file=sys.stderr)
    if result.summary["interrupted"]:
        print(f"to continue: sppl sample --resume {args.out}", file=sys.stderr)
        return 130
    return 0


def _sample_dataset(args, model) -> int:
    """``sppl sample`` over a data set: every scene x chain a task, one run folder a scene in
    ``--out``; rerunning the same command continues what an earlier run left unfinished."""
    from .runs.dataset import DATASET_RECORD, format_dataset_summary, run_dataset
    from .runs.executors import make_executor

    if args.lockstep:
        raise UsageError("--lockstep runs the chains of one scene in this process; a data set's "
                         "chains run as tasks (leave out --lockstep)")
    executor = make_executor(args.cluster, args.workers)
    out = args.out

    def prepare_out():
        if not (out / DATASET_RECORD).is_file() or args.force:  # else: continue that run
            _prepare_out(out, args.force, kind="dataset",
                         inputs={"the model argument": args.model, "--obs": args.obs})

    with _claim_out(out):  # one writer per data-set folder too
        result = run_dataset(
            model, args.obs, out, chains=args.chains, steps=args.steps, seed=args.seed,
            thin=args.thin, burn=args.burn, executor=executor,
            checkpoint_seconds=args.checkpoint_every, progress=False if args.quiet else None,
            on_scene=lambda name, line: print(line, flush=True), prepare_out=prepare_out,
        )
    summary = result.summary
    print(format_dataset_summary(summary))
    print(f"per scene: {out}/<scene>/; data-set summary: {out / 'summary.json'}")
    if summary["interrupted"] or summary["finished"] + summary["failed"] < summary["scenes"]:
        print("to continue: run the same command again", file=sys.stderr)
        return 130
    if summary["failed"]:
        first = next(r["error"] for r in summary["per_scene"] if "error" in r)
        raise SpplError(f"{summary['failed']} of {summary['scenes']} scenes failed; the first: "
                        f"{first}")
    return 0


def _resume_settings(args) -> None:
    """Fill the options of ``sample --resume RUN`` from the run's record; refuse to change
    what would make the continued chain another chain."""
    from .runs.run import read_run

    run = args.resume
    if (run / "dataset.json").is_file():
        raise UsageError(f"{run} is a data set's run; to continue it, run the command that "
                         "started it again (it skips finished tasks and resumes stopped ones)")
    if args.out is not None and args.out.resolve() != run.resolve():
        raise UsageError("--resume continues a run in its own folder; leave out --out")
    if args.force:
        raise UsageError("--resume continues a run and --force replaces it; choose one")
    meta, steps_done = read_run(run)
    args.out = run
    args.model = args.model or _recorded(run, meta.get("model"), "model file",
                                         "the model argument")
    args.obs = args.obs or _recorded(run, meta.get("observations"), "observations", "--obs")
    for option in ("seed", "thin", "chains"):
        recorded = meta.get(option, 1 if option == "chains" else None)
        given = getattr(args, option)
        if given is not None and given != recorded:
            raise UsageError(f"--{option} {given} differs from the run's ({recorded}); a resumed "
                             f"run keeps its --{option}")
        setattr(args, option, recorded)
    recorded = bool(meta.get("lockstep", False))
    if args.lockstep is not None and args.lockstep != recorded and args.chains > 1:
        raise UsageError(f"{run} ran its chains in parallel processes; a resumed run keeps "
                         "them there, so leave out --lockstep")
    args.lockstep = recorded
    args.steps = meta["steps"] if args.steps is None else args.steps
    args.burn = meta.get("burn") if args.burn is None else args.burn
    if args.steps <= steps_done:
        raise UsageError(f"{run} has already drawn {steps_done} of {args.steps} steps; give a "
                         "larger --steps to continue it")


def _recorded(run: Path, recorded: str | None, what: str, option: str) -> Path:
    if not recorded:
        raise UsageError(f"{run / 'run.json'} names no {what}; give it with {option}")
    path = Path(recorded)
    if not path.exists():
        raise UsageError(f"{run / 'run.json'} names the {what} {recorded}, which does not exist "
                         f"from here (it is relative to where the run started); give it with "
                         f"{option}")
    return path


def cmd_export(args) -> int:
    from .output.posterior import write_posterior

    print(f"wrote {write_posterior(args.run, args.out)}")
    return 0


def cmd_report(args) -> int:
    from .output.report import write_report

    if args.truth is not None and args.no_truth:
        raise UsageError("--truth and --no-truth contradict each other")
    page = write_report(args.run, out=args.out, truth=False if args.no_truth else args.truth,
                        model_path=args.model, obs_path=args.obs)
    print(f"wrote {page}")
    return 0


def cmd_verify(args) -> int:
    from .lang import load_model
    from .verify import verify_model

    _check_seed(args.seed)
    if args.steps < 100 or args.geweke_chains < 2 or args.geweke_length < 1 or args.size < 4:
        raise UsageError(
            "--steps must be at least 100, --geweke-chains 2, --geweke-length 1, --size 4"
        )
    if args.proposal_draws < 0:
        raise UsageError("--proposal-draws must be 0 (off) or more")
    if not 0.0 < args.alpha < 1.0:
        raise UsageError("--alpha is a probability between 0 and 1")
    model = load_model(args.model)
    report = verify_model(
        model, steps=args.steps, seed=args.seed, run_geweke=args.geweke,
        geweke_chains=args.geweke_chains, geweke_length=args.geweke_length, size=args.size,
        alpha=args.alpha, progress=lambda message: print(message, file=sys.stderr, flush=True),
        proposal_draws=args.proposal_draws,
    )
    print(f"{args.model}: verifying the sampler derived from this model")
    print(report.table(strict=args.strict))
    return 0 if (report.passed_strict if args.strict else report.passed) else 1


COMMANDS = {"check": cmd_check, "fmt": cmd_fmt, "simulate": cmd_simulate, "sample": cmd_sample,
            "verify": cmd_verify, "export": cmd_export, "report": cmd_report}


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.WARNING,
                        format="sppl: %(levelname)s: %(message)s")
    try:
        return COMMANDS[args.command](args)
    except SpplError as e:
        if args.debug:
            raise
        print(f"error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of the output went away (`sppl check m.scn | head`): nothing to tell
        # it, and Python's flush at exit must not fail on the pipe again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
