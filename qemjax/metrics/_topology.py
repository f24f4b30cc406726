"""Topology counts of a triangle mesh: borders, non-manifold elements, components, Euler characteristic, genus."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._common import MeshArrays, as_mesh, in_frame
from ._distance import nearest_faces


def _components(n_nodes: int, i: np.ndarray, j: np.ndarray) -> tuple[int, np.ndarray]:
    graph = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(n_nodes, n_nodes)).tocsr()
    return connected_components(graph, directed=False)


def _vertex_components(mesh: MeshArrays) -> tuple[int, np.ndarray]:
    """Connected components of the referenced vertices (faces that share a vertex are connected).
    Returns the count and (n,) int64 labels, -1 for unreferenced vertices."""
    e = mesh.edges
    _, labels = _components(len(mesh.vertices), e.lo, e.hi)
    used = mesh.referenced
    # Relabel 0..C-1 over referenced vertices only (an isolated vertex is its own scipy component).
    uniq, labels_used = np.unique(labels[used], return_inverse=True)
    out = np.full(len(mesh.vertices), -1, dtype=np.int64)
    out[used] = labels_used
    return len(uniq), out


def _fans_per_vertex(mesh: MeshArrays) -> np.ndarray:
    """(n,) int64: number of edge-connected fans of faces around each vertex (0 when unreferenced).

    Corners (face, vertex) around one vertex are joined across every edge shared by exactly two faces; a vertex
    of a manifold mesh has one fan. Endpoints of non-manifold edges are therefore counted as several fans.
    """
    e = mesh.edges
    f = mesh.faces
    h1, h2 = e.manifold_pairs

    def corner(h, at_start):
        """Corner id (3 * face + k) of half-edge h's start vertex where at_start, else of its end vertex."""
        return np.where(at_start, h, 3 * (h // 3) + (h % 3 + 1) % 3)

    # For each half-edge of a two-face edge, the corner of the edge's lower-index vertex and of its upper one.
    lo_1, hi_1 = corner(h1, e.forward[h1]), corner(h1, ~e.forward[h1])
    lo_2, hi_2 = corner(h2, e.forward[h2]), corner(h2, ~e.forward[h2])
    n_corners = 3 * len(f)
    # a face that repeats a vertex has two corners there, one fan (not a pinch)
    same = np.flatnonzero((f == np.roll(f, -1, axis=1)).ravel())  # corner 3·face + k, whose next is that vertex
    after = 3 * (same // 3) + (same % 3 + 1) % 3
    n_fans, label = _components(n_corners, np.concatenate([lo_1, hi_1, same]), np.concatenate([lo_2, hi_2, after]))
    fan_vertex = np.empty(n_fans, dtype=np.int64)
    fan_vertex[label] = f.ravel()
    return np.bincount(fan_vertex, minlength=len(mesh.vertices))


def _orientable(mesh: MeshArrays) -> bool:
    """Whether the faces can be oriented so that every two-face edge is traversed in opposite directions.

    Each face has two states (kept, flipped); an edge whose faces agree ties equal states, one whose faces
    disagree ties opposite states. The mesh is orientable iff no face's two states end up connected.
    """
    e = mesh.edges
    if e.consistent:
        return True
    m = len(mesh.faces)
    h1, h2 = e.manifold_pairs
    f1, f2 = h1 // 3, h2 // 3
    flip = (e.forward[h1] == e.forward[h2]).astype(np.int64) * m
    i = np.concatenate([f1, f1 + m])
    j = np.concatenate([f2 + flip, f2 + m - flip])
    _, label = _components(2 * m, i, j)
    return bool((label[:m] != label[m:]).all())


def topology_report(mesh, *, original=None, target_faces: int | None = None, fans: bool = True) -> dict:
    """Topology of a triangle mesh, as a flat dict of scalars.

    Args:
      mesh: `trimesh.Trimesh`, ``(vertices, faces)``, or any object with ``.vertices`` (n, 3) and
        ``.faces`` (m, 3). A trimesh (or file) carrying UVs, colours or normals has its vertices split
        where they differ (as trimesh loads them, and as `SimplifyResult.to_trimesh` gives them): its
        topology is measured with exactly coincident vertices joined, as `simplify` welds them, so that a
        seam is no border (the counts below are then of the joined mesh). Other meshes are measured as given.
      original: optional mesh this one was simplified from; adds ``flipped_faces`` and ``flipped_fraction``.
      target_faces: optional face count that was asked for; adds ``target_faces`` and ``target_error``.
      fans: count non-manifold vertices (one graph pass over all corners; skip it on huge meshes when not
        needed, the key is then NaN and genus is computed without that check).

    Returns (counts are ints unless stated):
      vertices: len(vertices) (including unreferenced ones); faces; edges: distinct undirected edges.
      boundary_edges: edges in exactly one face. non_manifold_edges: edges in three or more faces.
      non_manifold_vertices: vertices whose incident faces form more than one fan when joined across two-face
        edges (pinch / "bowtie" vertices, and the endpoints of non-manifold edges).
      components: connected components of faces, two faces being connected when they share a vertex.
      euler: V - E + F, with V the vertices referenced by faces.
      closed: bool, every edge in exactly two faces, and every face on an edge (a face (a, a, a) is a point,
        no surface: a mesh with one is not closed, nor one whose faces are all such). orientable: bool, faces can be oriented consistently.
      genus: int, sum over components of g = (2 - chi_c) / 2, i.e. (2 * components - euler) / 2, defined
        for closed, orientable meshes without non-manifold vertices; NaN (a float) otherwise.
      flipped_faces / flipped_fraction (with ``original``): faces whose normal points against the normal of
        the nearest original face (exact point-to-triangle nearest face of the face centroid; negative dot).
        Zero-area faces are never counted. Fraction of ``faces``.
      target_faces / target_error (with ``target_faces``): target, and faces / target - 1.
    """
    given = as_mesh(mesh)
    m = given.welded  # a trimesh split at its UV (colour, normal) seams: one surface, as simplify reads it
    e = m.edges
    n_components, _ = _vertex_components(m)
    V = int(m.referenced.sum())
    E = len(e.count)
    F = len(m.faces)
    euler = V - E + F
    boundary = int((e.count == 1).sum())
    non_manifold = int((e.count >= 3).sum())
    nm_vertices = int((_fans_per_vertex(m) > 1).sum()) if fans else float("nan")
    closed = e.watertight
    orientable = _orientable(m)
    twice_genus = 2 * int(n_components) - euler
    # an odd count proves a pinched vertex the skipped fans check would have found: no genus either
    genus_defined = closed and orientable and (not fans or nm_vertices == 0) and twice_genus % 2 == 0
    out = {
        "vertices": len(m.vertices),
        "faces": F,
        "edges": E,
        "boundary_edges": boundary,
        "non_manifold_edges": non_manifold,
        "non_manifold_vertices": nm_vertices,
        "components": n_components,
        "euler": euler,
        "closed": closed,
        "orientable": orientable,
        "genus": twice_genus // 2 if genus_defined else float("nan"),  # an int: a count of handles
    }
    if original is not None:
        _, (o, f) = in_frame(as_mesh(original, "original"), given)  # normals' products: lengths to the fourth
        out.update(flipped_faces_report(f, o, nearest_faces(o, face_centroids(f))))
    if target_faces is not None:
        out.update(target_report(F, target_faces))
    return out


def face_centroids(mesh: MeshArrays) -> np.ndarray:
    """(m, 3) float64 face centroids."""
    return mesh.corners.mean(axis=0).T


def flipped_faces_report(mesh: MeshArrays, original: MeshArrays, nearest: np.ndarray) -> dict:
    """flipped_faces / flipped_fraction given, for each face of mesh, its nearest original face (m,) int64."""
    dots = (mesh.cross * np.take(original.cross, nearest, axis=1)).sum(axis=0)
    flipped = int((dots < 0).sum())
    return {"flipped_faces": flipped, "flipped_fraction": flipped / len(mesh.faces)}


def target_report(faces: int, target_faces) -> dict:
    if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)) or target_faces <= 0:
        raise ValueError(f"target_faces must be a positive integer, got {target_faces!r}")
    target = int(target_faces)
    return {"target_faces": target, "target_error": faces / target - 1.0}
