"""Ahead-of-time compilation of the compiled host loops (numba), so that a fresh install's first run does not
spend its time compiling them.

Every numba function of qemjax is ``@njit(cache=True)``: compiled once per signature, then kept in numba's
cache, by default the ``__pycache__`` folder beside its module. numba checks an entry against the module's
source by content (a hash), the function's bytecode, numba's version and the CPU, so entries made from the
same sources on the same machine stay valid however the files are copied.

``signatures.txt`` (beside this file) lists the signatures the runs of `workloads` use. `compile_all` compiles
each of them into the cache: the package's build (``setup.py``) does it into the files a ``pip install .``
installs, so the first ``qemjax simplify`` loads the loops instead of compiling them; ``qemjax compile`` does
it for an editable install, a ``NUMBA_CACHE_DIR`` of the user's or a container image. A signature the list
lacks still works: numba compiles it on first use, as before. ``tests/test_ahead.py`` checks that the list
covers every signature the workloads use.
"""
from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
import time
import types
from pathlib import Path

MANIFEST = Path(__file__).with_name("signatures.txt")
_PACKAGE = Path(__file__).resolve().parents[1]  # qemjax/


def _dispatchers() -> dict:
    """{(module, name): numba dispatcher} of the qemjax modules imported so far."""
    from numba.core.registry import CPUDispatcher

    out = {}
    for mod_name in [m for m in list(sys.modules) if m.startswith("qemjax.")]:
        mod = sys.modules.get(mod_name)
        for name, obj in list(vars(mod).items()) if mod is not None else ():
            if isinstance(obj, CPUDispatcher) and getattr(obj.py_func, "__module__", None) == mod_name:
                out[(mod_name, name)] = obj
    return out


def used_signatures() -> dict:
    """{(module, name): sorted signature texts} that the dispatchers of this process have compiled or loaded."""
    out = {}
    for key, disp in _dispatchers().items():
        if disp.targetoptions.get("inline") == "always":
            continue  # an inlined helper is compiled into its callers, never called on its own
        sigs = sorted({_sig_text(s) for s in disp.signatures})
        if sigs:
            out[key] = sigs
    return out


def _sig_text(sig) -> str:
    return "(" + ", ".join(_type_text(t) for t in sig) + ("," if len(sig) == 1 else "") + ")"


def _type_text(t) -> str:
    """A numba type as text that `_sig_types` evaluates back: its repr, but a named tuple (whose repr does not
    evaluate) as ``named('module.Class', member types...)``."""
    from numba.core import types as nt

    if isinstance(t, (nt.NamedTuple, nt.NamedUniTuple)):
        cls = t.instance_class
        return f"named('{cls.__module__}.{cls.__qualname__}', " + ", ".join(_type_text(m) for m in t.types) + ")"
    return repr(t)


def _named(path: str, *members):
    """The named-tuple type ``named(...)`` in a signature's text stands for (`_type_text`)."""
    from numba.core import types as nt

    module, _, name = path.rpartition(".")
    return nt.BaseTuple.from_types(members, getattr(importlib.import_module(module), name))


def _sig_types(text: str) -> tuple:
    """A signature's text back into numba types (the reprs numba gives its types evaluate in `numba.types`)."""
    from numba.core import types as nt

    names = {k: getattr(nt, k) for k in dir(nt) if not k.startswith("_")}
    names["omitted"] = lambda default: nt.Omitted(default)
    names["named"] = _named
    text = re.sub(r"Literal\[\w+\]\(", "literal(", text)  # Literal[int](0): a constant a caller passes
    return eval(text, {"__builtins__": {}}, names)  # noqa: S307 - our own manifest, written by `write`


def read_manifest(path: Path = MANIFEST) -> dict:
    """{(module, name): [signature texts]} from ``signatures.txt`` (lines ``module name (types...)``)."""
    out: dict = {}
    if not path.exists():
        return out
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            mod, name, sig = line.split(" ", 2)
            out.setdefault((mod, name), []).append(sig)
    return out


def write_manifest(sigs: dict, path: Path = MANIFEST) -> None:
    lines = ["# Signatures compiled ahead (qemjax._ahead): `python -m qemjax._ahead --record` writes this file",
             "# from the runs of qemjax._ahead.workloads; one line per signature: module function (types)"]
    for (mod, name) in sorted(sigs):
        lines += [f"{mod} {name} {s}" for s in sigs[(mod, name)]]
    path.write_text("\n".join(lines) + "\n")


def _bare_packages() -> None:
    """Register qemjax's sub-packages without running their ``__init__`` (some import JAX, which a build
    environment does not have): the compiled modules need only numpy, numba and scipy."""
    for init in sorted(_PACKAGE.rglob("__init__.py")):
        rel = init.parent.relative_to(_PACKAGE.parent)
        name = ".".join(rel.parts)
        if name == "qemjax" or name in sys.modules:
            continue
        mod = types.ModuleType(name)
        mod.__path__ = [str(init.parent)]
        mod.__package__ = name
        sys.modules[name] = mod


def compile_all(manifest: dict | None = None, *, bare: bool = False, log=None) -> dict:
    """Compile (or load from the cache) every signature of ``manifest`` (default: ``signatures.txt``) into
    numba's cache. Returns {"signatures", "compiled", "loaded", "failed", "seconds"}; a signature that fails
    (a changed function, say) is reported and skipped: numba compiles it when a run uses it."""
    t0 = time.perf_counter()
    manifest = read_manifest() if manifest is None else manifest
    if bare:
        _bare_packages()
    counts = {"signatures": 0, "compiled": 0, "loaded": 0, "failed": []}
    for (mod_name, name), sigs in sorted(manifest.items()):
        try:
            disp = getattr(importlib.import_module(mod_name), name)
        except (ImportError, AttributeError) as exc:
            counts["failed"].append(f"{mod_name}.{name}: {exc}")
            continue
        for text in sigs:
            counts["signatures"] += 1
            try:
                sig = _sig_types(text)
                misses = sum(disp._cache_misses.values())
                disp.compile(sig)
                counts["compiled" if sum(disp._cache_misses.values()) > misses else "loaded"] += 1
            except Exception as exc:  # noqa: BLE001 - see the docstring
                counts["failed"].append(f"{mod_name}.{name}{text}: {type(exc).__name__}: {exc}"[:300])
            if log is not None:
                log(counts)
    counts["seconds"] = time.perf_counter() - t0
    return counts


def compile_ahead(jobs: int = 0, *, build: bool = False) -> dict:
    """`compile_all` in ``jobs`` processes (0: one per core), each compiling its share of the functions,
    then a last pass here that compiles what they left out and counts (the processes' saves of one shared
    helper take turns: `qemjax._mesh.compiled`)."""
    t0 = time.perf_counter()
    jobs = jobs or os.cpu_count() or 1
    if jobs > 1:
        cmd = [sys.executable, "-m", "qemjax._ahead"] + (["--build"] if build else [])
        procs = [subprocess.Popen(cmd + ["--slice", f"{i}/{jobs}"]) for i in range(jobs)]
        for p in procs:
            p.wait()
    out = compile_all(bare=build)
    out["seconds"] = time.perf_counter() - t0
    return out
