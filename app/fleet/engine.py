"""The engine under `headway fleet` and `headway eval --workers`: Dask (`dask.distributed`).

By default a local cluster of worker processes on this machine (one thread each, each process pinned to a
core: every process has its own Headway core, and the per-frame budget is per core), on 127.0.0.1 only.
With a scheduler address, an existing cluster (docs/fleet.md). A worker that dies has its tasks re-run by
the scheduler (up to `distributed.scheduler.allowed-failures`, 3); the drives are idempotent and their
outputs are renamed into place only when complete (app/fleet/drive.py).
"""
from __future__ import annotations

import contextlib
import os
import sys
import uuid
from typing import Callable, Iterable, Iterator, Optional

import cv2
import dask
from distributed import Client, LocalCluster, WorkerPlugin, as_completed
from tqdm import tqdm

from app.fleet.drive import one_line


class EngineError(RuntimeError):
    """The cluster could not be started or reached; the message says how to fix it."""


class PinToCore(WorkerPlugin):
    """Runs in each local worker process at start: pins it to one core (worker i -> the i-th allowed core)
    and keeps OpenCV on that one thread."""

    def setup(self, worker) -> None:
        cv2.setNumThreads(1)
        if hasattr(os, "sched_setaffinity"):
            cores = sorted(os.sched_getaffinity(0))
            os.sched_setaffinity(0, {cores[int(worker.name) % len(cores)]})


@contextlib.contextmanager
def cluster(scheduler: Optional[str] = None, workers: Optional[int] = None) -> Iterator:
    """A dask.distributed Client: on `scheduler` (tcp://HOST:PORT) or on a new local cluster of `workers`
    processes (default: one per allowed core)."""
    if scheduler:
        try:
            client = Client(scheduler, timeout="15s")
        except (OSError, TimeoutError) as exc:
            raise EngineError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({one_line(exc)}); "
                              "start one with `dask scheduler` (docs/fleet.md)") from None
        with client:
            if not client.scheduler_info().get("workers"):
                client.wait_for_workers(1, timeout=60)
            yield client
        return
    n = workers if workers is not None else len(os.sched_getaffinity(0))
    if n < 1:
        raise EngineError(f"--workers {n}: need at least one worker")
    env = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    # quiet: the fleet reports its drives itself; the workers' own chatter stays at warnings
    with dask.config.set({"distributed.worker.daemon": False, "logging.distributed": "error"}), \
            LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1", scheduler_port=0,
                         dashboard_address=None, worker_dashboard_address=None, env=env, silence_logs=40,
                         # no dashboard; the scheduler's own HTTP routes on a free local port, not 8787
                         scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as local, Client(local) as client:
        client.register_plugin(PinToCore())
        yield client


class Progress:
    """Drives done, running and failed: a bar on a terminal, one line per finished drive otherwise."""

    def __init__(self, total: int, done: int, desc: str, enabled: bool = True):
        self.tty = sys.stderr.isatty()
        self.enabled = enabled
        self.total, self.done, self.failed, self.running = total, done, 0, 0
        self.desc = desc
        self.bar = None
        if enabled and self.tty:
            self.bar = tqdm(total=total, initial=done, desc=desc, unit="drive", file=sys.stderr)
            self._postfix()

    def _postfix(self) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(f"running {self.running}, failed {self.failed}")

    def finished(self, name: str, ok: bool, running: int, note: str = "") -> None:
        self.done += 1
        self.failed += not ok
        self.running = running
        if self.bar is not None:
            self.bar.update(1)
            self._postfix()
        elif self.enabled:
            print(f"{self.desc}: [{self.done}/{self.total}] {name} {'done' if ok else 'FAILED'}{note} "
                  f"(running {running}, failed {self.failed})", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def running_count(client) -> int:
    """Tasks running now: those the scheduler has given each worker, up to its threads (it queues a few more)."""
    try:
        threads = client.nthreads()
        return sum(min(len(v), threads.get(w, 1)) for w, v in client.processing().items())
    except Exception:      # the scheduler is busy or gone: the count is only for display
        return 0


def run_tasks(client, fn: Callable, items: Iterable[tuple[str, tuple]], on_done: Callable[[str, object, Optional[str]], None]
              ) -> None:
    """Submit fn(*args) for each (name, args); call on_done(name, result, error_line) as each finishes (error
    None when it returned). A task whose worker died more often than allowed ends with its error line."""
    run_id = uuid.uuid4().hex[:12]   # two runs on one scheduler never share a task
    futures = {client.submit(fn, *args, key=f"headway-{name}-{run_id}", pure=False, retries=0): name
               for name, args in items}
    for fut in as_completed(futures):
        name = futures[fut]
        try:
            on_done(name, fut.result(), None)
        except Exception as exc:        # KilledWorker after repeated deaths, or an error raised by fn
            on_done(name, None, one_line(exc))


def map_ordered(fn: Callable, arg_list: list[tuple], names: list[str], desc: str,
                scheduler: Optional[str] = None, workers: Optional[int] = None) -> list:
    """fn(*args) for each args on the engine, the results in the given order (for `headway eval --workers`);
    raises the first error."""
    results: dict[str, object] = {}
    errors: dict[str, str] = {}
    with cluster(scheduler, workers) as client:
        prog = Progress(len(names), 0, desc)

        def done(name, result, error):
            (errors.__setitem__(name, error) if error else results.__setitem__(name, result))
            prog.finished(name, error is None, running_count(client))

        try:
            run_tasks(client, fn, zip(names, arg_list), done)
        finally:
            prog.close()
    if errors:
        name = next(n for n in names if n in errors)
        raise RuntimeError(f"{desc} {name}: {errors[name]}")
    return [results[n] for n in names]
