"""Threads for loops that release the GIL (compiled ``nogil`` loops, numpy's own): how many a process may use
(`count`), one pool made once (`pool`), and work run on threads, item by item (`blocks`, `each`). Each item
writes its own rows or returns its own answer, so a result is the same bits on any number of threads."""
from __future__ import annotations

import contextlib
import os
from concurrent.futures import ThreadPoolExecutor

MAX_THREADS = 4  # threads at most: a query's blocks gain little past it and would hold their memory at once

_POOL = None
_CAP = None  # `limited`: this process's share of the cores while others share them too


def _cores() -> int:
    """The cores this process may run on, at most MAX_THREADS."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cores))


def count() -> int:
    """The threads work here may use: the cores this process may run on, at most MAX_THREADS, and at most
    the share `limited` sets."""
    return max(1, min(_cores(), _CAP)) if _CAP else _cores()


@contextlib.contextmanager
def limited(n: int | None):
    """Within it, `count` is at most n (None: no change): a partition worker's share of the cores, where
    worker processes run tasks side by side (threads beyond a share only take turns on the same cores)."""
    global _CAP
    old = _CAP
    _CAP = int(n) if n else old
    try:
        yield
    finally:
        _CAP = old


def pool() -> ThreadPoolExecutor:
    """The threads `blocks` runs on, made once (a new pool per call costs more than a small query); as many
    as the cores, whatever `limited` says when it is made (`blocks` hands it no more items than `count`)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=_cores(), thread_name_prefix="qemjax")
    return _POOL


def spans(n: int, least: int, most: int | None = None) -> list:
    """[(lo, hi), ...]: n items cut into consecutive blocks of at least ``least`` items each, as many as there
    are threads (`count`), and of at most ``most`` (None: no bound); one block when n is small."""
    k = max(min(count(), n // least), -(-n // most) if most else 1, 1)
    step = max(-(-n // k), 1)
    return [(lo, min(lo + step, n)) for lo in range(0, n, step)]


def blocks(fn, items) -> list:
    """[fn(item) for item in items] on `pool`: with no more items than threads, this thread runs the first
    itself rather than handing it off and waiting. (fn must not wait on `pool` itself.)"""
    items = list(items)
    if len(items) <= 1:
        return [fn(item) for item in items]
    n = count()
    if n == 1:
        return [fn(item) for item in items]
    if len(items) <= n:
        rest = [pool().submit(fn, item) for item in items[1:]]
        return [fn(items[0])] + [r.result() for r in rest]
    if n < _cores():  # a share (`limited`): n at a time
        return [r for k in range(0, len(items), n) for r in blocks(fn, items[k:k + n])]
    return list(pool().map(fn, items))


def each(fn, items) -> None:
    """fn(item) for each item, on up to `count` threads of their own (in this thread when one suffices): for
    items that use `blocks` themselves (a batch's re-fits, `_pipeline.stages.refit_all`). An error or Ctrl-C
    drops the items not started."""
    items = list(items)
    if len(items) <= 1 or count() == 1:
        for item in items:
            fn(item)
        return
    with ThreadPoolExecutor(max_workers=min(count(), len(items))) as workers:
        try:
            for _ in workers.map(fn, items):  # re-raises an item's exception here
                pass
        except BaseException:
            workers.shutdown(wait=True, cancel_futures=True)
            raise
