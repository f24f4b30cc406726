"""Device results to the host, waited for by polling first.

A round's device call on a small mesh takes about a tenth of a millisecond. Blocking on its result puts
the calling thread to sleep, and waking it again when the result is in costs about as much as the call on
a virtual machine whose idle core halts; polling for the result instead shortens a small mesh's whole run
(docs/benchmarks.md, "Measured choices inside a run"). Only small results are polled for (at most `POLL_SIZE` values:
a small call's). A larger call may spread over every core, and a polling thread would take one from it (the
bunny's rounds, 4096 pairs a call, took longer polled), so it is waited for by blocking, as before; and
polling stops after `SPIN_S`. The values are the same either way: only how the thread waits changes.
"""
from __future__ import annotations

import time

import numpy as np

SPIN_S = 5e-4  # how long a wait polls before it blocks (s)
POLL_SIZE = 8192  # results with more values than this are waited for by blocking at once


def to_host(a) -> np.ndarray:
    """``np.asarray(a)`` for a device array ``a`` (any array: as it is); one of at most `POLL_SIZE` values
    is polled for up to `SPIN_S` until it is ready before the wait blocks."""
    ready = getattr(a, "is_ready", None)
    if ready is not None and a.size <= POLL_SIZE and not ready():
        until = time.perf_counter() + SPIN_S
        while not ready() and time.perf_counter() < until:
            pass
    return np.asarray(a)
