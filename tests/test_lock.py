"""One writer per run folder: a second `sppl sample` (new, --resume or --force) or `sppl
simulate` meets a one-line error naming the pid of the process writing the folder; a lock left
by a killed process is taken over; --force never deletes a folder a live process writes.

The first writer is a real `sppl sample` in a process of its own; the second is this process
(``main``), or a small holder process where only the lock matters.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_resume import small_observations

from sppl.cli import main
from sppl.output.samples import read_samples
from sppl.runs.lock import LOCK_FILE, FolderInUse, FolderLock, hold, holder

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def setup(tmp_path_factory, require_gl):
    d = tmp_path_factory.mktemp("lock")
    small_observations(d, ROOT)
    return ROOT / "models" / "shapes.scn", d / "obs"


def start_sample(model, obs, out, *more) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "sppl", "sample", str(model), "--obs", str(obs), "--out", str(out),
         "--steps", "1000000", "--seed", "3", "-q", *more],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_until_sampling(p: subprocess.Popen, out: Path, samples: str = "samples.jsonl") -> None:
    """Until ``p`` holds ``out`` and has written a sample (``samples``, a glob in ``out``)."""
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        if p.poll() is not None:
            pytest.fail(f"the first run ended: {p.communicate()[1]}")
        if holder(out) == p.pid and any(f.stat().st_size for f in out.glob(samples)):
            return
        time.sleep(0.1)
    p.kill()
    pytest.fail("the first run wrote no sample in 180 s")


def second(args: list[str], capsys) -> tuple[int, str]:
    code = main(args)
    return code, capsys.readouterr().err


def refused(code: int, err: str, pid: int) -> None:
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"pid {pid}" in lines[0], err


@pytest.fixture
def holder_process(tmp_path):
    """A process that holds a folder's lock until the test ends, as a run would."""
    procs = []

    def hold_it(folder: Path) -> subprocess.Popen:
        folder.mkdir(parents=True, exist_ok=True)
        p = subprocess.Popen(
            [sys.executable, "-c", "import sys, time; from sppl.runs.lock import FolderLock; "
             "FolderLock(sys.argv[1]).acquire(); print('held', flush=True); time.sleep(600)",
             str(folder)], stdout=subprocess.PIPE, text=True)
        assert p.stdout.readline().strip() == "held"
        procs.append(p)
        return p

    yield hold_it
    for p in procs:
        p.kill()
        p.wait()


def test_a_second_writer_is_refused_while_the_first_samples(setup, tmp_path, capsys):
    model, obs = setup
    out = tmp_path / "E"
    p = start_sample(model, obs, out)
    try:
        wait_until_sampling(p, out)
        sample = ["sample", str(model), "--obs", str(obs), "--out", str(out), "--steps", "5",
                  "--seed", "4", "-q"]
        refused(*second(sample, capsys), p.pid)
        refused(*second([*sample, "--force"], capsys), p.pid)  # and deletes nothing
        refused(*second(["sample", "--resume", str(out), "--steps", "2000000", "-q"], capsys),
                p.pid)
        refused(*second(["simulate", str(model), "--cameras", str(obs / "transforms.json"),
                         "--out", str(out), "--force"], capsys), p.pid)
        # Nor inside it: a chain's folder is the run's to write.
        refused(*second([*sample[:4], "--out", str(out / "chain_0"), "-q", "--steps", "5"],
                        capsys), p.pid)
        assert not (out / "chain_0").exists()
        before = len(read_samples(out / "samples.jsonl"))
        time.sleep(0.5)
        assert holder(out) == p.pid  # still the first run's, still sampling
    finally:
        p.terminate()
        stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    steps = [s["step"] for s in read_samples(out / "samples.jsonl")]
    assert len(steps) >= before and steps == list(range(1, len(steps) + 1))  # one writer
    assert json.loads((out / "run.json").read_text())["seed"] == 3
    assert not (out / LOCK_FILE).exists()  # released as it ended


def test_a_killed_writer_leaves_a_lock_the_next_run_takes_over(setup, tmp_path, capsys):
    model, obs = setup
    out = tmp_path / "K"
    p = start_sample(model, obs, out, "--checkpoint-every", "0")
    wait_until_sampling(p, out)
    p.kill()
    p.wait(timeout=60)
    assert (out / LOCK_FILE).read_text().strip() == str(p.pid)  # left behind, stale
    assert holder(out) is None
    done = json.loads((out / "checkpoint.json").read_text())["step"]
    code, err = second(["sample", "--resume", str(out), "--steps", str(done + 3), "-q"], capsys)
    assert code == 0, err
    assert [s["step"] for s in read_samples(out / "samples.jsonl")] == list(range(1, done + 4))
    assert not (out / LOCK_FILE).exists()


@pytest.mark.slow  # 15 to 45 s: a run of two chains started, and stopped
@pytest.mark.parametrize("more", [["--chains", "2"], ["--chains", "2", "--lockstep"]],
                         ids=["processes", "lockstep"])
def test_several_chains_hold_their_run_folder_for_the_run(setup, tmp_path, capsys, more):
    model, obs = setup
    out = tmp_path / "C"
    p = start_sample(model, obs, out, *more)
    try:
        wait_until_sampling(p, out, "chain_*/samples.jsonl")
        refused(*second(["sample", str(model), "--obs", str(obs), "--out", str(out), "--steps",
                         "5", "-q", "--force"], capsys), p.pid)
        assert (out / "chain_1").is_dir()
    finally:
        p.terminate()
        _, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    for chain in ("chain_0", "chain_1"):
        steps = [s["step"] for s in read_samples(out / chain / "samples.jsonl")]
        assert steps == list(range(1, len(steps) + 1))


def test_the_python_api_holds_the_run_folder_too(setup, tmp_path, holder_process):
    from sppl.data.observations import load_observations
    from sppl.lang import load_model
    from sppl.runs.chains import run_chains
    from sppl.runs.run import run_chain

    model_path, obs_path = setup
    model, obs = load_model(model_path), load_observations(obs_path)
    out = tmp_path / "api"
    p = holder_process(out)
    for run in (lambda: run_chain(model, obs, out, steps=3, seed=0, progress=False),
                lambda: run_chains(model, obs, out, chains=2, steps=3, seed=0, progress=False)):
        with pytest.raises(FolderInUse, match=f"pid {p.pid}"):
            run()
    assert sorted(x.name for x in out.iterdir()) == [LOCK_FILE]  # nothing written


def test_force_deletes_no_chain_folder_a_live_process_writes(tmp_path, holder_process, capsys,
                                                             monkeypatch):
    """A parent killed while its chains' processes still run: the chains hold their folders."""
    from test_cli import old_run

    monkeypatch.chdir(tmp_path)
    out = old_run(tmp_path / "run")
    p = holder_process(out / "chain_1")
    from sppl.cli import _prepare_out

    with pytest.raises(FolderInUse, match=f"pid {p.pid}"):
        _prepare_out(out, True)
    assert (out / "chain_1" / "samples.jsonl").exists()
    assert (out / "chain_0" / "samples.jsonl").exists()


def test_a_lock_is_held_once_per_process_and_released_on_any_exit(tmp_path):
    with hold(tmp_path):
        with hold(tmp_path):  # nested: the same holder
            assert (tmp_path / LOCK_FILE).read_text().strip().isdigit()
        assert (tmp_path / LOCK_FILE).exists()
    assert not (tmp_path / LOCK_FILE).exists()
    with pytest.raises(RuntimeError), hold(tmp_path):
        raise RuntimeError()
    assert not (tmp_path / LOCK_FILE).exists()
    lock = FolderLock(tmp_path).acquire()
    with pytest.raises(FolderInUse):  # another open file in this very process is another holder
        FolderLock(tmp_path).acquire()
    lock.release()
