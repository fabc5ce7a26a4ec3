"""Property-based fuzzing (hypothesis): bad input only ever raises sppl's own error type.

- Random and mutated model texts compile or raise ``ModelError`` with a position.
- Random and mutated ``transforms.json`` files, images and depth maps load or raise
  ``SpplError``.
- Extreme but valid scenes (tiny and huge noise scales, objects far outside every camera, no
  objects, fifty objects) score finitely and the chain keeps running from them.
- Random command lines of every subcommand (the folder's files in every place, numbers of every
  kind, stray words) exit with 0, 1 or 2, never show a traceback, and when they fail leave the
  folder as it was.

The default command runs a hundred examples of each (twenty scenes), a few seconds in all
(docs/errors.md gives the measured time); the ``slow`` marker runs the same properties with
many more (``python -m pytest -m slow tests/test_fuzz.py``). Hypothesis draws from a fixed
seed (``derandomize``), so a run is repeatable and a failure is reported with the smallest
input that shows it.
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from sppl.errors import ModelError, SpplError
from sppl.lang import compile_model

ROOT = Path(__file__).resolve().parent.parent
MODELS = sorted([*(ROOT / "models").glob("*.scn"), *(ROOT / "tests/golden/good").glob("*.scn")])
TEXTS = [p.read_text(encoding="utf-8") for p in MODELS if ".fmt." not in p.name]

QUICK = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
LONG = settings(QUICK, max_examples=1500)


# -- model texts ---------------------------------------------------------------------------------

TOKENS = [
    "class", "cube", "{", "}", "(", ")", "[", "]", ",", ":", "~", "=", "+", "-", "*", "/", "^",
    "count", "poisson", "normal", "gamma", "uniform", "categorical", "real", "positive",
    "periodic", "colour", "geometry", "box", "sphere", "cone", "cylinder", "at", "rotate",
    "sensor", "depth", "image", "likelihood", "gaussian", "sigma", "constraint", "no_overlap",
    "let", "inference", "render", "import", "from", "static", "ground", "change", "x", "y",
    "s", "c", "a", "pi", "red", "green", "0", "1", "-1", "2.5", "1e308", "1e-308", "0.0",
    "\n", " ", '"', "#", "integer", "floating", "scale", "pose", "mesh", "capsule", "if",
]
texts = st.one_of(
    st.text(alphabet=st.sampled_from(list("abcxyz_{}()[],:~=+-*/^.#\"\n 0123456789eE")),
            max_size=200),
    st.lists(st.sampled_from(TOKENS), max_size=80).map(" ".join),
    st.text(max_size=100),  # any unicode, control characters included
)


@st.composite
def mutated_models(draw):
    """A shipped model with a few edits: spans cut, repeated or moved, tokens and numbers
    put in at random places."""
    text = draw(st.sampled_from(TEXTS))
    for _ in range(draw(st.integers(1, 4))):
        n = len(text)
        i = draw(st.integers(0, n))
        j = draw(st.integers(i, min(n, i + 40)))
        op = draw(st.sampled_from(["cut", "repeat", "insert", "number", "swap-lines"]))
        if op == "cut":
            text = text[:i] + text[j:]
        elif op == "repeat":
            text = text[:j] + text[i:j] + text[j:]
        elif op == "insert":
            text = text[:i] + " " + draw(st.sampled_from(TOKENS)) + " " + text[i:]
        elif op == "number":
            number = draw(st.sampled_from(["0", "-0", "-3", "1e400", "-1e400", "1e-400", "nan",
                                           "inf", "123456789012345678901234567890", "0.5"]))
            text = text[:i] + number + text[j:]
        else:
            lines = text.split("\n")
            a, b = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
    return text


def compiles_or_model_error(text: str) -> None:
    try:
        compile_model(text, "fuzz.scn")
    except ModelError as e:
        errors = getattr(e, "errors", [e])
        for err in errors:
            assert err.span is not None and err.span.line >= 1 and err.span.column >= 1, str(err)
            assert err.path is not None
        assert str(e)


@QUICK
@given(texts)
def test_random_model_text_only_raises_model_errors_with_a_position(text):
    compiles_or_model_error(text)


@QUICK
@given(mutated_models())
def test_mutated_model_only_raises_model_errors_with_a_position(text):
    compiles_or_model_error(text)


@pytest.mark.slow
@LONG
@given(st.one_of(texts, mutated_models()))
def test_model_texts_long(text):
    compiles_or_model_error(text)


# -- observation folders -------------------------------------------------------------------------

W, H = 8, 6
json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
              st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12)),
    lambda inner: st.one_of(st.lists(inner, max_size=5),
                            st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12,
)
KEYS = ["fl_x", "fl_y", "cx", "cy", "w", "h", "depth_max", "near", "depth_type", "file_path",
        "depth_file_path", "transform_matrix", "look_at", "camera_model", "k1",
        "camera_convention", "integer_depth_scale", "camera_angle_x", "name", "modalities",
        "frames"]


def good_transforms() -> dict:
    from sppl.data.camera import look_at

    return {"fl_x": 9.0, "w": W, "h": H, "frames": [{
        "file_path": "images/a.png", "depth_file_path": "depth/a.npy",
        "transform_matrix": look_at([3.0, -2.0, 1.5], [0.0, 0.0, 0.5]).tolist()}]}


@st.composite
def mutated_transforms(draw):
    data = good_transforms()
    for _ in range(draw(st.integers(1, 4))):
        where = data if draw(st.booleans()) else data["frames"][0]
        if not isinstance(where, dict):
            break
        key = draw(st.sampled_from(KEYS))
        op = draw(st.sampled_from(["set", "delete", "matrix-entry"]))
        if op == "delete":
            where.pop(key, None)
        elif op == "set":
            where[key] = draw(json_values)
        elif isinstance(data.get("frames"), list) and data["frames"] and isinstance(
                data["frames"][0], dict) and isinstance(
                data["frames"][0].get("transform_matrix"), list):
            m = data["frames"][0]["transform_matrix"]
            r, c = draw(st.integers(0, 3)), draw(st.integers(0, 3))
            if r < len(m) and isinstance(m[r], list) and c < len(m[r]):
                m[r][c] = draw(json_values)
        if not isinstance(data.get("frames"), list) or not data["frames"]:
            break
    return data


def png_bytes(array: np.ndarray, mode: str | None = None) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(array, mode).save(buf, format="PNG")
    return buf.getvalue()


def npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


GOOD_PNG = png_bytes(np.full((H, W, 3), 128, np.uint8))
GOOD_NPY = npy_bytes(np.full((H, W), 2.0, np.float32))


@st.composite
def mutated_bytes(draw, good: bytes):
    data = bytearray(good)
    op = draw(st.sampled_from(["flip", "truncate", "random", "empty", "append"]))
    if op == "flip":
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] = draw(st.integers(0, 255))
    elif op == "truncate":
        data = data[: draw(st.integers(0, len(data)))]
    elif op == "random":
        data = bytearray(draw(st.binary(max_size=300)))
    elif op == "empty":
        data = bytearray()
    else:
        data += draw(st.binary(min_size=1, max_size=50))
    return bytes(data)


dtypes = st.sampled_from(["u1", "u2", "i4", "f2", "f4", "f8", "bool", "c8", "O", "U3"])
shapes = st.sampled_from([(H, W), (H, W, 1), (H, W, 2), (H, W, 3), (H, W, 4), (W, H), (0,),
                          (H,), (1, 1), (H, W, 3, 1)])


@st.composite
def arrays(draw):
    dtype, shape = draw(dtypes), draw(shapes)
    values = draw(st.sampled_from([0, 1, 2.0, 255, 65535, -1, np.nan, np.inf, 2000.0]))
    try:
        # NaN and inf cast to an integer type are whatever the platform makes of them: any
        # array is fair input here, so numpy's warning about it is not news.
        with np.errstate(invalid="ignore"):
            return np.full(shape, values).astype(dtype)
    except (ValueError, OverflowError):
        return np.zeros(shape, dtype)


@st.composite
def image_files(draw):
    """Any PNG Pillow can write from an array of any mode and size, or broken bytes."""
    if draw(st.booleans()):
        return draw(mutated_bytes(GOOD_PNG))
    a = draw(arrays())
    try:
        return png_bytes(a)
    except (TypeError, ValueError, KeyError, OSError):
        return png_bytes(np.zeros((draw(st.integers(1, 9)), draw(st.integers(1, 9))), np.uint8))


@st.composite
def depth_files(draw):
    kind = draw(st.sampled_from(["npy", "npy-bytes", "png"]))
    if kind == "npy":
        return "depth/a.npy", npy_bytes(draw(arrays()))
    if kind == "npy-bytes":
        return "depth/a.npy", draw(mutated_bytes(GOOD_NPY))
    return "depth/a.png", draw(image_files())


def loads_or_spplerror(folder: Path) -> None:
    from sppl.data.observations import load_cameras, load_observations

    for load in (load_observations, load_cameras):
        try:
            load(folder)
        except SpplError as e:
            assert str(e) and "Traceback" not in str(e)


def write_folder(folder: Path, transforms: bytes | dict, image: bytes = GOOD_PNG,
                 depth: tuple[str, bytes] = ("depth/a.npy", GOOD_NPY)) -> Path:
    if folder.exists():
        shutil.rmtree(folder)
    (folder / "images").mkdir(parents=True)
    (folder / "depth").mkdir()
    (folder / "images" / "a.png").write_bytes(image)
    (folder / depth[0]).write_bytes(depth[1])
    if isinstance(transforms, dict):
        if depth[0] != "depth/a.npy" and isinstance(transforms.get("frames"), list):
            for f in transforms["frames"]:
                if isinstance(f, dict) and f.get("depth_file_path") == "depth/a.npy":
                    f["depth_file_path"] = depth[0]
        transforms = json.dumps(transforms).encode()
    (folder / "transforms.json").write_bytes(transforms)
    return folder


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def test_the_unmutated_folder_loads(scratch):
    from sppl.data.observations import load_observations

    assert len(load_observations(write_folder(scratch / "good", good_transforms()))) == 1


@QUICK
@given(transforms=mutated_transforms())
def test_mutated_transforms_only_raise_sppl_errors(scratch, transforms):
    loads_or_spplerror(write_folder(scratch / "t", transforms))


@QUICK
@given(raw=st.one_of(st.binary(max_size=200), mutated_bytes(json.dumps(good_transforms()).encode())))
def test_random_transforms_bytes_only_raise_sppl_errors(scratch, raw):
    loads_or_spplerror(write_folder(scratch / "b", raw))


@QUICK
@given(image=image_files(), depth=depth_files())
def test_random_and_mutated_images_and_depth_maps_only_raise_sppl_errors(scratch, image, depth):
    loads_or_spplerror(write_folder(scratch / "i", good_transforms(), image, depth))


@pytest.mark.slow
@LONG
@given(transforms=st.one_of(mutated_transforms(), st.just(good_transforms())),
       image=image_files(), depth=depth_files())
def test_observation_folders_long(scratch, transforms, image, depth):
    loads_or_spplerror(write_folder(scratch / "l", transforms, image, depth))


# -- extreme but valid scenes --------------------------------------------------------------------


@pytest.fixture(scope="module")
def world(tmp_path_factory, require_gl):
    """shapes.scn and a 16x16 RGB and depth observation of one cube."""
    from sppl.cli import main
    from sppl.data.observations import load_observations
    from sppl.infer.chain import Sampler
    from sppl.lang import load_model
    from sppl.render import Renderer
    from sppl.scoring.scorer import Scorer

    d = tmp_path_factory.mktemp("extreme")
    cameras = {"w": 16, "h": 16, "fl_x": 18.0, "fl_y": 18.0, "cx": 8.0, "cy": 8.0,
               "depth_max": 8.0, "frames": [
                   {"name": "rgb", "modalities": ["rgb"], "look_at": {
                       "eye": [3.0, -2.5, 2.4], "target": [0, 0, 0.3], "up": [0, 0, 1]}},
                   {"name": "depth", "modalities": ["depth"], "look_at": {
                       "eye": [-3.0, -2.0, 2.6], "target": [0, 0, 0.3], "up": [0, 0, 1]}}]}
    (d / "cameras.json").write_text(json.dumps(cameras))
    model_path = ROOT / "models" / "shapes.scn"
    assert main(["simulate", str(model_path), "--cameras", str(d / "cameras.json"), "--out",
                 str(d / "obs"), "--seed", "4"]) == 0
    model = load_model(model_path)
    scorer = Scorer(model, load_observations(d / "obs"), Renderer(model.render))
    return model, lambda seed: Sampler(model, scorer, np.random.default_rng(seed))


def grid_scene(model, classes: list[int], far: bool, sizes: list[float]):
    """Objects on a grid 3 m apart (so none overlap), around the cameras' target or 10 km
    away, of the given classes and sizes (m)."""
    from sppl.model.trace import make_object

    objects = []
    for k, (c, size) in enumerate(zip(classes, sizes)):
        cls = model.classes[c]
        origin = 1e4 if far else 0.0
        values = {"x": origin + 3.0 * (k % 8) - 10.5, "y": origin + 3.0 * (k // 8) - 10.5}
        for p in cls.parameters:
            if p.name in values:
                continue
            if p.name in ("s", "r", "h"):
                values[p.name] = size
            elif p.domain.describe().startswith("periodic"):
                values[p.name] = 0.1
            else:
                values[p.name] = p.prior.sample(np.random.default_rng(k))
        objects.append(make_object(model, cls, values))
    return tuple(objects)


@st.composite
def extreme_scenes(draw, model):
    """0 to 50 objects, near or far, from a millimetre to a metre; noise scales from 1e-8 to
    1e8."""
    n = draw(st.sampled_from([0, 1, 2, 5, 50]))
    classes = draw(st.lists(st.integers(0, len(model.classes) - 1), min_size=n, max_size=n))
    sizes = draw(st.lists(st.sampled_from([1e-3, 0.3, 1.0]), min_size=n, max_size=n))
    objects = grid_scene(model, classes, draw(st.booleans()), sizes)
    noise = {kind: {p.name: draw(st.sampled_from([1e-8, 1e-3, 1.0, 1e3, 1e8]))
                    for p in sensor.noise} for kind, sensor in model.sensors.items()}
    return objects, noise


def check_extreme(world, data, sweeps: int) -> None:
    model, make_sampler = world
    objects, noise = data.draw(extreme_scenes(model))
    run_from(make_sampler(data.draw(st.integers(0, 2**16))), objects, noise, sweeps)


def run_from(sampler, objects, noise, sweeps: int) -> None:
    trace = sampler.make_trace(objects, noise)
    assert math.isfinite(trace.log_likelihood), (len(objects), noise)
    if not math.isfinite(trace.log_prior):  # a prior that rules the values out is no bug
        return
    assert math.isfinite(trace.score)
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
        assert math.isfinite(trace.score), "the chain reached a state with no finite score"
    assert sum(n for n, _ in sampler.stats.counts.values()) > 0


@settings(QUICK, max_examples=20)
@given(data=st.data())
def test_extreme_but_valid_scenes_score_finitely_and_the_chain_runs(world, data):
    check_extreme(world, data, sweeps=1)


@pytest.mark.slow
@settings(QUICK, max_examples=200)
@given(data=st.data())
def test_extreme_scenes_long(world, data):
    check_extreme(world, data, sweeps=5)


@pytest.mark.parametrize(
    "n, far, size, sigma",
    [(0, False, 1.0, 1e-8), (0, False, 1.0, 1e8), (50, False, 0.3, 1e-8), (50, True, 1.0, 1e8),
     (3, True, 1e-3, 1.0), (50, False, 1e-3, 1e-3)],
    ids=["empty-tiny-noise", "empty-huge-noise", "50-near-tiny-noise", "50-far-huge-noise",
         "3-far-millimetre", "50-millimetre"],
)
def test_the_named_extremes(world, n, far, size, sigma):
    """The corners of the space the property above draws from, each for sure."""
    model, make_sampler = world
    objects = grid_scene(model, [k % len(model.classes) for k in range(n)], far, [size] * n)
    assert len(objects) == n and all(math.isfinite(o.log_prior) for o in objects)
    noise = {kind: {p.name: sigma for p in sensor.noise} for kind, sensor in model.sensors.items()}
    run_from(make_sampler(n), objects, noise, sweeps=1)


# -- command lines -------------------------------------------------------------------------------

# What a hurried user types: the folder's own files and folders in every place, numbers of every
# kind. Only values that keep a run to a few sweeps are offered (--steps is always given, no
# second chain process), so that every example ends in a second or so.
CLI_PATHS = ["model.scn", "huge.scn", "obs", "obs/transforms.json", "obs/images/a.png", "run",
             "nowhere", "", ".", "notes.txt", "mine", "run/summary.json"]
CLI_OUTS = ["new", "run", "obs", ".", "notes.txt", "model.scn", "new/deeper", "mine",
            "run/chain_0", "obs/new"]
CLI_NUMBERS = ["0", "-1", "1", "x", "1e3", "nan", "inf", "99999999999999999999999", "-0", ""]
CLI_STEPS = ["0", "-2", "x", "1", "2", "nan"]
CLI_OPTIONS = {
    "sample": {"--obs": CLI_PATHS, "--out": CLI_OUTS, "--seed": CLI_NUMBERS,
               "--thin": CLI_NUMBERS, "--burn": CLI_NUMBERS, "--chains": ["0", "-1", "1", "x"],
               "--resume": CLI_PATHS, "--checkpoint-every": CLI_NUMBERS, "--force": None,
               "--lockstep": None, "-q": None},
    "simulate": {"--cameras": CLI_PATHS, "--out": CLI_OUTS, "--seed": CLI_NUMBERS,
                 "--scene": [*CLI_PATHS, "obs/scene.json"], "--depth-format": ["npy", "png",
                                                                               "exr"],
                 "--force": None},
    "check": {},
    "fmt": {"--check": None, "--write": None},
    "export": {"--out": ["p.nc", "nowhere/p.nc", "obs", "model.scn", "run/x.nc"]},
    "verify": {"--seed": CLI_NUMBERS,
               "--alpha": ["0", "1", "2", "nan", "x", "0.5"], "--size": ["0", "x", "3"],
               "--geweke-chains": ["0", "1", "x"]},
    "report": {"--truth": CLI_PATHS, "--no-truth": None, "--model": CLI_PATHS,
               "--obs": CLI_PATHS},
}


@st.composite
def command_lines(draw):
    command = draw(st.sampled_from(sorted(CLI_OPTIONS)))
    options = CLI_OPTIONS[command]
    args = [command]
    if command == "report":  # a real report takes seconds: only runs it cannot make one of
        args.append(draw(st.sampled_from([p for p in CLI_PATHS if p != "run"])))
    elif command != "sample" or draw(st.booleans()):
        args.append(draw(st.sampled_from(CLI_PATHS)))
    chosen = draw(st.lists(st.sampled_from(sorted(options)), max_size=5, unique=True)) \
        if options else []
    for name in chosen:
        args.append(name)
        if options[name] is not None:
            args.append(draw(st.sampled_from(options[name])))
    if command == "sample":
        args += ["--steps", draw(st.sampled_from(CLI_STEPS)), "-q"]
    if command == "verify":  # a short prior recovery only (the Geweke test renders)
        args += ["--steps", draw(st.sampled_from(["0", "x", "-1", "99", "100"])), "--no-geweke"]
    if draw(st.booleans()):  # and the odd stray word or option
        args.insert(draw(st.integers(1, len(args))),
                    draw(st.sampled_from(["--nonsense", "extra", "--", "-", "--steps"])))
    return args


@pytest.fixture(scope="module")
def cli_template(tmp_path_factory, require_gl):
    """A folder holding a good model, a model with a huge count, observations, a finished run
    of four sweeps and some files of the user's own."""
    from test_errors import MODEL, good

    from sppl.cli import main

    d = tmp_path_factory.mktemp("cli-template")
    good(d)
    (d / "huge.scn").write_text(MODEL.replace("count ~ poisson(1)", "count ~ poisson(1e6)", 1))
    (d / "notes.txt").write_text("mine")
    (d / "mine").mkdir()
    (d / "mine" / "thesis.tex").write_text("mine")
    old = Path.cwd()
    os.chdir(d)
    try:
        assert main(["sample", "model.scn", "--obs", "obs", "--out", "run", "--steps", "4",
                     "-q"]) == 0
    finally:
        os.chdir(old)
    return d


def check_command_line(args, template: Path, scratch: Path) -> None:
    folder = scratch / "cli"
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(template, folder, symlinks=True)
    from test_misuse import run_main, tree

    before = tree(folder)
    code, err = run_main(args, folder)
    assert code in (0, 1, 2), (args, code, err)
    assert "Traceback" not in err, (args, err)
    if code != 0:
        assert err.strip(), args  # a failure says why
        assert tree(folder) == before, (args, "a failed command changed the folder")


@settings(QUICK, max_examples=40)
@given(args=command_lines())
def test_random_command_lines_end_in_a_message_and_change_nothing_when_they_fail(
        cli_template, scratch, args):
    check_command_line(args, cli_template, scratch)


@pytest.mark.slow
@settings(QUICK, max_examples=600)
@given(args=command_lines())
def test_command_lines_long(cli_template, scratch, args):
    check_command_line(args, cli_template, scratch)
