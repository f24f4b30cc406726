"""The machine a benchmark ran on, for its output (ratios against peers move with the CPU), and how it times."""
from __future__ import annotations

import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, else what the platform module knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def median_time(fn, repeats: int, warm: bool = True) -> float:
    """The median wall time of ``repeats`` calls of ``fn`` (after one untimed call when ``warm``)."""
    import statistics
    import time

    if warm:
        fn()
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)
