"""Old code against new code: identical outputs, and wall/CPU time alternating.

The package as it was at a git revision is unpacked into a temporary folder under the name
``qemjax_old`` (it uses relative imports only). Each version runs in a process of its own (`Remote`), the
two called in turn on the same meshes, so timing medians share the machine's state. Not in one process:
numba's dispatcher types a named tuple by its name and fields, so the second package's compiled loops that
take named tuples (the selection's) missed the fast argument typing and were typed in Python at every call
(about 0.4 ms a round), which made whichever version ran second look slower. Outputs are compared by hash
(vertices, faces, history).

    python experiments/ab_compare.py --rev HEAD --meshes cow stanford-bunny --ratios 0.1 0.01   # outputs
    python experiments/ab_compare.py --rev HEAD --meshes armadillo-x16 --ratios 0.01 --repeats 7 --time
    python experiments/ab_compare.py --rev 02a1390 --meshes armadillo-x16 --ratios 0.01 --repeats 5 --time \
        --new-option placement=rank          # an option of the new code against the old default
    python experiments/ab_compare.py --rev HEAD --meshes cow --option method=accurate   # both run an option
    (--option and --new-option values: true/false are bools, numbers floats, anything else a string)
"""
from __future__ import annotations

import argparse
import hashlib
import importlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _value(text: str):
    """A --new-option value: true/false as a bool, a number as a float, else the text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        return float(text)
    except ValueError:
        return text


# absolute module names in older revisions: the scheduler registry and the lazy submodules. Left as they are,
# the old package would import this checkout's schedulers and compare the new scheduler with itself
ABSOLUTE_NAMES = ('"qemjax._schedulers.', 'f"qemjax.{name}"')


def _own_modules(root: Path, as_name: str) -> None:
    """Point the absolute module names (`ABSOLUTE_NAMES`) of the package copy at ``root`` at the copy."""
    for path in root.rglob("*.py"):
        text = path.read_text()
        new = text
        for name in ABSOLUTE_NAMES:
            new = new.replace(name, name.replace("qemjax", as_name, 1))
        if new != text:
            path.write_text(new)


def package_at(rev: str) -> Path:
    """A new folder holding the qemjax package as it was at git revision ``rev`` (``folder / "qemjax"``)."""
    tmp = Path(tempfile.mkdtemp(prefix="qemjax-old-"))
    tar = subprocess.run(["git", "-C", str(HERE.parent), "archive", rev, "qemjax"], check=True,
                         capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tmp)], input=tar, check=True)
    return tmp


def load_old(rev: str, as_name: str = "qemjax_old"):
    """The qemjax package at git revision ``rev``, imported as ``as_name``."""
    tmp = package_at(rev)
    os.rename(tmp / "qemjax", tmp / as_name)
    _own_modules(tmp / as_name, as_name)
    sys.path.insert(0, str(tmp))
    pkg = importlib.import_module(as_name)
    _rename_named_tuples(as_name)
    return pkg


def _rename_named_tuples(as_name: str) -> None:
    """Give the named tuple classes of the package ``as_name`` (every module imported) a name of their own.
    numba's dispatcher types a named tuple argument by its class name and fields: with two packages in one
    process, the second one's compiled loops that take named tuples (the selection's) missed the fast
    argument typing and were typed in Python at every call (about 0.4 ms a round), which made whichever
    version ran second look slower. The package's modules are imported first (some load lazily)."""
    import pkgutil

    for info in pkgutil.walk_packages(sys.modules[as_name].__path__, as_name + "."):
        try:
            importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - an optional dependency missing: nothing of it runs
            pass
    for name, module in list(sys.modules.items()):
        if module is None or not (name == as_name or name.startswith(as_name + ".")):
            continue
        for cls in vars(module).values():
            if (isinstance(cls, type) and issubclass(cls, tuple) and hasattr(cls, "_fields")
                    and cls.__module__ == name and not cls.__name__.startswith(as_name)):
                cls.__name__ = cls.__qualname__ = f"{as_name}_{cls.__name__}"


class Reply:
    """What a `Remote` call returns: the result's vertices, faces, stats and `digest`, and the call's wall
    and CPU seconds measured in the serving process."""

    def __init__(self, res, wall_s: float, cpu_s: float):
        self.vertices, self.faces = np.asarray(res.vertices), np.asarray(res.faces)
        self.stats, self.digest = res.stats, digest(res)
        self.wall_s, self.cpu_s = wall_s, cpu_s


def _serve(conn, make, args) -> None:
    """The serving process of `Remote`: ``make(*args)`` once, then each call timed until None arrives."""
    import warnings

    warnings.simplefilter("ignore")
    fn = make(*args)
    while (msg := conn.recv()) is not None:
        call_args, call_kw = msg
        try:
            c0, t0 = cpu_time(), time.perf_counter()
            res = fn(*call_args, **call_kw)
            conn.send(Reply(res, time.perf_counter() - t0, cpu_time() - c0))
        except Exception as exc:  # noqa: BLE001 - handed to the caller, which raises it
            conn.send(exc)


class Remote:
    """A function made by ``make(*args)`` in a process of its own (spawned: nothing of this process's
    numba or JAX state), called with pickled arguments; each call returns a `Reply`."""

    def __init__(self, make, *args):
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child, make, args), daemon=True)
        self.proc.start()

    def __call__(self, *args, **kw) -> Reply:
        self.conn.send((args, kw))
        out = self.conn.recv()
        if isinstance(out, Exception):
            raise out
        return out

    def close(self) -> None:
        self.conn.send(None)
        self.proc.join(30)


def simplify_of(rev: str | None, as_name: str = "qemjax_old"):
    """``simplify`` of qemjax at git revision ``rev`` (None: this checkout), for a `Remote`."""
    if rev is None:
        import qemjax

        return qemjax.simplify
    return load_old(rev, as_name).simplify


def digest(res) -> str:
    h = hashlib.sha256()
    for a in (res.vertices, res.faces, res.history.pairs, res.history.positions, res.history.costs):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def cpu_time() -> float:
    t = os.times()
    return t.user + t.system


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="the old code's git revision")
    ap.add_argument("--new", default=None, help="the new code's git revision (default: the working tree)")
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny"])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--scheduler", default="parallel")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--time", action="store_true", help="report medians of wall and CPU time")
    ap.add_argument("--out", default=None, help="append rows to this CSV")
    ap.add_argument("--new-option", nargs="*", default=[], metavar="KEY=VALUE",
                    help="keywords of simplify for the new code only (e.g. placement=rank)")
    ap.add_argument("--option", nargs="*", default=[], metavar="KEY=VALUE",
                    help="keywords of simplify for both codes (e.g. method=accurate)")
    args = ap.parse_args()
    both_kw = {k: _value(v) for k, v in (kv.split("=", 1) for kv in args.option)}
    new_kw = {**both_kw, **{k: _value(v) for k, v in (kv.split("=", 1) for kv in args.new_option)}}
    import warnings

    warnings.simplefilter("ignore")  # above-target warnings of the mesh/ratio cases are not the point here
    import meshes as bench_meshes

    old = Remote(simplify_of, args.rev)
    new = Remote(simplify_of, args.new or None, "qemjax_new")
    rows = []
    for name in args.meshes:
        bm = bench_meshes.load(name)
        V, F = bm.V, bm.F
        for ratio in args.ratios:
            times = {"old": [], "new": []}
            cpus = {"old": [], "new": []}
            hashes = {}
            kws = {"old": both_kw, "new": new_kw}
            for tag, run in (("old", old), ("new", new)):  # warm-up: compile both
                run((V, F), ratio=ratio, scheduler=args.scheduler, **kws[tag])
            for rep in range(args.repeats):
                order = (("old", old), ("new", new)) if rep % 2 == 0 else (("new", new), ("old", old))
                for tag, run in order:
                    res = run((V, F), ratio=ratio, scheduler=args.scheduler, **kws[tag])
                    times[tag].append(res.wall_s)
                    cpus[tag].append(res.cpu_s)
                    hashes[tag] = res.digest
            same = hashes["old"] == hashes["new"]
            row = dict(mesh=name, faces=len(F), ratio=ratio, scheduler=args.scheduler, rev=args.rev,
                       new=(args.new or "working tree") + "".join(f" {k}={v}" for k, v in new_kw.items()),
                       identical=same, hash_old=hashes["old"], hash_new=hashes["new"], repeats=args.repeats,
                       wall_old=statistics.median(times["old"]), wall_new=statistics.median(times["new"]),
                       cpu_old=statistics.median(cpus["old"]), cpu_new=statistics.median(cpus["new"]))
            rows.append(row)
            msg = f"{name} {ratio}: {'identical' if same else 'DIFFERENT'} ({hashes['old']} / {hashes['new']})"
            if args.time:
                msg += (f"  wall {row['wall_old']:.3f} -> {row['wall_new']:.3f} s"
                        f"  cpu {row['cpu_old']:.3f} -> {row['cpu_new']:.3f} s  (medians of {args.repeats})")
            print(msg, flush=True)
    old.close()
    new.close()
    if args.out:
        import csv

        new_file = not Path(args.out).exists()
        with open(args.out, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            if new_file:
                w.writeheader()
            w.writerows(rows)
    return 0 if all(r["identical"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
