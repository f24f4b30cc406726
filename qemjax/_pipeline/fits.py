"""Whether a mesh fits one process: `simplify` refuses, before it reads the mesh, a run in one process that
would need more memory than this machine has available, and says how to run it partitioned instead.

Without the check such a run grows until the system kills it, minutes later and with no word of why. The
need is the faces times the memory an in-core run takes per input face at its peak (`BYTES_PER_FACE`,
measured: docs/large-meshes.md, "Which path"); the faces of a file are read from its header (PLY, binary
STL, OFF) or counted (OBJ, ASCII STL), and only for a file large enough that it might not fit. The count
is a lower bound (a polygon counts as one triangle), so a refusal is never for a mesh smaller than said.
``partition=False`` (``--no-partition``) runs in one process regardless.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

# an in-core run's peak memory per input face (the growth of the peak from one size to another, the default
# method), rounded up (experiments/figures/memory_peak.py; docs/large-meshes.md, "Which path")
BYTES_PER_FACE = 512
SMALLEST_FACE_BYTES = 12  # the fewest bytes a face takes in a file (binary PLY: a count and three 4-byte indices;
# its vertices come on top): a file of S bytes holds at most S / 12 faces
_BLOCK = 1 << 24  # bytes read at a time when faces are counted


class TooLargeError(MemoryError, ValueError):
    """A mesh too large for one process on this machine: a MemoryError, and a ValueError like every other
    input `simplify` refuses. One line, with the way to run it partitioned."""


def available() -> int | None:
    """The memory this process may still take, in bytes: the system's available memory (Linux
    ``MemAvailable``), or less where a control group limits the process; None where it cannot be read."""
    out = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    out = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if out is None:
        try:
            out = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    for limit, used in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),  # cgroup v2, v1
                        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            cap, now = Path(limit).read_text().strip(), int(Path(used).read_text())
        except (OSError, ValueError):
            continue
        if cap.isdigit() and int(cap) < 1 << 60:  # "max", or v1's huge number: no limit
            out = min(out, max(int(cap) - now, 0))
    return out


def _count(path: Path, needles: tuple) -> int:
    """How often the file holds any of ``needles`` (all of one length; the file's start counts as a "\\n")."""
    n, size = 0, len(needles[0])
    tail = b"\n"  # the last size - 1 bytes seen: a match cut at a block's end, too short to be counted twice
    with open(path, "rb") as f:
        while block := f.read(_BLOCK):
            text = tail + block
            n += sum(text.count(s) for s in needles)
            tail = text[-(size - 1):]
    return n


def file_faces(path) -> int | None:
    """At least how many triangles the mesh file at ``path`` holds (None: a format not counted here), from
    its header (PLY, binary STL, OFF) or by counting its face lines (OBJ, ASCII STL)."""
    path = Path(path)
    fmt = path.suffix.lower()
    try:
        if fmt == ".ply":
            from .._io import ply

            with open(path, "rb") as f:
                face = ply.parse_header(f.read(1 << 20)).element("face")
            return None if face is None else face.rows
        if fmt == ".stl":
            from .._io.files import binary_stl_count

            with open(path, "rb") as f:
                count = binary_stl_count(f.read(84), path.stat().st_size)
            return _count(path, (b"endfacet",)) if count is None else count
        if fmt == ".obj":
            return _count(path, (b"\nf ", b"\nf\t"))
        if fmt == ".off":
            with open(path, "rb") as f:
                words = f.read(1 << 16).split(b"#")[0].split()
            return int(words[2]) if words[:1] == [b"OFF"] and len(words) > 2 else None
    except (OSError, ValueError, IndexError):
        return None  # the reader says what is wrong with the file
    return None


def faces_of(mesh: Any, room: int) -> int | None:
    """At least how many faces ``mesh`` (what `simplify` takes) has, when that is known without reading it
    whole; None for a file whose every possible face fits in ``room`` bytes, or of a format not counted."""
    if isinstance(mesh, (str, os.PathLike)):
        try:
            size = os.path.getsize(mesh)
        except OSError:
            return None  # the reader names the missing file
        if size // SMALLEST_FACE_BYTES * BYTES_PER_FACE <= room:
            return None  # fits, whatever the file holds
        return file_faces(mesh)
    faces = mesh[1] if isinstance(mesh, tuple) and len(mesh) >= 2 else getattr(mesh, "faces", None)
    try:
        return len(faces) if faces is not None else None
    except TypeError:
        return None


def check(mesh: Any, what: str | None = None) -> None:
    """Raise `TooLargeError` when the in-core run of ``mesh`` would need more memory than is available. Its
    advice: a partitioned run where one can read the mesh, else one process regardless; ``what``: a caller
    that runs in one process only (``lod_chain``), named."""
    room = available()
    short = shortfall(None if room is None else faces_of(mesh, room), room)
    if short is None:
        return
    name = os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else "the mesh"
    regardless = "in one process regardless (--no-partition; partition=False)"
    if what is not None:
        advice = f"{what} runs in one process: run it {regardless}"
    elif isinstance(mesh, (str, os.PathLike)) and Path(mesh).suffix.lower() not in (".ply", ".obj", ".stl"):
        advice = f"a partitioned run reads PLY, OBJ and STL files: convert it to one, or run it {regardless}"
    else:
        advice = ("run it partitioned (--partition; partition=True in Python), which reads it in parts, or "
                  + regardless)
    raise TooLargeError(f"{name}: {short}: {advice}")


def shortfall(n: int | None, room: int | None, per_face: int = BYTES_PER_FACE) -> str | None:
    """What an in-core run of ``n`` faces lacks, in words, when it would need more than ``room`` bytes (the
    memory `available`); None when it fits, or either is unknown. ``per_face``: the bytes a face takes in
    what is done with them (`shapes` making a mesh: less than a run)."""
    if room is None or not n or n * per_face <= room:
        return None
    return (f"{n:,} faces need about {_size(n * per_face)} in one process, and this machine has "
            f"{_size(room)} available")


def _size(b: int) -> str:
    return f"{b / 2**30:.1f} GiB" if b >= 2**29 else f"{b / 2**20:.0f} MiB"
