"""A data set of scenes: every scene x chain a task, on local workers or on Ray.

Every comparison is exact: a scene's chains in a data-set run draw the samples that the same
chains draw when that scene is sampled alone, whatever ran them, and a task whose worker was
killed mid-chain is run again from its checkpoint and still draws them.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from test_cli import CAMERAS

from sppl.cli import main
from sppl.data.observations import load_observations
from sppl.lang import load_model
from sppl.output.samples import read_samples
from sppl.runs.dataset import find_scenes, is_dataset, run_dataset
from sppl.runs.executors import LocalExecutor
from sppl.runs.run import chain_extra, chain_seeds, run_chain
from sppl.runs.tasks import TASK_RECORD

SEED = 3
STEPS = 10
SCENES = 4
CHAINS = 2
LONG = 400  # sweeps of a task killed mid-chain: long enough to be killed well before its end


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, root, require_gl):
    """Four scenes drawn from shapes.scn's prior, seen by 24x24 cameras."""
    d = tmp_path_factory.mktemp("dataset")
    cameras = {**CAMERAS, "w": 24, "h": 24, "fl_x": 27.0, "fl_y": 27.0, "cx": 12.0, "cy": 12.0}
    (d / "cameras.json").write_text(json.dumps(cameras))
    model_path = root / "models" / "shapes.scn"
    for i in range(SCENES):
        assert main(["simulate", str(model_path), "--cameras", str(d / "cameras.json"),
                     "--out", str(d / "data" / f"scene_{i}"), "--seed", str(10 + i)]) == 0
    return load_model(model_path), d


def alone(model, obs_folder, out, *, chains, steps, seed=SEED, chain=0):
    """Chain ``chain`` of ``sppl sample --chains CHAINS`` on one scene, run in this process."""
    obs = load_observations(obs_folder)
    if chains == 1:
        run_chain(model, obs, out, steps=steps, seed=seed, progress=False)
    else:
        run_chain(model, obs, out, steps=steps, seed=chain_seeds(seed, chains)[chain],
                  progress=False, extra=chain_extra(chain, chains, seed))
    return read_samples(out / "samples.jsonl")


@pytest.fixture(scope="module")
def local_run(dataset, tmp_path_factory):
    model, d = dataset
    out = tmp_path_factory.mktemp("local") / "out"
    result = run_dataset(model, d / "data", out, chains=CHAINS, steps=STEPS, seed=SEED,
                         executor=LocalExecutor(2), checkpoint_seconds=0, progress=False)
    return out, result


def test_a_folder_of_observation_folders_or_a_list_file_is_a_data_set(dataset, tmp_path):
    _, d = dataset
    assert is_dataset(d / "data") and not is_dataset(d / "data" / "scene_0")
    listing = tmp_path / "scenes.txt"
    listing.write_text(f"# two of them\n{d / 'data' / 'scene_2'}\n\n{d / 'data' / 'scene_0'}\n")
    assert is_dataset(listing)
    assert [s.name for s in find_scenes(listing)] == ["scene_2", "scene_0"]
    assert [s.name for s in find_scenes(d / "data")] == [f"scene_{i}" for i in range(SCENES)]


def test_each_scene_gets_the_run_folder_that_sampling_it_alone_gives(dataset, local_run,
                                                                     tmp_path):
    model, d = dataset
    out, result = local_run
    assert result.summary["finished"] == SCENES and result.summary["failed"] == 0
    for i in range(SCENES):
        folder = out / f"scene_{i}"
        for name in ("run.json", "summary.json", "summary.txt", "posterior.nc"):
            assert (folder / name).is_file(), name
        for c in range(CHAINS):
            assert len(read_samples(folder / f"chain_{c}" / "samples.jsonl")) == STEPS
    for i, c in ((0, 0), (3, 1)):  # two of the eight chains, each against its run alone
        reference = alone(model, d / "data" / f"scene_{i}", tmp_path / f"alone_{i}_{c}",
                          chains=CHAINS, steps=STEPS, chain=c)
        assert read_samples(out / f"scene_{i}" / f"chain_{c}" / "samples.jsonl") == reference
    # Every scene has its truth beside it, so the data-set summary judges every MAP.
    summary = json.loads((out / "summary.json").read_text())
    assert summary["with_truth"] == SCENES
    assert {r["scene"] for r in summary["per_scene"]} == {f"scene_{i}" for i in range(SCENES)}
    assert all(isinstance(r["recovered"], bool) for r in summary["per_scene"])


def test_rerunning_skips_finished_tasks_and_continues_to_more_steps(dataset, local_run,
                                                                    tmp_path):
    model, d = dataset
    out = tmp_path / "out"
    shutil.copytree(local_run[0], out)
    record = out / "scene_1" / "chain_0" / TASK_RECORD
    before = json.loads(record.read_text())["attempts"]
    samples = out / "scene_1" / "chain_0" / "samples.jsonl"
    stamp = samples.stat().st_mtime_ns
    run_dataset(model, d / "data", out, chains=CHAINS, steps=STEPS, seed=SEED,
                executor=LocalExecutor(2), checkpoint_seconds=0, progress=False)
    assert json.loads(record.read_text())["attempts"] == before  # not run again
    assert samples.stat().st_mtime_ns == stamp
    run_dataset(model, d / "data", out, chains=CHAINS, steps=2 * STEPS, seed=SEED,
                executor=LocalExecutor(2), checkpoint_seconds=0, progress=False)
    assert json.loads(record.read_text())["resumed"]
    reference = alone(model, d / "data" / "scene_1", tmp_path / "alone", chains=CHAINS,
                      steps=2 * STEPS, chain=0)
    assert read_samples(samples) == reference


def kill_when_running(out: Path, task_folder: str, min_samples: int = 3, timeout: float = 240):
    """Wait until the chain in ``out/task_folder`` has drawn a few samples, then SIGKILL the
    process running it; return its pid."""
    folder = out / task_folder
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            pid = json.loads((folder / TASK_RECORD).read_text())["pid"]
            if len((folder / "samples.jsonl").read_text().splitlines()) >= min_samples:
                os.kill(pid, signal.SIGKILL)
                return pid
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.02)
    raise AssertionError(f"{folder}: the chain never started")


def test_a_local_worker_killed_mid_task_is_replaced_and_nothing_is_lost(dataset, tmp_path):
    model, d = dataset
    listing = tmp_path / "one.txt"
    listing.write_text(str(d / "data" / "scene_2") + "\n")
    out = tmp_path / "out"
    done = {}
    thread = threading.Thread(target=lambda: done.setdefault("result", run_dataset(
        model, listing, out, chains=1, steps=LONG, seed=SEED, executor=LocalExecutor(1),
        checkpoint_seconds=0, progress=False)))
    thread.start()
    killed = kill_when_running(out, "scene_2")
    thread.join(timeout=600)
    assert not thread.is_alive()
    record = json.loads((out / "scene_2" / TASK_RECORD).read_text())
    assert record["attempts"] == 2 and record["resumed"] and record["pid"] != killed
    assert done["result"].summary["finished"] == 1
    reference = alone(model, d / "data" / "scene_2", tmp_path / "alone", chains=1, steps=LONG)
    assert read_samples(out / "scene_2" / "samples.jsonl") == reference


# ----------------------------------------------------------------------------------------------
# The command line


def sample(*args):
    return main(["sample", *map(str, args)])


def test_the_command_runs_a_data_set_and_a_rerun_is_a_no_op(dataset, tmp_path, capsys, root):
    _, d = dataset
    listing = tmp_path / "two.txt"
    listing.write_text("\n".join(str(d / "data" / f"scene_{i}") for i in (0, 3)) + "\n")
    model = root / "models" / "shapes.scn"
    out = tmp_path / "out"
    assert sample(model, "--obs", listing, "--out", out, "--steps", 6, "--workers", 2,
                  "--quiet", "--checkpoint-every", 0) == 0
    first = capsys.readouterr().out
    assert "2 of 2 scenes finished" in first and "scene_0: MAP" in first
    assert sample(model, "--obs", listing, "--out", out, "--steps", 6, "--quiet") == 0
    assert "2 of 2 scenes finished" in capsys.readouterr().out
    # Another --seed would mix two runs in one folder.
    assert sample(model, "--obs", listing, "--out", out, "--steps", 6, "--seed", 9) == 1
    assert "--seed" in capsys.readouterr().err
    assert main(["sample", "--resume", str(out)]) == 1
    assert "run the command that started it again" in capsys.readouterr().err


def test_data_set_usage_errors_are_one_line(dataset, tmp_path, capsys, root):
    _, d = dataset
    model = root / "models" / "shapes.scn"
    listing = tmp_path / "bad.txt"
    listing.write_text(f"{d / 'data' / 'scene_0'}\n  nowhere\n")
    cases = [
        ((model, "--obs", listing, "--out", tmp_path / "a"), "bad.txt:2:3: 'nowhere' is not"),
        ((model, "--obs", d / "data" / "scene_0", "--workers", 2, "--out", tmp_path / "b"),
         "--workers and --cluster run the tasks of a data set"),
        ((model, "--obs", d / "data", "--cluster", "elsewhere", "--out", tmp_path / "c"),
         "unknown --cluster 'elsewhere'"),
        ((model, "--obs", d / "data", "--workers", 0, "--out", tmp_path / "d"),
         "--workers must be at least 1"),
        ((model, "--obs", d / "data", "--chains", 2, "--lockstep", "--out", tmp_path / "e"),
         "leave out --lockstep"),
    ]
    for args, expected in cases:
        assert sample(*args) == 1, args
        err = capsys.readouterr().err
        assert expected in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------------------------------------
# Ray: a cluster of this machine, in a network namespace of its own, so that nothing it opens
# listens anywhere but on the loopback address; stopped by the script that started it.


def _ray_in_a_namespace_or_skip():
    pytest.importorskip("ray")
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.skip("needs unshare and ip (util-linux, iproute2) for a loopback-only cluster")
    probe = subprocess.run(["unshare", "--net", "ip", "link", "set", "lo", "up"],
                           capture_output=True)
    if probe.returncode != 0:
        pytest.skip("cannot make a network namespace here (needs root or user namespaces)")


RAY_SCRIPT = """\
set -u
ip link set lo up
export RAY_AUTH_MODE=disabled RAY_USAGE_STATS_ENABLED=0
trap 'ray stop --force >/dev/null 2>&1' EXIT
timeout 120 ray start --head --node-ip-address 127.0.0.1 --port {port} --num-cpus 2 \\
    --include-dashboard false --disable-usage-stats --temp-dir {temp} >{temp}/start.log 2>&1 \\
    || {{ cat {temp}/start.log; exit 3; }}
{python} -m sppl sample {model} --obs {obs} --out {out} --steps {steps} --seed {seed} \\
    --chains {chains} --cluster 127.0.0.1:{port} --quiet --checkpoint-every 0
"""


def run_on_ray(model: Path, obs: Path, out: Path, *, steps: int, chains: int, kill: str | None):
    """``sppl sample`` on a Ray cluster of 2 CPUs that the script starts and stops; with
    ``kill``, the worker running that task folder is SIGKILLed mid-chain."""
    temp = Path(tempfile.mkdtemp(prefix="sr", dir="/tmp"))  # Ray's socket paths must be short
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    script = RAY_SCRIPT.format(port=port, temp=temp, python=sys.executable, model=model,
                               obs=obs, out=out, steps=steps, seed=SEED, chains=chains)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    proc = subprocess.Popen(["unshare", "--net", "bash", "-c", script], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        if kill is not None:
            kill_when_running(out, kill)
        output, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:  # past its time: the namespace's cluster goes with its script
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=60)
        shutil.rmtree(temp, ignore_errors=True)
    assert proc.returncode == 0, output
    return output


def test_ray_runs_the_same_tasks_and_retries_a_killed_worker(dataset, local_run, tmp_path,
                                                             root):
    _ray_in_a_namespace_or_skip()
    model, d = dataset
    out = tmp_path / "ray"
    output = run_on_ray(root / "models" / "shapes.scn", d / "data", out, steps=STEPS,
                        chains=CHAINS, kill=None)
    assert f"{SCENES} of {SCENES} scenes finished" in output
    for i in range(SCENES):
        for c in range(CHAINS):
            path = Path(f"scene_{i}") / f"chain_{c}" / "samples.jsonl"
            assert read_samples(out / path) == read_samples(local_run[0] / path)

    listing = tmp_path / "one.txt"
    listing.write_text(str(d / "data" / "scene_2") + "\n")
    out = tmp_path / "ray_killed"
    run_on_ray(root / "models" / "shapes.scn", listing, out, steps=LONG, chains=1,
               kill="scene_2")
    record = json.loads((out / "scene_2" / TASK_RECORD).read_text())
    assert record["attempts"] == 2 and record["resumed"]
    reference = alone(model, d / "data" / "scene_2", tmp_path / "alone", chains=1, steps=LONG)
    assert read_samples(out / "scene_2" / "samples.jsonl") == reference
