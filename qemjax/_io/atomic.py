"""`replace_atomically`: a file written whole or not at all, for files other processes read or a later run
resumes from (a partitioned run's pieces, JAX's compilation cache entries)."""
from __future__ import annotations

import os
import threading
from pathlib import Path


def replace_atomically(path: Path, write) -> None:
    """Calls ``write(tmp_path)`` then renames the temporary file onto ``path``: readers see the old file or
    the whole new one, never a part. The temporary name (``.NAME.PID.THREAD.tmp``) is this process's and
    thread's own."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
