"""Every bad input a user can give gets one clear message and exit status 1, no traceback.

``CASES`` is the list of bad inputs tried. Each is a test, and the table in docs/errors.md is
made from them: ``python tests/test_errors.py`` rewrites it after a deliberate change to a
message, and ``test_the_table_in_docs_errors_md_is_these_cases`` fails when the two drift.
Each case runs in a fresh folder, with paths relative to it, so the messages are the same on
every machine.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "errors.md"
BEGIN, END = "<!-- cases: begin -->", "<!-- cases: end -->"

W, H = 8, 6
MODEL = (ROOT / "models" / "shapes.scn").read_text(encoding="utf-8")
SAMPLE = ["sample", "model.scn", "--obs", "obs", "--out", "run", "-q"]
FORCE = ["--steps", "5", "--force"]  # few steps: a --force that wrongly goes ahead ends soon


def _pose(eye=(3.0, -2.0, 1.5), target=(0.0, 0.0, 0.5)):
    from sppl.data.camera import look_at

    return look_at(eye, target).tolist()


def observations(d: Path, frame=(), top=(), rgb=None, depth=None, depth_name="depth/a.npy"):
    """A one-camera observation folder: an 8x6 image and a depth map; ``frame`` and ``top``
    override (None removes) keys of the frame and of the top level of transforms.json."""
    (d / "obs" / "images").mkdir(parents=True)
    (d / "obs" / "depth").mkdir()
    image = np.full((H, W, 3), 128, np.uint8) if rgb is None else rgb
    Image.fromarray(image).save(d / "obs" / "images" / "a.png")
    depth = np.full((H, W), 2.0, np.float32) if depth is None else depth
    if depth_name.endswith(".npy"):
        np.save(d / "obs" / depth_name, depth)
    else:
        Image.fromarray(depth).save(d / "obs" / depth_name)
    entry = {"file_path": "images/a.png", "depth_file_path": depth_name,
             "transform_matrix": _pose(), **dict(frame)}
    transforms = {"fl_x": 9.0, "w": W, "h": H, **dict(top)}
    entry = {k: v for k, v in entry.items() if v is not None}
    transforms = {k: v for k, v in transforms.items() if v is not None} | {"frames": [entry]}
    (d / "obs" / "transforms.json").write_text(json.dumps(transforms))


def _depth_sensor(body: str) -> str:
    """The shipped model with another depth sensor."""
    old = re.search(r"sensor depth \{.*?\n\}", MODEL, re.DOTALL)
    assert old is not None
    return MODEL.replace(old.group(0), "sensor depth {\n    " + body + "\n}")


def model_file(d: Path, text: str = MODEL) -> None:
    (d / "model.scn").write_text(text, encoding="utf-8")


def good(d: Path) -> None:
    model_file(d)
    observations(d)


def with_frame(**frame):
    return lambda d: (model_file(d), observations(d, frame=frame))


def with_top(**top):
    return lambda d: (model_file(d), observations(d, top=top))


def with_files(**files):
    return lambda d: (model_file(d), observations(d, **files))


def then(first: Callable[[Path], None], second: Callable[[Path], None]):
    return lambda d: (first(d), second(d))


def write(name: str, data: bytes | str):
    def make(d: Path) -> None:
        path = d / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(data, bytes):
            path.write_bytes(data)
        else:
            path.write_text(data)

    return make


def a_run(steps=10, done=10, **meta):
    """A run folder as ``sppl sample`` leaves it, without sampling: its record and a
    checkpoint at step ``done``."""

    def make(d: Path) -> None:
        good(d)
        run = d / "run"
        run.mkdir()
        record = {"seed": 0, "steps": steps, "thin": 1, "model": "model.scn",
                  "observations": "obs", **meta}
        (run / "run.json").write_text(json.dumps(record))
        (run / "checkpoint.json").write_text(json.dumps({"format": 1, "step": done}))

    return make


@dataclass(frozen=True)
class Case:
    name: str  # the test's id
    what: str  # the bad input, as the table in docs/errors.md names it
    args: list[str]  # the command after `sppl`
    setup: Callable[[Path], None]
    expect: str  # a part of the message it must get
    env: dict[str, str] = field(default_factory=dict)  # run as a separate process if given
    excerpt: bool = False  # a model error: the offending line and a caret follow the message
    unless: Callable[[], str | None] | None = None  # why the case can't be made here, if so


def a_two_chain_run(d: Path) -> None:
    """A run of two chains, stopped before either wrote anything, whose chain_1 folder has
    been replaced by a file: the second chain's worker process cannot write its samples."""
    a_run(steps=4, done=0, chains=2, chain_folders=["chain_0", "chain_1"])(d)
    (d / "run" / "checkpoint.json").unlink()
    (d / "run" / "chain_1").write_text("not a folder")


UNWRITABLE = "/sys/sppl-run"  # sysfs refuses mkdir even to root (chmod does not stop root)


def unwritable_is_unwritable() -> str | None:
    try:
        os.mkdir(UNWRITABLE)
    except PermissionError:
        return None
    except OSError as e:
        return f"mkdir {UNWRITABLE} fails here with {e.strerror}, not a permission error"
    os.rmdir(UNWRITABLE)
    return f"{UNWRITABLE} can be created on this machine"


def shear() -> list:
    m = np.array(_pose())
    m[:3, 0] += 0.3 * m[:3, 1]
    return m.tolist()


def scaled() -> list:
    m = np.array(_pose())
    m[:3, :3] *= 2.0
    return m.tolist()


def nan_matrix() -> list:
    m = np.array(_pose())
    m[1, 2] = float("nan")
    return m.tolist()


def reflected() -> list:
    m = np.array(_pose())
    m[:3, 2] *= -1
    return m.tolist()


CASES = [
    # -- model files --------------------------------------------------------------------------
    Case("model-missing", "model file missing", ["check", "nowhere.scn"], lambda d: None,
         "cannot read the model file"),
    Case("model-syntax", "model: syntax error", ["check", "model.scn"],
         lambda d: model_file(d, "clas cube {\n    count ~ poisson(1)\n}\n"), "model.scn:1:1",
         excerpt=True),
    Case("model-semantic", "model: unknown distribution (semantic error)",
         ["check", "model.scn"],
         lambda d: model_file(d, "class cube {\n    count ~ poisson(1)\n    s : positive ~ "
                                 "gama(2, 1)\n    geometry box(s, s, s) colour red\n}\n"),
         "did you mean",
         excerpt=True),
    Case("model-no-classes", "model with no classes", ["check", "model.scn"],
         lambda d: model_file(d, "sensor depth { likelihood gaussian  sigma : positive ~ "
                                 "gamma(2, 0.1) }\n"), "model.scn", excerpt=True),
    Case("model-no-geometry", "class with no geometry", ["check", "model.scn"],
         lambda d: model_file(d, "class cube {\n    count ~ poisson(1)\n    x : real ~ "
                                 "normal(0, 1)\n}\n"), "geometry", excerpt=True),
    Case("likelihood-option", "likelihood: unknown option", ["check", "model.scn"],
         lambda d: model_file(d, _depth_sensor("likelihood mixture(outliers = 0.1)\n    "
                                               "sigma : positive ~ gamma(2, 0.1)")),
         "no option `outliers`", excerpt=True),
    Case("likelihood-outlier-value", "likelihood: outlier probability outside [0, 1]",
         ["check", "model.scn"],
         lambda d: model_file(d, _depth_sensor("likelihood mixture(outlier = 1.5)\n    "
                                               "sigma : positive ~ gamma(2, 0.1)")),
         "must lie in [0, 1]", excerpt=True),
    Case("likelihood-outlier-domain", "likelihood: outlier prior reaching outside [0, 1]",
         ["check", "model.scn"],
         lambda d: model_file(d, _depth_sensor("likelihood mixture\n    sigma : positive ~ "
                                               "gamma(2, 0.1)\n    outlier : positive ~ "
                                               "gamma(1, 0.1)")),
         "is a probability", excerpt=True),
    Case("likelihood-no-prior", "likelihood: noise parameter without a prior",
         ["check", "model.scn"],
         lambda d: model_file(d, _depth_sensor("likelihood mixture\n    sigma : positive ~ "
                                               "gamma(2, 0.1)")),
         "needs a prior for its noise parameter `outlier`", excerpt=True),
    Case("model-render-prior", "model: a prior on a render parameter that does not exist",
         ["check", "model.scn"],
         lambda d: model_file(d, "class cube {\n    count ~ poisson(1)\n    geometry box(1, 1, "
                                 "1) colour rgb(1, 0, 0)\n}\nrender {\n    ambinet : interval(0, 1) ~ "
                                 "beta(4, 6)\n}\n"),
         "did you mean `ambient`", excerpt=True),
    # -- observation folders ------------------------------------------------------------------
    Case("obs-missing", "observation folder missing", SAMPLE, model_file, "not found"),
    Case("obs-empty", "observation folder empty", SAMPLE,
         lambda d: (model_file(d), (d / "obs").mkdir()), "empty"),
    Case("obs-no-transforms", "no transforms.json in the folder", SAMPLE,
         lambda d: (model_file(d), write("obs/notes.txt", "x")(d)), "no transforms.json"),
    Case("json-malformed", "transforms.json: not valid JSON", SAMPLE,
         then(good, write("obs/transforms.json", '{"frames": [\n  {"fl_x": }\n]}')),
         "not valid JSON"),
    Case("json-no-frames", "transforms.json: no frames", SAMPLE,
         then(good, write("obs/transforms.json", '{"fl_x": 500}')), "missing key 'frames'"),
    Case("json-no-pose", "transforms.json: frame without a pose", SAMPLE,
         with_frame(transform_matrix=None), "missing 'transform_matrix'"),
    Case("json-no-focal", "transforms.json: no focal length", SAMPLE,
         with_top(fl_x=None), "missing focal length"),
    Case("json-nan", "transforms.json: NaN intrinsics", SAMPLE,
         then(good, write("obs/transforms.json",
                          '{"fl_x": NaN, "frames": [{"file_path": "images/a.png", '
                          '"transform_matrix": %s}]}' % json.dumps(_pose()))),
         "must be a finite number"),
    Case("image-missing", "image file missing", SAMPLE,
         with_frame(file_path="images/b.png"), "not found"),
    Case("pose-scaled", "pose: scaled rotation", SAMPLE,
         with_frame(transform_matrix=scaled()), "not orthonormal"),
    Case("pose-shear", "pose: not orthonormal (shear)", SAMPLE,
         with_frame(transform_matrix=shear()), "not orthonormal"),
    Case("pose-nan", "pose: NaN in the matrix", SAMPLE,
         with_frame(transform_matrix=nan_matrix()), "NaN or inf"),
    Case("pose-reflection", "pose: a reflection (one axis flipped)", SAMPLE,
         with_frame(transform_matrix=reflected()), "determinant -1"),
    Case("pose-last-row", "pose: last row not 0 0 0 1", SAMPLE,
         with_frame(transform_matrix=[*_pose()[:3], [0, 0, 1, 1]]), "last row"),
    Case("pose-below-ground", "camera below the ground (y-up or world-to-camera pose)",
         SAMPLE, with_frame(transform_matrix=_pose((3.0, -2.0, -1.5))), "not above the ground"),
    Case("pose-sky", "camera that sees none of the ground", SAMPLE,
         with_frame(transform_matrix=_pose((3.0, -2.0, 1.5), (0.0, 0.0, 9.0))),
         "above the horizon"),
    Case("size-mismatch", "intrinsics not matching the image size", SAMPLE,
         with_top(w=16), "image is 8x6 pixels but the camera is 16x6"),
    Case("principal-point", "principal point off the image (intrinsics for another size)",
         SAMPLE, with_top(cx=320.0), "principal point"),
    Case("rgb-grey", "RGB image with 1 channel", SAMPLE,
         then(good, lambda d: Image.fromarray(np.zeros((H, W), np.uint8)).save(
             d / "obs/images/a.png")), "greyscale"),
    Case("rgb-grey-alpha", "RGB image with 2 channels", SAMPLE,
         then(good, lambda d: Image.fromarray(np.zeros((H, W, 2), np.uint8), "LA").save(
             d / "obs/images/a.png")), "greyscale"),
    Case("rgb-16bit-grey", "16-bit depth PNG given as the RGB image", SAMPLE,
         then(good, lambda d: Image.fromarray(np.full((H, W), 2000, np.uint16)).save(
             d / "obs/images/a.png")), "16-bit greyscale"),
    Case("rgb-garbage", "image file that is not an image", SAMPLE,
         then(good, write("obs/images/a.png", b"not a png")), "cannot read image"),
    Case("depth-8bit", "8-bit depth PNG where 16-bit is expected", SAMPLE,
         with_files(depth=np.full((H, W), 2, np.uint8), depth_name="depth/a.png"),
         "not 16-bit greyscale"),
    Case("depth-rgb-png", "depth PNG with 3 channels", SAMPLE,
         with_files(depth=np.full((H, W, 3), 2, np.uint8), depth_name="depth/a.png"),
         "not 16-bit greyscale"),
    Case("depth-channels", "depth .npy with 3 channels", SAMPLE,
         with_files(depth=np.ones((H, W, 3), np.float32)), "expected (H, W)"),
    Case("depth-int-npy", "depth .npy of integers", SAMPLE,
         with_files(depth=np.full((H, W), 2000, np.uint16)), "not float metres"),
    Case("depth-mm-npy", "depth .npy in millimetres", SAMPLE,
         with_files(depth=np.full((H, W), 2000.0, np.float32)), "millimetres"),
    Case("depth-m-png", "16-bit depth PNG in metres (wrong integer_depth_scale)", SAMPLE,
         with_files(depth=np.full((H, W), 2, np.uint16), depth_name="depth/a.png"),
         "wrong unit"),
    Case("depth-all-missing", "depth map all missing (zeros)", SAMPLE,
         with_files(depth=np.zeros((H, W), np.float32)), "every pixel of the depth map is missing"),
    Case("depth-all-nan", "depth map all NaN or inf", SAMPLE,
         with_files(depth=np.where(np.eye(H, W, dtype=bool), np.inf, np.nan).astype(np.float32)),
         "every pixel of the depth map is missing"),
    Case("depth-size", "depth map of another size than the image", SAMPLE,
         with_files(depth=np.full((H + 2, W), 2.0, np.float32)), "depth map is 8x8"),
    Case("depth-missing", "depth file named in transforms.json missing", SAMPLE,
         with_frame(depth_file_path="depth/b.npy"), "'depth/b.npy' not found"),
    # -- environment and options --------------------------------------------------------------
    Case("no-egl", "no EGL library (libEGL.so.1 missing)", SAMPLE, good, "apt-get install",
         env={"GLCONTEXT_LINUX_LIBEGL": "/nonexistent/libEGL.so.1"}),
    Case("no-egl-driver", "no EGL driver (Mesa's drivers missing)", SAMPLE, good,
         "libgl1-mesa-dri", env={"LIBGL_DRIVERS_PATH": "/nonexistent"}),
    Case("out-exists", "--out exists, without --force", SAMPLE,
         then(good, write("run/samples.jsonl", "")), "--force"),
    Case("out-unwritable", "--out that cannot be written (under a file)",
         [*SAMPLE[:-3], "--out", "notes.txt/run", "-q"], then(good, write("notes.txt", "x")),
         "cannot create the output folder"),
    Case("out-permission", "--out where creating a folder is not permitted",
         [*SAMPLE[:-3], "--out", UNWRITABLE, "-q"], good,
         "cannot create the output folder (Operation not permitted)",
         unless=unwritable_is_unwritable),
    Case("force-not-a-run", "--force on a folder that is not a run folder",
         [*SAMPLE, *FORCE], then(good, write("run/notes.txt", "mine")),
         "it holds notes.txt, which `sppl sample` does not write"),
    Case("force-a-file", "--force on a file",
         [*SAMPLE[:-3], "--out", "notes.txt", "-q", *FORCE],
         then(good, write("notes.txt", "mine")), "this is a file"),
    Case("force-the-observations", "--force on the observation folder",
         [*SAMPLE[:-3], "--out", "obs", "-q", *FORCE], good,
         "would delete obs, which --obs reads"),
    Case("force-holds-the-model", "--force on a folder holding the model file",
         ["sample", "in/model.scn", "--obs", "obs", "--out", "in", "-q", *FORCE],
         then(good, lambda d: os.renames(d / "model.scn", d / "in" / "model.scn")),
         "would delete in/model.scn, which the model argument reads"),
    Case("force-current-folder", "--force on the current folder",
         [*SAMPLE[:-3], "--out", ".", "-q", *FORCE], good,
         "would delete the current folder"),
    Case("force-run-as-obs", "simulate --force over a run folder",
         ["simulate", "model.scn", "--cameras", "obs/transforms.json", "--out", "run",
          "--force"],
         a_run(), "replaces only an observation folder"),
    Case("steps-zero", "--steps 0", [*SAMPLE, "--steps", "0"], good, "at least 1"),
    Case("seed-negative", "--seed below zero", [*SAMPLE, "--seed", "-1"], good,
         "--seed must be a whole number from 0 to 2**63 - 1"),
    Case("seed-huge", "--seed beyond 64 bits", [*SAMPLE, "--seed", "99999999999999999999999"],
         good, "--seed must be a whole number from 0 to 2**63 - 1"),
    Case("simulate-seed", "simulate --seed below zero",
         ["simulate", "model.scn", "--cameras", "obs/transforms.json", "--out", "sim",
          "--seed", "-1"], good, "--seed must be"),
    Case("burn-negative", "--burn below zero", [*SAMPLE, "--burn", "-5"], good,
         "--burn is a number of sweeps"),
    Case("count-huge", "a prior on more objects than a run can sample",
         ["check", "model.scn"],
         lambda d: model_file(d, MODEL.replace("count ~ poisson(1)", "count ~ poisson(1e6)", 1)),
         "more than 1000 objects", excerpt=True),
    Case("count-huge-simulate", "simulate from such a prior (it hung before)",
         ["simulate", "model.scn", "--cameras", "obs/transforms.json", "--out", "sim"],
         lambda d: (observations(d), model_file(
             d, MODEL.replace("count ~ poisson(1)", "count ~ poisson(1e6)", 1))),
         "more than 1000 objects", excerpt=True),
    Case("resume-not-run", "--resume of a folder that is not a run", ["sample", "--resume", "obs"],
         good, "not a run folder"),
    Case("resume-complete", "--resume of a finished run", ["sample", "--resume", "run"],
         a_run(), "already drawn 10 of 10 steps"),
    Case("resume-changed-model", "--resume after the model file changed",
         ["sample", "--resume", "run", "--steps", "20", "-q"],
         a_run(done=5, model_sha256="0" * 64), "model has changed"),
    Case("resume-seed", "--resume with another --seed",
         ["sample", "--resume", "run", "--seed", "3"], a_run(done=5), "--seed 3 differs"),
    Case("resume-lockstep", "--resume --lockstep of chains that ran in processes",
         ["sample", "--resume", "run", "--lockstep"],
         a_run(done=5, chains=2, chain_folders=["chain_0", "chain_1"]),
         "leave out --lockstep"),
    # -- several chains: errors found before the chains start, and in a chain's own process --
    Case("chains-bad-obs", "a bad observation with --chains 2", [*SAMPLE, "--chains", "2"],
         with_files(depth=np.zeros((H, W), np.float32)),
         "every pixel of the depth map is missing"),
    Case("chains-worker-fails", "a chain's process fails (its folder is a file)",
         ["sample", "--resume", "run", "-q"], a_two_chain_run, "chain 1 failed: run/chain_1"),
]


def run_case(case: Case, folder: Path) -> tuple[int, str]:
    """Exit status and stderr of the case's command, run in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    case.setup(folder)
    if case.env:  # environment variables read when the process starts: a process of its own
        env = {**os.environ, **case.env, "PYTHONPATH": str(ROOT)}
        r = subprocess.run([sys.executable, "-m", "sppl", *case.args], cwd=folder, env=env,
                           capture_output=True, text=True, timeout=300)
        return r.returncode, r.stderr
    from sppl.cli import main

    err, old = io.StringIO(), Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(case.args)
    finally:
        os.chdir(old)
    return code, err.getvalue()


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, tuple[int, str]]:
    base = tmp_path_factory.mktemp("errors")
    return {case.name: run_case(case, base / case.name) for case in CASES}


def test_the_case_names_are_unique():
    assert len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_bad_input_gets_one_clear_message(case, results):
    if case.unless and case.unless():
        pytest.skip(case.unless())
    code, err = results[case.name]
    assert code == 1, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and lines[0].startswith("error: "), err
    assert case.expect in lines[0], err
    if case.excerpt:  # the offending line of the model, and a caret under the column
        assert ":" in lines[0].split()[1] and lines[-1].strip().endswith("^"), err
    else:
        assert len(lines) == 1, err


def run_command(case: Case, folder: Path, *before: str) -> subprocess.CompletedProcess:
    """The case's command as a user runs it, ``python -m sppl [before...] ARGS``, in ``folder``."""
    folder.mkdir(parents=True)
    case.setup(folder)
    env = {**os.environ, **case.env, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "sppl", *before, *case.args], cwd=folder,
                          env=env, capture_output=True, text=True, timeout=300, check=False)


@pytest.mark.parametrize("name, raised, where", [
    ("obs-missing", "sppl.errors.ObservationError", "load_observations"),
    # The failure is in a chain's own process: its traceback comes with the parent's.
    ("chains-worker-fails", "sppl.errors.SpplError", "the chain's own traceback"),
])
def test_debug_shows_the_traceback_that_is_otherwise_left_out(tmp_path, name, raised, where):
    case = next(c for c in CASES if c.name == name)
    plain = run_command(case, tmp_path / "plain")
    assert plain.returncode == 1
    assert "Traceback" not in plain.stderr and len(plain.stderr.strip().splitlines()) == 1
    message = plain.stderr.strip().removeprefix("error: ")
    assert case.expect in message

    debug = run_command(case, tmp_path / "debug", "--debug")
    assert debug.returncode == 1, debug.stderr
    assert "Traceback (most recent call last):" in debug.stderr, debug.stderr
    assert where in debug.stderr
    assert debug.stderr.rstrip().endswith(f"{raised}: {message}"), debug.stderr
    if name == "chains-worker-fails":  # where in the chain it failed, not only that it did
        assert "FileExistsError" in debug.stderr and "in run_chain" in debug.stderr


def table(results: dict[str, tuple[int, str]]) -> str:
    rows = ["| bad input | command | message (exit status 1) |", "| --- | --- | --- |"]
    for case in CASES:
        message = results[case.name][1].strip().splitlines()[0].removeprefix("error: ")
        env = " ".join(f"{k}={v}" for k, v in case.env.items())
        command = " ".join([env, "sppl", *case.args]).strip()
        rows.append(f"| {case.what} | {_code(command)} | {_code(message)} |")
    return "\n".join(rows)


def _code(text: str) -> str:
    # Double backticks, so that a message quoting a command in backticks stays one span.
    return "`` " + text.replace("|", "\\|") + " ``"


def doc_table() -> str:
    text = DOC.read_text(encoding="utf-8")
    return text[text.index(BEGIN) + len(BEGIN) : text.index(END)].strip()


def test_the_table_in_docs_errors_md_is_these_cases(results):
    cannot = [f"{c.name}: {c.unless()}" for c in CASES if c.unless and c.unless()]
    if cannot:
        pytest.skip("the table has cases this machine cannot make: " + "; ".join(cannot))
    assert doc_table() == table(results), "run `python tests/test_errors.py` and review the diff"


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        found = {case.name: run_case(case, Path(tmp) / case.name) for case in CASES}
    text = DOC.read_text(encoding="utf-8")
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    DOC.write_text(text[:start] + "\n" + table(found) + "\n" + text[end:], encoding="utf-8")
    print(f"wrote {len(CASES)} cases to {DOC}")
