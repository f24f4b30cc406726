"""Benchmark meshes: the real meshes in ``../shared/meshes`` plus large ones made in code.

``names()`` lists what is available; ``load(name)`` returns a :class:`BenchMesh`.

- Shared meshes are read with trimesh (``process=False, force="mesh"``, so nothing is merged or reordered on
  load) and then *welded*: vertices with exactly equal coordinates are merged (UV seams in spot, the split
  corners of teapot / beetle / face). Every method gets the welded mesh, so this is a geometry-only benchmark;
  the raw arrays stay on the record as ``V_raw`` / ``F_raw``.
- ``armadillo-x16`` (~1.38 M faces) and ``armadillo-x64`` (~5.5 M faces) are ``armadillo.obj`` Loop-subdivided
  two and three times with ``trimesh.remesh.subdivide_loop`` (``stanford-bunny-x16``, ``fertility-x16`` and
  ``rocker-arm-x16`` likewise, twice); they are cached as ``.npz`` under
  ``experiments/results/cache/`` (git-ignored) because subdivision takes a while.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED_MESHES = ROOT.parent / "shared" / "meshes"
CACHE = ROOT / "experiments" / "results" / "cache"

MESH_SUFFIXES = (".obj", ".off", ".ply", ".stl")

# name -> (base mesh, Loop subdivision iterations); each iteration multiplies the face count by 4
SUBDIVIDED = {"armadillo-x16": ("armadillo", 2), "armadillo-x64": ("armadillo", 3),
              # more large inputs of other shapes, for the partitioned runs' quality
              "stanford-bunny-x16": ("stanford-bunny", 2), "fertility-x16": ("fertility", 2),
              "rocker-arm-x16": ("rocker-arm", 2),
              # between the compiled rounds' limit and the large meshes (`probes/round_paths.py`)
              "armadillo-x4": ("armadillo", 1), "stanford-bunny-x4": ("stanford-bunny", 1),
              "bumpy-cube-x4": ("bumpy-cube", 1), "face-x4": ("face", 1)}


@dataclass
class BenchMesh:
    name: str
    V: np.ndarray  # (n, 3) float64, welded
    F: np.ndarray  # (m, 3) int64, indices into V
    source: str  # file path, or how it was made
    V_raw: np.ndarray | None = field(default=None, repr=False)
    F_raw: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_faces(self) -> int:
        return len(self.F)

    @property
    def n_vertices(self) -> int:
        return len(self.V)


def shared_files() -> dict[str, Path]:
    """name -> path for each mesh file in ``../shared/meshes`` (one level of sub-folders, e.g. spot/)."""
    if not SHARED_MESHES.is_dir():
        return {}
    files = {}
    for path in sorted(SHARED_MESHES.rglob("*")):
        if path.suffix.lower() in MESH_SUFFIXES and len(path.relative_to(SHARED_MESHES).parts) <= 2:
            files[path.stem] = path
    return files


def names(*, big: bool = False) -> list[str]:
    """Shared mesh names sorted by face count is not known without loading, so alphabetically; big ones last."""
    out = list(shared_files())
    if big:
        out += list(SUBDIVIDED)
    return out


def weld(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices with exactly equal coordinates; returns (V', F') with F' indexing V'.

    Faces are kept as they are (a face whose corners coincide stays, degenerate); unreferenced vertices are
    dropped. The vertex order follows the first occurrence in ``V``.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    # renumber the unique rows by first occurrence, to keep the original order
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    F2 = rank[inverse][F]
    V2 = V[first[order]]
    used, F3 = np.unique(F2.ravel(), return_inverse=True)
    return V2[used], F3.reshape(-1, 3)


def _read(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.load(str(path), process=False, force="mesh")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def _subdivided(name: str) -> BenchMesh:
    import trimesh.remesh

    base_name, iterations = SUBDIVIDED[name]
    cache_file = CACHE / f"{name}.npz"
    base = load(base_name)
    source = f"{base_name} Loop-subdivided x{iterations} (trimesh.remesh.subdivide_loop)"
    if cache_file.exists():
        data = np.load(cache_file)
        return BenchMesh(name, data["V"], data["F"], source)
    V, F = trimesh.remesh.subdivide_loop(base.V, base.F, iterations=iterations)
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = cache_file.with_suffix(".tmp.npz")
    np.savez(tmp, V=V, F=F)
    tmp.replace(cache_file)
    return BenchMesh(name, V, F, source)


def load(name: str) -> BenchMesh:
    """Load benchmark mesh ``name`` (a shared mesh's file stem, or a key of ``SUBDIVIDED``)."""
    if name in SUBDIVIDED:
        return _subdivided(name)
    files = shared_files()
    if name not in files:
        raise KeyError(f"unknown mesh {name!r}; known: {sorted(files) + sorted(SUBDIVIDED)}")
    V_raw, F_raw = _read(files[name])
    V, F = weld(V_raw, F_raw)
    return BenchMesh(name, V, F, str(files[name]), V_raw=V_raw, F_raw=F_raw)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", help="meshes to load and describe (default: every shared mesh)")
    for n in ap.parse_args().names or names():
        m = load(n)
        raw = "" if m.V_raw is None else f"  (raw V {len(m.V_raw)})"
        print(f"{n:20s} V {m.n_vertices:8d}  F {m.n_faces:8d}{raw}")
