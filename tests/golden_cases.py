"""Golden-output cases: the fixed list of `qemjax.simplify` calls whose outputs must stay bit-identical, and
the hash of one result. Every case runs ``method="classic"`` (``QEM()``, the default until the default was
chosen by ranking) unless it names another, so those hashes are the ones the package gave before; the
``default/`` cases pin `qemjax.QEM.default` (what `simplify` runs when no method is given). Used by ``tests/test_golden.py`` and ``experiments/golden.py`` (which writes
``tests/golden_hashes.json``). Plain module (no pytest): the script imports it with ``tests/`` on sys.path.

A case is an id (``parallel/cow/0.1``), a mesh (a file in ``../shared/meshes`` or a `qemjax.shapes` call) and
the keywords of `qemjax.simplify`. Its digest is sha256 over res.vertices, res.faces, res.history.pairs,
res.history.positions and res.history.costs, each preceded by its name, dtype and shape, so a change of any
value, dtype, shape or of the contraction order changes it.

Hashes hold for the library versions they were made with. They used to depend on the number of usable
CPUs too (XLA's CPU fusion emitter split loops by core count); since the kernels compile with
`_kernels.CPU_COMPILER_OPTIONS` they do not: ``taskset -c 1 python experiments/golden.py --check`` gives
57/57 OK against hashes made with 2 CPUs (2026-11-24). The file still records the CPU count.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "meshes"
HASHES = Path(__file__).resolve().parent / "golden_hashes.json"
DIGEST_CHARS = 16

# every mesh in ../shared/meshes (*.obj, *.off and spot/spot.obj), listed explicitly: a new file in
# ../shared must not silently add an unguarded case, and a missing one must show up as a skip
SHARED_MESHES = (
    "3holes.off", "armadillo.obj", "beetle.obj", "bumpy-cube.obj", "cow.obj", "face.obj", "fandisk.obj",
    "fertility.off", "homer.obj", "max-planck-10k.obj", "rocker-arm-small.off", "rocker-arm.obj",
    "spot/spot.obj", "stanford-bunny.obj", "suzanne.obj", "teapot.obj", "truck.obj",
)
# greedy is ~2 ms a contraction: the small meshes whose two ratios together take a few seconds. Left out to
# keep the golden test near 90 s on a 2-core machine: cow, spot, teapot (10-25 s each), max-planck-10k (~25 s),
# fandisk (~200 s).
GREEDY_MESHES = ("rocker-arm-small.off", "suzanne.obj", "beetle.obj")
DEFAULT_MESHES = ("cow.obj", "beetle.obj", "fandisk.obj", "suzanne.obj", "truck.obj", "rocker-arm-small.off")
RATIOS = (0.1, 0.01)

# generated meshes (no files): name -> (qemjax.shapes function, its keywords, schedulers at 10 %)
SHAPES = {
    "icosphere-3": ("icosphere", {"subdivisions": 3}, ("parallel", "greedy")),  # 1,280 faces, closed, uniform
    "bumpy-sphere-3": ("bumpy_sphere", {"subdivisions": 3}, ("parallel", "greedy")),  # 1,280 faces, detail
    "bumpy-sphere-4": ("bumpy_sphere", {"subdivisions": 4}, ("parallel",)),  # 5,120 faces (greedy: ~10 s)
    "grid-24-hole": ("grid", {"n": 24, "hole": True}, ("parallel", "greedy")),  # 896 faces, two boundary loops
    "torus-32x16": ("torus", {"n_major": 32, "n_minor": 16}, ("parallel", "greedy")),  # 1,024 faces, genus 1
}

# pair_threshold cases: about 1 % of the bounding-box diagonal (truck 2.0000, suzanne 3.7754), exact floats
TRUCK_THRESHOLD = 0.02
SUZANNE_THRESHOLD = 0.04


@dataclass(frozen=True)
class Case:
    id: str
    mesh: str  # a path under ../shared/meshes, or a key of SHAPES
    kwargs: dict = field(default_factory=dict, hash=False)

    @property
    def shared(self) -> bool:
        return self.mesh not in SHAPES


def _name(mesh: str) -> str:
    return mesh if mesh in SHAPES else Path(mesh).stem


def cases() -> list[Case]:
    out = []
    for mesh in SHARED_MESHES:
        for r in RATIOS:
            out.append(Case(f"parallel/{_name(mesh)}/{r:g}", mesh, {"ratio": r}))
    for mesh in GREEDY_MESHES:
        for r in RATIOS:
            out.append(Case(f"greedy/{_name(mesh)}/{r:g}", mesh, {"ratio": r, "scheduler": "greedy"}))
    variants = [
        ("preserve_topology=False", ("cow.obj", "suzanne.obj"), {"preserve_topology": False}),
        ("placement=endpoints", ("cow.obj", "rocker-arm-small.off"), {"placement": "endpoints"}),
        ("area_weighted=False", ("cow.obj", "rocker-arm-small.off"), {"area_weighted": False}),
    ]
    for label, meshes, kw in variants:
        for mesh in meshes:
            out.append(Case(f"{label}/{_name(mesh)}/0.05", mesh, {"ratio": 0.05} | kw))
    for mesh, t in (("truck.obj", TRUCK_THRESHOLD), ("suzanne.obj", SUZANNE_THRESHOLD)):
        out.append(Case(f"pair_threshold={t:g}/{_name(mesh)}/0.05", mesh, {"ratio": 0.05, "pair_threshold": t}))
    for shape, (_, _, schedulers) in SHAPES.items():
        for scheduler in schedulers:
            out.append(Case(f"{scheduler}/{shape}/0.1", shape, {"ratio": 0.1, "scheduler": scheduler}))
    for mesh in DEFAULT_MESHES:
        for r in RATIOS:
            out.append(Case(f"default/{_name(mesh)}/{r:g}", mesh, {"ratio": r, "method": "default"}))
    for shape in ("bumpy-sphere-3", "torus-32x16"):
        for scheduler in ("parallel", "greedy"):
            out.append(Case(f"default/{scheduler}/{shape}/0.1", shape,
                            {"ratio": 0.1, "scheduler": scheduler, "method": "default"}))
    # the memoryless quadrics' rebuild (`method="accurate"`), closed and open, on both schedulers
    for shape in ("bumpy-sphere-3", "grid-24-hole"):
        for scheduler in ("parallel", "greedy"):
            out.append(Case(f"accurate/{scheduler}/{shape}/0.1", shape,
                            {"ratio": 0.1, "scheduler": scheduler, "method": "accurate"}))
    out.append(Case("accurate/cow/0.1", "cow.obj", {"ratio": 0.1, "method": "accurate"}))
    # the methods whose kernels sum over a ring (minimum area difference, ESQEM's curvature): their sums in a
    # fixed order keep them the same bits on every CPU (the cow's area run by the greedy queue was not)
    for method in ("area", "esqem"):
        for scheduler in ("parallel", "greedy"):
            out.append(Case(f"{method}/{scheduler}/bumpy-sphere-3/0.1", "bumpy-sphere-3",
                            {"ratio": 0.1, "scheduler": scheduler, "method": method}))
        out.append(Case(f"{method}/greedy/cow/0.1", "cow.obj", {"ratio": 0.1, "scheduler": "greedy", "method": method}))
    ids = [c.id for c in out]
    assert len(set(ids)) == len(ids), "duplicate case ids"
    return out


def mesh_input(case: Case, resolve=None):
    """What `simplify` gets: the file path (through ``resolve(relative path)``, default SHARED / path), or the
    generated `qemjax.shapes` mesh."""
    if case.shared:
        return str(resolve(case.mesh) if resolve is not None else SHARED / case.mesh)
    from qemjax import shapes

    fn, kw, _ = SHAPES[case.mesh]
    return getattr(shapes, fn)(**kw)


def digest(res) -> str:
    """sha256 (first DIGEST_CHARS hex) over the bytes of the outputs that must not change."""
    h = hashlib.sha256()
    for name, a in (("vertices", res.vertices), ("faces", res.faces), ("pairs", res.history.pairs),
                    ("positions", res.history.positions), ("costs", res.history.costs)):
        a = np.ascontiguousarray(a)
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:DIGEST_CHARS]


def run(case: Case, resolve=None) -> dict:
    """Simplify one case; its digest, output face count and number of contractions."""
    import qemjax

    # positions-only runs: spot (UVs), beetle and suzanne (stored normals) carry attributes, which the default
    # (attributes='auto', issue #21) keeps, with seams that change their contractions; these hashes guard the
    # geometric path, identical to the default on every mesh without attributes (the other 45 cases). The
    # attribute path is tested in tests/test_attributes.py.
    res = qemjax.simplify(mesh_input(case, resolve), **({"attributes": None, "method": "classic"} | case.kwargs))
    return {"hash": digest(res), "faces_out": int(len(res.faces)), "contractions": int(len(res.history))}


def load_golden(path: Path = HASHES) -> dict:
    """The stored file: {"cases": {id: {"hash", "faces_out", ...}}, "regenerations": [...], ...}."""
    if not path.exists():
        return {"cases": {}}
    return json.loads(path.read_text())


def usable_cpus() -> int:
    """CPUs this process may run on. The parallel scheduler's outputs depend on it (with one core, e.g.
    under ``taskset -c 0``, 44 of its 47 hashes differ from those made with two), so the file records it."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


REGENERATE = 'python experiments/golden.py --regenerate --why "<the deliberate change>"'
