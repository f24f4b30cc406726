"""A sweep's helper processes: the other cores' share of a sweep's pieces (`run.sweep`, ``workers=``).

Each helper is a fresh Python (``sys.executable``, the caller's ``sys.path``) that imports qemjax, connects
back to this process (`multiprocessing.connection`, with a random key) and runs the pieces it is sent
(`run.run_cells`), one at a time, returning their rows and the warnings they raised. Nothing is forked (JAX's
threads do not survive a fork) and, unlike a ``spawn`` process pool, the caller's ``__main__`` is never
imported again: a script without ``if __name__ == "__main__":`` works as it is. Helpers start when a sweep
first needs them (`HELPERS`: the process's pool), in the background, while this process already runs
pieces itself, and stay for the process's later sweeps; each takes pieces only once it has imported
qemjax (its first piece also loads the compiled kernels from the caches on disk). A helper ignores Ctrl-C
(the sweep stops it) and exits when this process closes the connection or goes away, or after `IDLE_S`
idle.
"""
from __future__ import annotations

import atexit
import collections
import os
import pickle
import queue
import signal
import subprocess
import sys
import threading
import traceback
import warnings
from multiprocessing import connection

_BOOT = ("import sys, pickle; sys.path[:] = pickle.load(sys.stdin.buffer); "
         "from qemjax._sweep.pool import serve; serve()")
POLL_S = 0.05  # how often the dispatcher looks for helpers that became ready or died
IDLE_S = 600.0  # a helper sent nothing for this long exits (a later sweep starts a new one)


def cores() -> int:
    """The cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


class _Helper:
    """One helper process: ``conn`` once it has connected (ready), ``piece`` the piece it runs (or None)."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.conn = None
        self.piece = None

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        """Kill it (a piece in flight is dropped)."""
        if self.conn is not None:
            try:
                self.conn.close()
            except OSError:
                pass
        if self.alive():
            self.proc.kill()
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass


class Pool:
    """The helper processes of this process's sweeps (`HELPERS`), started on demand and reused; one sweep
    at a time uses them (``busy``)."""

    def __init__(self):
        self.helpers: list[_Helper] = []
        self.lock = threading.Lock()
        self.busy = threading.Lock()
        self._listener = None
        self._key = os.urandom(32)

    def _listen(self) -> None:
        if self._listener is not None:
            return
        self._listener = connection.Listener(authkey=self._key)
        threading.Thread(target=self._accept, args=(self._listener,), name="qemjax-sweep-accept",
                         daemon=True).start()

    def _accept(self, listener) -> None:
        """Take each helper's connection as it comes (once it has imported qemjax): ready for pieces."""
        while True:
            try:
                conn = listener.accept()
                pid = conn.recv()
            except (OSError, EOFError):
                if listener is not self._listener:  # closed: the pool was shut down
                    return
                continue  # a connection that failed (or a wrong key): not a helper
            except Exception:  # noqa: BLE001 - e.g. multiprocessing's AuthenticationError
                continue
            with self.lock:
                for h in self.helpers:
                    if h.proc.pid == pid and h.conn is None:
                        h.conn = conn
                        break
                else:
                    conn.close()

    def grow(self, n: int) -> None:
        """Have n helpers (alive, ready or starting): start the ones missing."""
        with self.lock:
            self.helpers = [h for h in self.helpers if h.alive()]
            missing = n - len(self.helpers)
        if missing <= 0:
            return
        self._listen()
        try:
            settings = pickle.dumps(_settings())
        except Exception:  # noqa: BLE001 - something registered here that cannot be pickled: no helpers
            return
        for _ in range(missing):
            try:
                proc = subprocess.Popen([_executable(), "-c", _BOOT], stdin=subprocess.PIPE, close_fds=True)
            except OSError:  # no Python to start (an embedded interpreter): this process runs the pieces
                return
            try:
                pickle.dump(list(sys.path), proc.stdin)
                pickle.dump((self._listener.address, self._key, settings), proc.stdin)  # settings: bytes
                proc.stdin.close()
            except OSError:  # it died at once: it will be seen dead
                pass
            with self.lock:
                self.helpers.append(_Helper(proc))

    def size(self) -> int:
        """Helpers alive (ready or starting)."""
        with self.lock:
            return sum(h.alive() for h in self.helpers)

    def ready(self) -> int:
        """Helpers alive and connected."""
        with self.lock:
            return sum(h.alive() and h.conn is not None for h in self.helpers)

    def shutdown(self) -> None:
        """Stop every helper (a piece in flight is dropped) and stop listening."""
        with self.lock:
            helpers, self.helpers = self.helpers, []
            listener, self._listener = self._listener, None
        for h in helpers:
            h.stop()
        if listener is not None:
            try:
                listener.close()
            except OSError:
                pass


HELPERS = Pool()
atexit.register(HELPERS.shutdown)


def _executable() -> str:
    from multiprocessing import spawn

    return spawn.get_executable()


def registered() -> dict:
    """The methods and schedulers this process registered (`qemjax.register_method`, `_schedulers.register`)
    beyond the built-in ones: {"methods": {name: class}, "schedulers": {name: run}}, empty dicts when none."""
    from .. import _costs, _schedulers

    return {"methods": {k: v for k, v in _costs.REGISTRY.items() if k not in _costs.BUILT_IN},
            "schedulers": {k: v for k, v in _schedulers._REGISTRY.items() if k not in _schedulers.BUILT_IN}}


def from_main(value) -> bool:
    """Whether ``value`` (a class, a function or an object of a class) comes from the caller's ``__main__``,
    which a helper cannot import (it does not run the caller's script)."""
    owner = value if isinstance(value, type) or callable(value) and hasattr(value, "__module__") else type(value)
    return getattr(owner, "__module__", None) == "__main__"


def shippable() -> bool:
    """Whether helpers can take what this process registered (`registered`: nothing from ``__main__``)."""
    reg = registered()
    return not any(from_main(v) for kind in reg.values() for v in kind.values())


def _settings() -> dict:
    """What a helper must do as this process does: JAX's float64 mode and qemjax's compilation cache (when
    this process has set them; otherwise the helper takes the same defaults from the same environment), and
    the methods and schedulers registered here (`registered`: sent by reference, so a helper can take them
    only from a module it can import, not from a script's ``__main__``)."""
    out = {"registered": registered()}
    jax = sys.modules.get("jax")
    if jax is not None:
        out["x64"] = bool(jax.config.jax_enable_x64)
    from .._kernels import cache as _cache

    if _cache._DECIDED and jax is not None:
        on = jax.config.jax_enable_compilation_cache and jax.config.jax_compilation_cache_dir
        out["cache"] = jax.config.jax_compilation_cache_dir if on else False
    return out


def serve() -> None:
    """A helper's life (started by `Pool.grow`): settings from stdin, imports, connect, then run what it is
    sent, (piece id, function, arguments), until the connection closes (or stays idle `IDLE_S`)."""
    address, key, raw = pickle.load(sys.stdin.buffer)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the sweep's process handles Ctrl-C and stops us
    try:
        settings = pickle.loads(raw)
    except Exception as exc:  # noqa: BLE001 - e.g. a method registered from a script's __main__
        sys.stderr.write(f"qemjax sweep helper: cannot take this process's settings ({exc}); its pieces run "
                         "in the sweep's process\n")
        return
    if "x64" in settings:
        import jax

        jax.config.update("jax_enable_x64", settings["x64"])
    if "cache" in settings:
        from .._kernels import cache as _cache

        if settings["cache"] is False:
            _cache.disable()
        else:
            _cache.enable(settings["cache"])
    from .. import _costs, _schedulers

    _costs.REGISTRY.update(settings["registered"]["methods"])
    for name, run in settings["registered"]["schedulers"].items():
        _schedulers._REGISTRY[name] = run
    from .._pipeline import stages  # noqa: F401 - the run's modules (JAX, numba's cached loops), before "ready"
    from .._schedulers import batched  # noqa: F401

    conn = connection.Client(address, authkey=key)
    conn.send(os.getpid())
    while True:
        try:
            if not conn.poll(IDLE_S):
                return
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            piece_id, fn, args = pickle.loads(data)  # fn by reference (`run.run_cells`): imported here
        except Exception:  # noqa: BLE001 - e.g. a method object of a class in the caller's __main__
            try:
                conn.send(("unreadable", None, traceback.format_exc(), []))
                continue
            except (OSError, EOFError):
                return
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                reply = ("rows", piece_id, fn(*args))
            except Exception:  # noqa: BLE001 - not a cell's error (those are rows): the piece is lost
                reply = ("failed", piece_id, traceback.format_exc())
        said = [(w.category.__module__, w.category.__qualname__, str(w.message)) for w in caught]
        try:
            conn.send(reply + (said,))
        except (OSError, EOFError):
            return


def warn_again(said: list) -> None:
    """Issue here the warnings a helper recorded (category by name; UserWarning when not found)."""
    for module, name, message in said:
        category = UserWarning
        mod = sys.modules.get(module)
        found = getattr(mod, name, None) if mod is not None and "." not in name else None
        if isinstance(found, type) and issubclass(found, Warning):
            category = found
        warnings.warn(message, category, stacklevel=4)


class Dispatch(threading.Thread):
    """One sweep's pieces on the helpers: takes pieces from ``todo`` (a deque shared with the sweep's own
    thread, which takes pieces from it too) for each helper that is ready and idle, and puts what comes
    back on ``results``: ("rows", piece, rows, warnings), ("here", piece) for a piece to run in this process
    (lost `retries` times: its helper died, or no helper is left), and ("done",) once ``todo`` is empty and
    nothing is in flight; ``payload(piece)``: what a helper is sent for it, (piece id, a module-level
    function, its arguments), the function's return value coming back as the rows; ``limit``: how many of
    the pool's helpers to use. ``stop()``: stop handing out pieces (the caller then stops the helpers)."""

    def __init__(self, pool: Pool, todo: collections.deque, lock: threading.Lock, payload, retries: int,
                 limit: int):
        super().__init__(name="qemjax-sweep-dispatch", daemon=True)
        self.pool, self.todo, self.todo_lock, self.payload, self.retries = pool, todo, lock, payload, retries
        self.limit = limit  # at most this many of the pool's helpers
        self.results: queue.Queue = queue.Queue()
        self.tries: dict = {}
        self._halt = threading.Event()
        self.error = None

    def stop(self) -> None:
        self._halt.set()

    def _take(self):
        with self.todo_lock:
            return self.todo.popleft() if self.todo else None

    def _lost(self, piece) -> None:
        """A piece whose helper died: back to the front of the queue, or after `retries`, to this process."""
        n = self.tries[id(piece)] = self.tries.get(id(piece), 0) + 1
        if n > self.retries:
            self.results.put(("here", piece))
        else:
            with self.todo_lock:
                self.todo.appendleft(piece)

    def run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # noqa: BLE001 - the sweep's thread raises it
            self.error = exc
        finally:
            self.results.put(("done",))

    def _loop(self) -> None:
        pool = self.pool
        while not self._halt.is_set():
            with pool.lock:
                helpers = list(pool.helpers)
            for h in helpers:  # dead ones give their piece back
                if not h.alive() and h.piece is not None:
                    piece, h.piece = h.piece, None
                    self._lost(piece)
            live = [h for h in helpers if h.alive()][: self.limit]
            for h in live:
                if h.conn is None or h.piece is not None:
                    continue
                piece = self._take()
                if piece is None:
                    break
                try:
                    data = pickle.dumps(self.payload(piece))
                except Exception:  # noqa: BLE001 - its cells hold something that does not pickle: run here
                    self.results.put(("here", piece))
                    continue
                try:
                    h.conn.send_bytes(data)
                    h.piece = piece
                except (OSError, EOFError, ValueError):
                    h.stop()
                    self._lost(piece)
            busy = [h for h in live if h.piece is not None]
            if not busy:
                with self.todo_lock:
                    empty = not self.todo
                if empty:
                    return
                if not live:  # no helper left: this process runs the rest
                    while (piece := self._take()) is not None:
                        self.results.put(("here", piece))
                    return
            for conn in connection.wait([h.conn for h in busy], timeout=POLL_S):
                h = next(h for h in busy if h.conn is conn)
                piece, h.piece = h.piece, None
                try:
                    msg = conn.recv()
                except (OSError, EOFError):
                    h.stop()
                    self._lost(piece)
                    continue
                if msg[0] == "rows":
                    self.results.put(("rows", piece, msg[2], msg[3]))
                elif msg[0] == "unreadable":  # what the helper cannot import (a script's class): run here
                    self.results.put(("here", piece))
                else:  # the piece failed as a whole in the helper: lost, as if it had died
                    self._lost(piece)
