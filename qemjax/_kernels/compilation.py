"""Counts JAX compilations and the time they take, through jax.monitoring (installed once)."""
from __future__ import annotations

import threading

import jax

_lock = threading.Lock()
_state = {"compiles": 0, "seconds": 0.0}
_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
           "/jax/core/compile/backend_compile_duration")


def _listener(name, duration, **_):
    if name in _EVENTS:
        with _lock:
            _state["seconds"] += duration
            if name == _EVENTS[-1]:
                _state["compiles"] += 1


jax.monitoring.register_event_duration_secs_listener(_listener)


def snapshot() -> tuple[int, float]:
    """(compilations so far, seconds spent tracing + lowering + compiling so far) in this process."""
    with _lock:
        return _state["compiles"], _state["seconds"]
