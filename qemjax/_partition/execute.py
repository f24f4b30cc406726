"""Where a partitioned run's tasks run: on a ``dask.distributed`` client's workers, on local worker
processes, or in this process. `Runner.map` yields each task's result as it finishes (in any order: each
task writes its own file, so the output does not depend on the order), runs again a task whose worker
died, and on Ctrl-C stops the workers at once."""
from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
from typing import Iterator

from .._mesh import threads as _threads
from .._options import Partition
from . import task as _task
from . import worker as _worker


class TaskError(RuntimeError):
    """A task raised: its message and the worker's traceback."""


class Runner:
    """Runs the tasks in this process (``Partition(workers=1)``)."""

    name = "this process"
    workers = 1

    def map(self, name: str, specs: list) -> Iterator[tuple[int, dict]]:
        for i, spec in enumerate(specs):
            yield i, getattr(_task, name)(spec)

    def close(self, cancel: bool = False) -> None:
        pass


def _worker_env() -> dict:
    """A worker's environment: one compute thread for numba, XLA and BLAS (the workers, not threads inside
    one, share the cores; JAX and numba give the same bits with any thread count). qemjax's own threads
    (`_mesh.threads`) take the share each task is sent (`share`)."""
    env = dict(os.environ)
    env.setdefault("NUMBA_NUM_THREADS", "1")
    flags = env.get("XLA_FLAGS", "")
    if "intra_op_parallelism_threads" not in flags:
        env["XLA_FLAGS"] = (flags + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1").strip()
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, "1")
    return env


def share(workers: int, tasks: int) -> int:
    """The threads each of a level's ``tasks`` may use on ``workers`` local worker processes: the cores
    (`_mesh.threads.count`) over the tasks that run at once, at least one. A level of many tasks runs one
    thread per worker (more would only take turns on the same cores); the last level's one group gets every
    core for its re-fit's searches."""
    return max(1, _threads.count() // max(1, min(workers, tasks)))


class LocalRunner(Runner):
    """``workers`` local processes (`worker`), started once per run so each compiles its kernels once, each
    fed by a thread of this process. A worker that dies (killed, out of memory) is started again and its
    task run again, up to ``retries`` times per task."""

    CLOSE_WAIT_S = 10  # how long `close` waits for a worker to exit before killing it

    def __init__(self, workers: int, retries: int):
        self.workers, self.retries = workers, retries
        self.name = f"{workers} local worker processes"
        self.lock = threading.Lock()
        self.closed = False
        # started now: their imports overlap the client's reading of the input
        self.procs: list = [None] * workers
        for k in range(workers):
            self._start(k)

    def _start(self, k: int):
        cmd = [sys.executable, "-m", "qemjax._partition.worker"]
        p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=_worker_env())
        self.procs[k] = p
        return p

    def _serve(self, k: int, todo: queue.Queue, done: queue.Queue, name: str):
        while not self.closed:
            try:
                i, spec, tries = todo.get_nowait()
            except queue.Empty:
                return
            with self.lock:  # close() holds it too: no worker starts after the run was stopped
                if self.closed:
                    return
                p = self.procs[k]
                if p is None or p.poll() is not None:
                    p = self._start(k)
            try:
                _worker.send(p.stdin, (name, spec))
                ok, value = _worker.receive(p.stdout)
            except (EOFError, BrokenPipeError, OSError):
                if self.closed:
                    return
                p.kill()
                p.wait()  # reaped: a killed process can still poll as running for a moment
                with self.lock:
                    if self.procs[k] is p:
                        self.procs[k] = None
                if tries >= self.retries:
                    done.put((i, False, f"a worker died {tries + 1} times running this task (out of memory? "
                                        "a smaller Partition(part_faces=...) or fewer workers)"))
                    return
                todo.put((i, spec, tries + 1))
                continue
            done.put((i, ok, value))

    def map(self, name, specs):
        todo, done = queue.Queue(), queue.Queue()
        cap = share(self.workers, len(specs))
        for i, spec in enumerate(specs):
            todo.put((i, spec | {"threads": cap}, 0))
        threads = [threading.Thread(target=self._serve, args=(k, todo, done, name), daemon=True)
                   for k in range(min(self.workers, len(specs)))]
        for t in threads:
            t.start()
        for _ in range(len(specs)):
            while True:  # short waits: Ctrl-C reaches this thread within a fraction of a second
                try:
                    i, ok, value = done.get(timeout=0.2)
                    break
                except queue.Empty:
                    if not any(t.is_alive() for t in threads) and done.empty():
                        raise TaskError("partition: the workers stopped with tasks left")
            if not ok:
                raise TaskError(f"partition: a task failed: {value}")
            yield i, value
        for t in threads:
            t.join()

    def close(self, cancel: bool = False):
        with self.lock:
            self.closed = True
        live = [p for p in self.procs if p is not None]
        for p in live:  # every worker told first, so that they exit side by side
            if cancel:
                p.kill()
            else:
                try:
                    p.stdin.close()
                except Exception:
                    p.kill()
        for p in live:
            try:
                p.wait(timeout=self.CLOSE_WAIT_S)
            except Exception:
                p.kill()
                p.wait()  # reaped: else it polls as running, and stays a zombie until collected
            if p.stdout is not None:  # its pipe (unclosed, it warned ResourceWarning at exit)
                p.stdout.close()


class DaskRunner(Runner):
    """Tasks submitted to a ``dask.distributed`` client (``retries``: the scheduler runs again a task whose
    worker died); results taken as they complete."""

    def __init__(self, client, retries: int):
        self.client, self.retries = client, retries
        self.workers = max(len(client.scheduler_info().get("workers", {})), 1)
        self.name = f"dask ({self.workers} workers)"
        self.futures = []

    def map(self, name, specs):
        from dask.distributed import as_completed

        fn = getattr(_task, name)
        futures = [self.client.submit(fn, spec, pure=False, retries=self.retries) for spec in specs]
        self.futures = futures
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in as_completed(futures):
            yield index[fut.key], fut.result()
        self.futures = []

    def close(self, cancel: bool = False):
        if cancel and self.futures:
            self.client.cancel(self.futures, force=True)
        self.futures = []


def open_runner(p: Partition) -> Runner:
    if p.client is not None:
        return DaskRunner(p.client, p.retries)
    if p.n_workers <= 1:
        return Runner()
    return LocalRunner(p.n_workers, p.retries)
