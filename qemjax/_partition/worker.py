"""A local worker process (``python -m qemjax._partition.worker``): reads tasks from stdin and writes their
results to stdout, each a length-prefixed pickle. Started as a fresh interpreter, not through
multiprocessing, so that a user's script needs no ``if __name__ == "__main__"`` guard and a worker's death
is an end of file the pool sees at once."""
from __future__ import annotations

import os
import pickle
import signal
import struct
import sys
import traceback

HEADER = struct.Struct("<Q")


def send(stream, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(HEADER.pack(len(data)) + data)
    stream.flush()


def receive(stream):
    """The next object on ``stream``, or raises EOFError when the other side is gone."""
    head = stream.read(HEADER.size)
    if len(head) < HEADER.size:
        raise EOFError
    n = HEADER.unpack(head)[0]
    data = stream.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


def main() -> None:
    # Ctrl-C in a terminal reaches the whole process group: the client decides what stops (it kills workers)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # the protocol owns the real stdout; anything a library prints goes to stderr
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    inp = sys.stdin.buffer
    from .._mesh import threads
    from . import task
    # what every task needs, imported while the client is still reading the input
    from .._pipeline import api, stages  # noqa: F401

    while True:
        try:
            name, spec = receive(inp)
        except EOFError:  # the client is done with us and waits for our exit: every result is written and
            # flushed, so the process ends as multiprocessing ends its children, without Python's shutdown
            # (whose last garbage collection and module teardown, after JAX and numba, the client would wait
            # for: docs/benchmarks.md, "A command's exit"); what libraries printed (sys.stdout, pointed at
            # stderr above) is flushed here, as the shutdown would have
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
        try:
            with threads.limited(spec.get("threads")):  # this task's share of the cores (`execute`)
                result = getattr(task, name)(spec)
            send(out, (True, result))
        except Exception as exc:  # the task's error goes back to the client, which raises it there
            send(out, (False, f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))


if __name__ == "__main__":
    main()
