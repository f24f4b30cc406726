"""The compiled loops of an installed build, for a checkout of the same sources (`conftest.pytest_configure`).

The tests import the package from the checkout, whose numba cache is empty on a fresh clone: every test
process would compile the loops again (two workers at once on two cores, a minute or more each). Where the
environment also holds qemjax installed from a build of the very same sources (the README's and CI's
`pip install '.[test]'`, which compiles them ahead: `qemjax._ahead`), its cached loops are copied beside the
checkout's modules first. The same sources throughout, not module by module: numba checks an entry against
its own module only, so a caller cached from other sources could run an old callee (docs/contributing.md).
"""
from __future__ import annotations

import importlib.metadata
import os
import shutil
import sysconfig
from pathlib import Path


def installed(path: list[str] | None = None):
    """The qemjax distribution installed in ``path`` (default: this environment's site-packages), or None;
    not the checkout's own metadata (a build leaves qemjax.egg-info in it, listing no compiled loops)."""
    path = sorted({sysconfig.get_paths()[k] for k in ("purelib", "platlib")}) if path is None else path
    return next(iter(importlib.metadata.distributions(name="qemjax", path=path)), None)


def copy_into(dist, repo: Path) -> int:
    """Copy ``dist``'s compiled loops (numba's ``*.nbi``/``*.nbc``) beside the modules of the checkout
    ``repo`` when its ``qemjax/**/*.py`` are exactly the installed ones; files already there are kept.
    Returns how many were copied."""
    files = [f for f in dist.files or () if f.parts[0] == "qemjax"]
    built = {f: Path(f.locate()).resolve() for f in files if f.suffix in (".nbi", ".nbc")}
    if not built:
        return 0  # nothing compiled ahead (an editable install)
    sources = [f for f in files if f.suffix == ".py"]
    mine = {p.relative_to(repo).as_posix() for p in (repo / "qemjax").rglob("*.py")}
    if {f.as_posix() for f in sources} != mine or any(
            Path(f.locate()).read_bytes() != repo.joinpath(*f.parts).read_bytes() for f in sources):
        return 0
    copied = 0
    for f, src in built.items():
        dst = repo.joinpath(*f.parts)
        if dst.exists() or not src.is_file():
            continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        tmp = dst.with_name(f"{dst.name}.{os.getpid()}.tmp")  # (workers may copy at once: each file whole)
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)
        copied += 1
    return copied
