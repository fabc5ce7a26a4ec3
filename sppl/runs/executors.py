"""Where a data set's tasks run: local worker processes, or a Ray cluster.

An executor has one method, ``run(model_source, model_path, tasks)``, a generator that yields
``(task, result)`` as each task ends, in the order they end; ``result`` is what
``sppl.runs.tasks.run_task`` returned, or a ``TaskFailed``. Both executors run a task again when
the process running it is lost (killed, crashed, its machine gone), up to ``retries`` times; the
task then continues from its chain's last checkpoint, so nothing it drew is lost and its
samples are those of a run that was never interrupted. An error in the user's input (a
``SpplError``) is not retried: it would fail again.
"""

from __future__ import annotations

import os
import queue
import signal
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from ..errors import SpplError, UsageError
from .tasks import Task, run_task

RETRIES = 3


@dataclass(frozen=True)
class TaskFailed:
    message: str


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _one_line(e: BaseException) -> str:
    if isinstance(e, SpplError):
        return str(e).splitlines()[0]
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


# ----------------------------------------------------------------------------------------------
# Local worker processes


def _local_worker(model_source: str, model_path: str | None, tasks, results, stop) -> None:
    """A worker process: take tasks until told to stop. Ctrl-C is the parent's to handle: it
    sets ``stop`` and sends SIGTERM, which a running chain takes as a request to stop at the
    end of its sweep, checkpointed, and which ends an idle worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        item = tasks.get()
        if item is None or stop.is_set():
            return
        index, task = item
        results.put(("start", index, os.getpid()))
        try:
            results.put(("done", index, run_task(model_source, model_path, task)))
        except BaseException as e:  # noqa: BLE001 - reported by the parent as one line
            results.put(("failed", index, _one_line(e)))
            if not isinstance(e, Exception):
                return


class LocalExecutor:
    """Tasks in ``workers`` processes of this machine (spawned, each with its own GL context,
    kept for the next task). A worker that dies mid-task is replaced and its task run again."""

    def __init__(self, workers: int | None = None, retries: int = RETRIES) -> None:
        if workers is not None and workers < 1:
            raise UsageError("--workers must be at least 1")
        self.workers, self.retries = workers, retries

    def run(self, model_source: str, model_path: str | None,
            tasks: Iterable[Task]) -> Iterator[tuple[Task, Any]]:
        import multiprocessing as mp

        tasks = list(tasks)
        if not tasks:
            return
        ctx = mp.get_context("spawn")
        todo, results, stop = ctx.Queue(), ctx.Queue(), ctx.Event()
        for item in enumerate(tasks):
            todo.put(item)
        procs = []

        def start_worker():
            p = ctx.Process(target=_local_worker, name="sppl-task-worker", daemon=True,
                            args=(model_source, model_path, todo, results, stop))
            p.start()
            procs.append(p)

        running: dict[int, int] = {}  # pid -> the task it runs
        ended: set[int] = set()
        attempts = [0] * len(tasks)
        idle_ticks = 0
        try:
            for _ in range(min(self.workers or default_workers(), len(tasks))):
                start_worker()
            while len(ended) < len(tasks):
                try:
                    kind, index, value = results.get(timeout=0.5)
                except queue.Empty:
                    lost = []
                    for p in [p for p in procs if not p.is_alive()]:
                        procs.remove(p)
                        if p.pid in running:
                            lost.append((running.pop(p.pid), p.exitcode))
                    # A worker that died between taking a task and saying so leaves a task
                    # that no one runs: seen as no task running and none queued, twice.
                    idle_ticks = idle_ticks + 1 if not running and todo.empty() else 0
                    if idle_ticks >= 2:
                        lost += [(i, None) for i in range(len(tasks)) if i not in ended]
                        idle_ticks = 0
                    for index, status in lost:  # run it again, or give up on it
                        attempts[index] += 1
                        if attempts[index] > self.retries:
                            ended.add(index)
                            yield tasks[index], TaskFailed(
                                f"its worker process died {attempts[index]} times"
                                + ("" if status is None else f" (last exit status {status})"))
                        else:
                            todo.put((index, tasks[index]))
                    while len(procs) < min(self.workers or default_workers(),
                                           len(tasks) - len(ended)):
                        start_worker()
                    continue
                if kind == "start":
                    running[value] = index
                    continue
                running = {pid: i for pid, i in running.items() if i != index}
                if index in ended:
                    continue
                ended.add(index)
                yield tasks[index], (value if kind == "done" else TaskFailed(value))
            for _ in procs:
                todo.put(None)
        except (KeyboardInterrupt, GeneratorExit):
            stop.set()
            for p in procs:
                if p.is_alive():
                    p.terminate()  # SIGTERM: a running chain stops after its sweep, saved
            raise
        finally:
            for p in procs:
                p.join(timeout=120)
                if p.is_alive():
                    p.kill()


# ----------------------------------------------------------------------------------------------
# Ray


class RayExecutor:
    """Tasks on a Ray cluster, one Ray task per chain (``pip install 'sppl-scenes[ray]'``).

    ``address``: ``None`` or ``"ray"`` connects to the cluster that ``RAY_ADDRESS`` names, or
    to the one ``ray start`` runs on this machine, or, when there is none, starts a private one
    of ``workers`` CPUs on the loopback address for this run only; ``"ray://host:port"`` is a
    Ray client connection; ``"host:port"`` a cluster's GCS address. Each chain needs one CPU.
    Workers write the run folders themselves, so on a cluster of several machines the output
    folder and the observations must be on a file system every worker sees at the same path.
    """

    def __init__(self, address: str | None = None, workers: int | None = None,
                 retries: int = RETRIES) -> None:
        try:
            import ray  # noqa: F401
        except ImportError:
            raise UsageError("--cluster ray needs Ray: pip install 'sppl-scenes[ray]'") from None
        self.address = None if address in (None, "ray") else address
        self.workers, self.retries = workers, retries

    def _connect(self) -> bool:
        """Connect to (or start) the cluster; True if this run started it and must stop it."""
        import ray

        if ray.is_initialized():
            return False
        quiet = {"include_dashboard": False, "log_to_driver": False,
                 "configure_logging": False}
        address = self.address or os.environ.get("RAY_ADDRESS")
        if address:
            try:
                ray.init(address=address, log_to_driver=False)
            except Exception as e:  # noqa: BLE001 - Ray's connection errors have no common type
                raise UsageError(f"cannot connect to the Ray cluster at {address}: "
                                 f"{_one_line(e)}") from None
            return False
        try:
            ray.init(address="auto", log_to_driver=False)
            return False
        except ConnectionError:
            pass
        ray.init(num_cpus=self.workers or default_workers(), _node_ip_address="127.0.0.1",
                 object_store_memory=80 * 1024**2, **quiet)
        return True

    def run(self, model_source: str, model_path: str | None,
            tasks: Iterable[Task]) -> Iterator[tuple[Task, Any]]:
        import ray

        tasks = list(tasks)
        if not tasks:
            return
        started = self._connect()
        remote = ray.remote(num_cpus=1, max_retries=self.retries,
                            retry_exceptions=False)(run_task)
        pending = {remote.remote(model_source, model_path, t): t for t in tasks}
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    task = pending.pop(ref)
                    try:
                        yield task, ray.get(ref)
                    except ray.exceptions.RayTaskError as e:
                        cause = getattr(e, "cause", None) or e
                        yield task, TaskFailed(_one_line(cause))
                    except ray.exceptions.RayError as e:  # lost more often than it may retry
                        yield task, TaskFailed(_one_line(e))
        except (KeyboardInterrupt, GeneratorExit):
            for ref in pending:
                ray.cancel(ref)  # a KeyboardInterrupt in the task: its chain stops, saved
            try:
                ray.wait(list(pending), num_returns=len(pending), timeout=60)
            except Exception:  # noqa: BLE001, S110 - stopping anyway
                pass
            raise
        finally:
            if started:
                ray.shutdown()


def make_executor(cluster: str | None, workers: int | None) -> LocalExecutor | RayExecutor:
    """The executor ``--cluster`` names: ``local`` (the default) or Ray."""
    if cluster in (None, "local"):
        return LocalExecutor(workers)
    if cluster == "ray" or cluster.startswith("ray://") or ":" in cluster:
        return RayExecutor(cluster, workers)
    raise UsageError(f"unknown --cluster {cluster!r}; use local, ray, ray://HOST:PORT or "
                     "HOST:PORT (a Ray cluster's address)")
