"""Tasks per minute of a data-set run: local workers and Ray, and what more machines would give.

    python benchmarks/datasets.py                 # 8 scenes x 1 chain x 300 sweeps, 48x48 px
    python benchmarks/datasets.py --scenes 16 --steps 1000

Runs one data set (scenes drawn from models/shapes.scn's prior, simulated here) three ways:
local with 1 worker, local with 2 workers, and Ray with 2 workers (a private cluster of this
machine, started and stopped here; inside a network namespace of its own where one can be made,
so that it listens on the loopback address only). For each it prints the wall time, tasks per
minute, and where a task's time goes: the chain itself (its summary's seconds) and the rest
(process or Ray start-up, model compilation, GL context, loading, writing), measured as
workers x wall time minus the chains' time, per task. From those measured costs it states what
N machines of this machine's cores would give, on paper: every task costs its chain time plus
the per-task overhead, the driver pools each scene when its last chain ends, and a cluster
adds its start-up once.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sppl.cli import main as sppl  # noqa: E402
from sppl.lang import load_model  # noqa: E402
from sppl.output.posterior import write_posterior  # noqa: E402
from sppl.runs.dataset import find_scenes, run_dataset  # noqa: E402
from sppl.runs.executors import LocalExecutor, RayExecutor, default_workers  # noqa: E402

MODEL = ROOT / "models" / "shapes.scn"


def make_dataset(folder: Path, scenes: int, size: int) -> Path:
    cameras = json.loads((ROOT / "examples" / "three_shapes" / "cameras.json").read_text())
    scale = size / cameras["w"]
    cameras.update(w=size, h=size, fl_x=cameras["fl_x"] * scale, fl_y=cameras["fl_y"] * scale,
                   cx=size / 2, cy=size / 2)
    (folder / "cameras.json").write_text(json.dumps(cameras))
    data = folder / "data"
    for i in range(scenes):
        assert sppl(["simulate", str(MODEL), "--cameras", str(folder / "cameras.json"),
                     "--out", str(data / f"scene_{i:03d}"), "--seed", str(100 + i)]) == 0
    return data


def measure(name: str, executor, data: Path, out: Path, steps: int) -> dict:
    model = load_model(MODEL)
    startup = 0.0
    if isinstance(executor, RayExecutor):  # the cluster's start, once per run, timed apart
        import ray

        t0 = time.perf_counter()
        ray.init(num_cpus=executor.workers, include_dashboard=False, log_to_driver=False,
                 object_store_memory=80 * 1024**2, _node_ip_address="127.0.0.1")
        startup = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = run_dataset(model, data, out, chains=1, steps=steps, seed=0, executor=executor,
                         progress=False)
    wall = time.perf_counter() - t0
    tasks = len(result.scenes)
    chain_seconds = [json.loads((out / s.name / "summary.json").read_text())["seconds"]
                     for s in result.scenes]
    workers = executor.workers
    if startup:
        import ray

        ray.shutdown()
    t0 = time.perf_counter()  # what the driver does alone for each scene: its posterior file
    write_posterior(out / result.scenes[0].name)
    driver = time.perf_counter() - t0
    return {"name": name, "workers": workers, "tasks": tasks, "wall": wall, "startup": startup,
            "driver": driver,
            "tasks_per_minute": 60 * tasks / wall,
            "chain": sorted(chain_seconds)[tasks // 2],  # the median task's chain time
            "overhead": max(0.0, (workers * wall - sum(chain_seconds)) / tasks)}


def ray_run(data: Path, out: Path, steps: int, workers: int) -> dict:
    """Ray with ``workers`` CPUs; in a network namespace of its own where this process can
    make one (then its cluster listens on the loopback address only)."""
    namespace = (shutil.which("unshare") and shutil.which("ip") and subprocess.run(
        ["unshare", "--net", "ip", "link", "set", "lo", "up"], capture_output=True).returncode == 0)
    if namespace and not os.environ.get("SPPL_BENCH_IN_NAMESPACE"):
        result = Path(tempfile.mkdtemp()) / "ray.json"
        cmd = (f"ip link set lo up && SPPL_BENCH_IN_NAMESPACE=1 {sys.executable} {__file__} "
               f"--ray-only {data} {out} {steps} {workers} {result}")
        subprocess.run(["unshare", "--net", "bash", "-c", cmd], check=True,
                       env={**os.environ, "RAY_AUTH_MODE": "disabled",
                            "RAY_USAGE_STATS_ENABLED": "0"})
        return json.loads(result.read_text())
    return measure(f"ray, {workers} workers", RayExecutor(None, workers), data, out, steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--size", type=int, default=48, help="image width and height, pixels")
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--ray-only", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.ray_only:
        data, out, steps, workers, result = args.ray_only
        row = measure(f"ray, {workers} workers", RayExecutor(None, int(workers)), Path(data),
                      Path(out), int(steps))
        Path(result).write_text(json.dumps(row))
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = make_dataset(tmp, args.scenes, args.size)
        n = len(find_scenes(data))
        print(f"{n} scenes x 1 chain x {args.steps} sweeps, {args.size}x{args.size} px, "
              f"{default_workers()} cores")
        rows = [measure("local, 1 worker", LocalExecutor(1), data, tmp / "l1", args.steps),
                measure("local, 2 workers", LocalExecutor(2), data, tmp / "l2", args.steps)]
        try:
            import ray  # noqa: F401

            if not args.no_ray:
                rows.append(ray_run(data, tmp / "r2", args.steps, 2))
        except ImportError:
            print("(Ray is not installed: pip install 'sppl-scenes[ray]')")
    print("\n| run | cluster start (s) | wall (s) | tasks/min | median chain (s) | "
          "overhead per task (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['name']} | {r['startup']:.1f} | {r['wall']:.1f} | "
              f"{r['tasks_per_minute']:.1f} | {r['chain']:.2f} | {r['overhead']:.2f} |")
    base = rows[0]["tasks_per_minute"]
    print("\nspeed-up over 1 local worker: "
          + ", ".join(f"{r['name']} {r['tasks_per_minute'] / base:.2f}x" for r in rows[1:]))
    # On paper: N machines of this one's cores, each task costing its chain time plus the
    # per-task overhead measured on Ray here.
    cores = default_workers()
    ray_row = rows[-1]
    per_task = ray_row["chain"] + ray_row["overhead"]
    ceiling = 60 / ray_row["driver"]
    print(f"\non paper, Ray on N machines of {cores} cores: a task costs {ray_row['chain']:.2f} s "
          f"of chain and {ray_row['overhead']:.2f} s besides; the driver writes each scene's "
          f"posterior file alone ({ray_row['driver']:.2f} s), which caps a run at "
          f"{ceiling:.0f} one-chain scenes a minute whatever the cluster; the cluster's start "
          f"({ray_row['startup']:.1f} s here) is paid once")
    for machines in (1, 2, 4, 8, 16, 32):
        rate = min(60 * machines * cores / per_task, ceiling)
        print(f"  N = {machines:2d}: {rate:8.1f} tasks/min")


if __name__ == "__main__":
    main()
