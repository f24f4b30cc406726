"""Counts compilations and the time they take: JAX's (through jax.monitoring) and numba's (its compile
events), so that a run's ``compile_s`` holds every compilation and ``run_s`` is the run (both installed once,
when this module is first imported)."""
from __future__ import annotations

import threading
import time

import jax

_lock = threading.Lock()
_state = {"compiles": 0, "seconds": 0.0, "numba_compiles": 0, "numba_seconds": 0.0}
_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
           "/jax/core/compile/backend_compile_duration")


def _listener(name, duration, **_):
    if name in _EVENTS:
        with _lock:
            _state["seconds"] += duration
            if name == _EVENTS[-1]:
                _state["compiles"] += 1


jax.monitoring.register_event_duration_secs_listener(_listener)


def _numba_listener():
    """A numba event listener that times the outermost compilation on each thread: compiling a function
    compiles the functions it calls inside the same event, which must not count twice. Cache loads fire no
    event: a loop loaded from numba's cache costs nothing here."""
    from numba.core import event

    local = threading.local()

    class Outermost(event.Listener):
        def on_start(self, ev):
            depth = getattr(local, "depth", 0)
            if depth == 0:
                local.t0 = time.perf_counter()
            local.depth = depth + 1

        def on_end(self, ev):
            local.depth -= 1
            if local.depth == 0:
                with _lock:
                    _state["numba_seconds"] += time.perf_counter() - local.t0
                    _state["numba_compiles"] += 1

    event.register("numba:compile", Outermost())


_numba_listener()


def snapshot() -> tuple[int, float]:
    """(JAX compilations so far, seconds spent compiling so far: JAX's tracing + lowering + compiling and
    numba's compiling) in this process."""
    with _lock:
        return _state["compiles"], _state["seconds"] + _state["numba_seconds"]


def numba_compiles() -> int:
    """numba functions compiled (not loaded from its cache) in this process so far, outermost ones only."""
    with _lock:
        return _state["numba_compiles"]
