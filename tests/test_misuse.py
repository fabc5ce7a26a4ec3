"""A sweep of the bad inputs and misuses a new user tries, every command: each gets exit status
1 (or 2 for a command line argparse refuses) and a short message, never a traceback, and
changes nothing on disk: no folder made, half-written or deleted.

The folder each runs in holds a good model, an observation folder and a finished run, so that
only the misuse is wrong. The single-line messages of the ones sppl words itself are in
docs/errors.md (tests/test_errors.py); this sweep checks the behaviour of many more.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from false_alarms import EACH
from test_errors import MODEL, good

from sppl.cli import main

HUGE = MODEL.replace("count ~ poisson(1)", "count ~ poisson(1e6)", 1)
SAMPLE = ["sample", "model.scn", "--obs", "obs", "-q"]
SIM = ["simulate", "model.scn", "--cameras", "obs/transforms.json"]

MISUSES = [
    # sample: options
    [*SAMPLE, "--out", "new", "--steps", "0"],
    [*SAMPLE, "--out", "new", "--steps", "-3"],
    [*SAMPLE, "--out", "new", "--steps", "x"],
    [*SAMPLE, "--out", "new", "--thin", "0"],
    [*SAMPLE, "--out", "new", "--chains", "0"],
    [*SAMPLE, "--out", "new", "--chains", "-2"],
    [*SAMPLE, "--out", "new", "--seed", "-1"],
    [*SAMPLE, "--out", "new", "--seed", "99999999999999999999999"],
    [*SAMPLE, "--out", "new", "--seed", "1e3"],
    [*SAMPLE, "--out", "new", "--burn", "-1"],
    [*SAMPLE, "--out", "new", "--checkpoint-every", "-1"],
    [*SAMPLE, "--out", "new", "--checkpoint-every", "nan"],
    [*SAMPLE, "--out", "new", "--lockstep", "--seed", "-4"],
    ["sample", "model.scn", "--out", "new"],
    ["sample", "--obs", "obs", "--out", "new"],
    ["sample"],
    # sample: paths
    ["sample", "obs", "--obs", "obs", "--out", "new", "-q"],
    ["sample", "obs/images/a.png", "--obs", "obs", "--out", "new", "-q"],
    ["sample", "model.scn", "--obs", "model.scn", "--out", "new", "-q"],
    ["sample", "model.scn", "--obs", "nowhere", "--out", "new", "-q"],
    ["sample", "huge.scn", "--obs", "obs", "--out", "new", "-q", "--steps", "5"],
    [*SAMPLE, "--out", "run", "--steps", "5"],
    [*SAMPLE, "--out", "model.scn", "--steps", "5", "--force"],
    [*SAMPLE, "--out", "obs", "--steps", "5", "--force"],
    [*SAMPLE, "--out", ".", "--steps", "5", "--force"],
    [*SAMPLE, "--out", "notes.txt/new", "--steps", "5"],
    [*SAMPLE, "--out", "mine", "--steps", "5", "--force"],
    # sample --resume
    ["sample", "--resume", "nowhere"],
    ["sample", "--resume", "obs"],
    ["sample", "--resume", "model.scn"],
    ["sample", "--resume", "run"],
    ["sample", "--resume", "run", "--force", "--steps", "9"],
    ["sample", "--resume", "run", "--out", "other", "--steps", "9"],
    ["sample", "--resume", "run", "--seed", "9", "--steps", "9"],
    ["sample", "--resume", "run", "--chains", "3", "--steps", "9"],
    ["sample", "--resume", "run", "--steps", "9", "--seed", "-1"],
    # simulate
    [*SIM[:2], "--cameras", "nowhere.json", "--out", "sim"],
    [*SIM[:2], "--cameras", "model.scn", "--out", "sim"],
    [*SIM, "--out", "sim", "--scene", "nowhere.json"],
    [*SIM, "--out", "sim", "--scene", "model.scn"],
    [*SIM, "--out", "sim", "--depth-format", "exr"],
    [*SIM, "--out", "sim", "--seed", "-5"],
    [*SIM, "--out", "obs"],
    [*SIM, "--out", "run", "--force"],
    ["simulate", "huge.scn", "--cameras", "obs/transforms.json", "--out", "sim"],
    ["simulate", "model.scn", "--out", "sim"],
    # check and fmt
    ["check", "nowhere.scn"],
    ["check", "obs"],
    ["check", "obs/images/a.png"],
    ["check", "empty.scn"],
    ["check", "huge.scn"],
    ["fmt", "nowhere.scn"],
    ["fmt", "obs"],
    ["fmt", "--check", "--write", "model.scn"],
    ["fmt", "obs/images/a.png"],
    # export and report
    ["export", "nowhere"],
    ["export", "obs"],
    ["export", "model.scn"],
    ["export", "run", "--out", "nowhere/deeper/p.nc"],
    ["export", "run", "--out", "model.scn"],  # it replaced the model file with the posterior
    ["export", "run", "--out", "obs"],
    ["report", "nowhere"],
    ["report", "obs"],
    ["report", "run", "--truth", "scene.json", "--no-truth"],
    ["report", "run", "--truth", "nowhere.json"],
    ["report", "run", "--model", "nowhere.scn"],
    # verify
    ["verify", "model.scn", "--steps", "5"],
    ["verify", "model.scn", "--alpha", "2"],
    ["verify", "model.scn", "--alpha", "nan"],
    ["verify", "model.scn", "--seed", "-1"],
    ["verify", "model.scn", "--size", "1"],
    ["verify", "huge.scn", "--no-geweke"],
    # the command line itself
    [],
    ["nonsense"],
    ["sample", "--no-such-option"],
]


def tree(folder: Path) -> dict[str, tuple]:
    """Every file and folder under ``folder``, a file with its size and modification time (a
    folder's own time changes when a lock file comes and goes: not a change to what it holds)."""
    found = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        found[str(p.relative_to(folder))] = (
            ("folder",) if p.is_dir() else ("file", st.st_size, st.st_mtime_ns))
    return found


def run_main(args: list[str], folder: Path) -> tuple[int, str]:
    out, err, old = io.StringIO(), io.StringIO(), Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            try:
                code = main(args)
            except SystemExit as e:  # argparse: a usage error, or --help
                code = e.code if isinstance(e.code, int) else 1
    finally:
        os.chdir(old)
    return code, err.getvalue()


@pytest.fixture(scope="module")
def place(tmp_path_factory, require_gl) -> Path:
    d = tmp_path_factory.mktemp("misuse")
    good(d)
    (d / "huge.scn").write_text(HUGE)
    (d / "empty.scn").write_text("")
    (d / "notes.txt").write_text("mine")
    (d / "mine").mkdir()
    (d / "mine" / "thesis.tex").write_text("mine")
    code, err = run_main(["sample", "model.scn", "--obs", "obs", "--out", "run", "--steps", "4",
                          "-q"], d)
    assert code == 0, err
    return d


@pytest.mark.parametrize("args", MISUSES, ids=lambda a: " ".join(a) or "(nothing)")
def test_a_misuse_gets_a_message_and_changes_nothing(place, args):
    before = tree(place)
    code, err = run_main(args, place)
    assert code in (1, 2), err
    assert "Traceback" not in err and err.strip(), err
    if code == 1:  # sppl's own message: "error: ...", one line (a model error: and its excerpt)
        lines = err.strip().splitlines()
        assert lines[0].startswith("error: "), err
        assert len(lines) == 1 or lines[-1].strip().endswith("^"), err
    assert tree(place) == before, "a failed command changed the folder"


def test_the_sweep_is_the_size_of_a_new_users_afternoon():
    assert len(MISUSES) >= 67


def test_a_bad_seed_leaves_no_run_folder_behind(place):
    """`--seed -1` sampled into an empty run folder and then failed with a traceback."""
    for seed in ("-1", "99999999999999999999999"):
        code, err = run_main([*SAMPLE, "--out", "fresh/run", "--seed", seed, "--steps", "2"],
                             place)
        assert code == 1 and "--seed must be" in err and "Traceback" not in err, err
        assert not (place / "fresh").exists()


def test_the_largest_seed_samples_and_writes_its_posterior_file(place):
    """A seed at the top of the range goes through to posterior.nc (a larger one used to
    sample and then fail writing it)."""
    import xarray as xr

    out = place.parent / "top-seed"
    code, err = run_main([*SAMPLE, "--out", str(out), "--seed", str(2**63 - 1), "--steps", "4"],
                         place)
    assert code == 0, err
    assert xr.open_datatree(out / "posterior.nc").attrs["seed"] == 2**63 - 1
    shutil.rmtree(out)


def test_a_run_that_fails_before_its_first_sample_leaves_nothing(place, monkeypatch):
    """A failure after the folder was made (here the scorer's set-up) removes what was
    written; the folder it made goes too."""
    import sppl.runs.run

    def broken(*args, **kwargs):
        raise sppl.runs.run.RunError("the starting scene's log joint is NaN")

    monkeypatch.setattr(sppl.runs.run, "Scorer", broken)
    before = tree(place)
    code, err = run_main([*SAMPLE, "--out", "made/here", "--steps", "3"], place)
    assert code == 1 and "NaN" in err, err
    assert tree(place) == before


def test_simulate_of_a_huge_count_with_a_bound_ends_with_a_message(place, capsys):
    """poisson(1e6) under `max_count`: drawn exactly, not by rejection that never ends."""
    bounded = MODEL.replace("count ~ poisson(1)", "count ~ poisson(1e6)\n    max_count = 2", 1)
    folder = place.parent / "bounded"
    folder.mkdir()
    (folder / "model.scn").write_text(bounded)
    code, err = run_main(["simulate", "model.scn", "--cameras",
                          str(place / "obs" / "transforms.json"), "--out", "sim", "--seed", "1"],
                         folder)
    assert code == 0, err
    import json

    cubes = [o for o in json.loads((folder / "sim" / "scene.json").read_text())["objects"]
             if o["class"] == "cube"]
    assert len(cubes) == 2  # P(N = 2 | N <= 2) = 1 - 2e-6 under Poisson(1e6)


@pytest.mark.false_alarm(EACH)
def test_a_truncated_count_is_its_truncated_poisson_even_far_below_the_rate(false_alarm):
    """The exact draw that replaces endless rejection: frequencies against the pmf, by a
    chi-square test at the test's false-alarm rate (fixed seed)."""
    from scipy import stats

    from sppl.model.types import ObjectClass

    cls = ObjectClass("c", 12.0, (), lambda v: (), max_count=4)
    rng = np.random.default_rng(0)
    n = 4000
    draws = np.array([cls.sample_count(rng) for _ in range(n)])
    pmf = stats.poisson.pmf(np.arange(5), 12.0)
    pmf /= pmf.sum()
    observed = np.bincount(draws, minlength=5)
    assert stats.chisquare(observed, n * pmf).pvalue > false_alarm
