"""A file or folder that one run at a time uses (a sweep's table, a partitioned run's scratch folder): `take`
an exclusive lock on a file beside it, or ValueError at once when another run holds it; `release` removes
the lock file and lets go. The file is removed while held, so that a process forked meanwhile (a fork-based
executor's worker), which keeps the lock it inherited, holds a file nobody takes again; a run that opened
the file before it was removed sees it is gone and takes the one there now.

Where files cannot be locked (no ``fcntl``, as on Windows, or a file system without locks) nothing is held,
and no lock file is left.
"""
from __future__ import annotations

import os
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


def take(path: Path, busy: str) -> int | None:
    """A descriptor of ``path`` locked exclusively (made when missing); ValueError(``busy``) when another run
    holds it; None where it cannot be locked."""
    if fcntl is None:  # pragma: no cover - Windows
        return None
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ValueError(busy) from None
        except OSError:  # a file system without locks: nobody can hold it, so the file made for it goes too
            os.close(fd)
            try:
                os.unlink(path)
            except OSError:
                pass
            return None
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except OSError:  # removed by the run that held it, after this one opened it
            same = False
        if same:
            return fd
        os.close(fd)


def release(path: Path, fd: int | None) -> None:
    """Remove ``path`` and let go of the lock `take` gave (nothing for None)."""
    if fd is None:
        return
    try:
        os.unlink(path)
    except OSError:
        pass
    os.close(fd)
