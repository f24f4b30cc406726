"""Appearance attributes (UVs, vertex colours, normals) as per-corner wedges, kept through simplification.

The simplifier's vertices are welded positions; each face corner also names a **wedge**: one distinct
attribute value (uv, colour, normal) at that position. A vertex whose corners name two or more wedges
sits on a **seam** (a UV chart border, a colour discontinuity, a hard normal edge).

Seam rule (as meshoptimizer without its Permissive flag): a contraction (a, b) is allowed when

- both endpoints have a single wedge: the position is the cost model's (optimal placement) and the
  kept wedge's value is interpolated along the segment at the placement's projection; or
- it keeps one endpoint where it is (x = that endpoint's position) and every wedge of the removed
  endpoint maps to exactly one wedge of the kept one through the faces that die (the faces holding both),
  one to one. Then the surviving faces keep their charts and the seam does not move: a vertex on a seam
  slides only along a seam edge into its neighbour on the same seam, a seam junction or seam end never
  moves, and no face comes to span two charts.

Anything else is refused with the reason ``"seam"`` (``stats['rejected_by']``). Pairs with a seam
endpoint are priced at the allowed endpoint with the vertices' quadrics (so they rank by the error of the
position they will really take). All of this runs on the host in compiled loops (`seam_rule`), per pair,
and only for pairs that touch a seam vertex; runs without attributes never build a `Tracker`.
"""
from __future__ import annotations

import dataclasses
import os
import sys
import warnings

import numpy as np


KINDS = ("uv", "color", "normal")
SIZES = {"uv": 2, "color": 4, "normal": 3}


@dataclasses.dataclass
class Attributes:
    """Attributes of a mesh, per wedge: corners (m,3) int64 wedge ids aligned with the faces; wedge_vertex
    (w,) the (welded) vertex of each wedge; values {kind: (w,k) float64} for kinds in KINDS (colours RGBA
    in [0, 1]); material: a trimesh material (with its texture image) or None."""

    corners: np.ndarray
    wedge_vertex: np.ndarray
    values: dict
    material: object = None

    def has_seams(self) -> bool:
        """Whether some vertex has two or more wedges (a seam: a UV chart border, a colour discontinuity,
        a hard normal edge)."""
        return bool(len(self.wedge_vertex)) and int(np.bincount(self.wedge_vertex).max()) > 1

    def matrix(self) -> np.ndarray:
        """(w, Σk) the values side by side, in KINDS order."""
        return np.concatenate([self.values[k] for k in KINDS if k in self.values], 1)

    def split(self, M: np.ndarray) -> dict:
        out, c = {}, 0
        for k in KINDS:
            if k in self.values:
                out[k] = M[:, c:c + SIZES[k]]
                c += SIZES[k]
        return out


def unit_normals(N: np.ndarray, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, int]:
    """Stored normals N (n,3) as unit vectors, and how many had to be recomputed.

    Exporters store normals at any length (MeshLab / VCG write area-weighted sums, lengths 0.05 to 13 on
    one scan), and a normal is a direction: each is divided by its length. Those of zero (or non-finite)
    length are recomputed from the faces, as the area-weighted mean of the face normals at the vertex (V
    (n,3), F (m,3)); a vertex in no face, or whose faces have no area, gets (0, 0, 1)."""
    N = np.asarray(N, np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.sqrt(np.sum(N * N, axis=1))
    bad = ~(np.isfinite(length) & (length > np.finfo(np.float64).tiny))
    out = np.where(bad[:, None], 0.0, N) / np.where(bad, 1.0, length)[:, None]
    if bad.any():
        P = np.asarray(V, np.float64)[F]
        cross = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])  # twice the area, along the normal
        acc = np.zeros((len(N), 3))
        for k in range(3):
            np.add.at(acc, F[:, k], cross)
        acc = acc[bad]
        la = np.linalg.norm(acc, axis=1)
        fallback = np.array([0.0, 0.0, 1.0])
        out[bad] = np.where((la > 0)[:, None], acc / np.where(la > 0, la, 1.0)[:, None], fallback)
    return out, int(np.count_nonzero(bad))


def is_placeholder(material) -> bool:
    """True for the material trimesh invents for UVs that come without one (`empty_material`)."""
    from trimesh.visual.material import SimpleMaterial, empty_material

    try:
        ref = empty_material()
        return (type(material) is SimpleMaterial and not material.kwargs
                and all(np.array_equal(getattr(material, k), getattr(ref, k))
                        for k in ("ambient", "diffuse", "specular"))
                and material.image is not None and material.image.size == ref.image.size
                and np.array_equal(np.asarray(material.image), np.asarray(ref.image)))
    except Exception:  # another trimesh version: call it dropped rather than stay silent
        return False


def from_trimesh(obj, report: dict | None = None) -> tuple[dict, object]:
    """({kind: (n,k) per-vertex values}, material or None) of a `trimesh.Trimesh` (its vertices are split
    where the attributes differ, as trimesh loads them). Normals only when the file stored them, as unit
    vectors (`unit_normals`); ``report``, when given, gets ``normals_recomputed``: how many stored normals
    had zero length and were recomputed from the faces."""
    visual = getattr(obj, "visual", None)
    kind = getattr(visual, "kind", None)
    vals, material = {}, None
    if kind == "texture":
        uv = getattr(visual, "uv", None)
        if uv is not None and len(uv) == len(obj.vertices):
            vals["uv"] = np.asarray(uv, np.float64)
        m = getattr(visual, "material", None)
        if m is not None and not is_placeholder(m):
            material = m
    elif kind == "vertex":
        vals["color"] = np.asarray(visual.vertex_colors, np.float64) / 255.0
    cache = getattr(getattr(obj, "_cache", None), "cache", {})
    vn = cache.get("vertex_normals") if hasattr(cache, "get") else None
    if vn is not None and len(vn) == len(obj.vertices):
        vals["normal"], fixed = unit_normals(vn, obj.vertices, np.asarray(obj.faces, np.int64))
        if report is not None:
            report["normals_recomputed"] = fixed
    return vals, material


# What attributes='auto' keeps (measured: `python experiments/figures/attribute_defaults.py`, README "Appearance
# attributes"): each kind whose values are continuous over the welded mesh. A kind with seams (UV chart
# borders, colour discontinuities, hard normal edges) holds its seam vertices in place, which costs
# geometric rms there: it is kept only when asked for, except UVs whose file names a texture image (or
# given texture=): a texture without its UVs is lost, which weighs more than the time keeping them costs
# (docs/attributes.md, "What is kept").
AUTO_RULE = "kinds without seams, and UVs with a texture image"


def names_texture(material) -> bool:
    """Whether a material (not trimesh's placeholder) carries a texture image: an OBJ's ``map_Kd``, a glTF
    base colour texture."""
    return material is not None and (getattr(material, "image", None) is not None
                                     or getattr(material, "baseColorTexture", None) is not None)
DROPPED_NAME = {"uv": "uv", "color": "vertex_colors", "normal": "normals"}


def _differs_from_first(rep: np.ndarray, vals: np.ndarray) -> np.ndarray:
    """(k,) bool: corners whose values vals (k,c) differ from those of the first corner of their welded
    vertex rep (k,). A vertex has two or more distinct values exactly when one of its corners does."""
    first = np.full(int(rep.max()) + 1 if len(rep) else 0, -1, np.int64)
    first[rep[::-1]] = np.arange(len(rep) - 1, -1, -1)  # the last write of each vertex is its first corner
    return np.any(vals != vals[first[rep]], axis=1)


def seam_vertex_count(values: np.ndarray, F: np.ndarray, F_src: np.ndarray) -> int:
    """How many welded vertices carry two or more different values of one attribute kind: values (n0,k)
    per source vertex, F (m,3) the welded faces, F_src (m,3) the same corners' source vertices."""
    rep = F.reshape(-1)
    differs = _differs_from_first(rep, np.asarray(values, np.float64)[F_src.reshape(-1)])
    return int(np.unique(rep[differs]).size)


def warn_seamed(seamed: dict, others: list, what: str, stacklevel: int):
    """One warning: the kinds in ``seamed`` ({kind: seam vertices}) are not kept by attributes='auto'."""
    also = f"; also not kept: {', '.join(others)}" if others else ""
    warnings.warn(f"{what}: {seamed_left_out(seamed)}{also}", stacklevel=stacklevel + 1)


def seamed_left_out(seamed: dict) -> str:
    """What an in-core run (`warn_seamed`) and a partitioned one (`_partition.run`) say of the kinds in
    ``seamed`` ({kind: seam vertices}) that attributes='auto' does not keep: which, why, and how to keep them."""
    kinds = tuple(seamed)
    arg = repr(kinds[0]) if len(kinds) == 1 else repr(kinds)
    seams = ", ".join(f"{k}: {c} seam vertices" for k, c in seamed.items())
    return (f"{', '.join(kinds)} not kept by default ({seams}): seams hold their vertices in place, which costs "
            f"geometry and time (docs/attributes.md); attributes={arg} (CLI: --attributes {','.join(kinds)}) "
            "keeps them")


def select(available: dict, attributes, unkept: list = ()) -> tuple[dict, list]:
    """The kinds ``attributes`` asks for among those available: 'auto' (all), None / () (none), a kind or
    a tuple of kinds ('uv', 'color', 'normal'). Returns (kept {kind: values}, not kept [kinds]).
    ``unkept``: what the mesh carries that no kind keeps (`_io.mesh.dropped_attributes`), for the error
    when a kind asked for is missing."""
    if attributes == "auto":
        want = set(available)
    elif attributes is None or attributes is False:
        want = set()
    else:
        check_kinds(attributes)
        req = (attributes,) if isinstance(attributes, str) else tuple(attributes)
        missing = [a for a in req if a not in available]
        if missing:
            face = "; its colours are per face, and qemjax keeps colours per vertex" if (
                "color" in missing and "face_colors" in unkept) else ""
            raise ValueError(f"attributes={attributes!r}: the mesh carries no {', '.join(missing)} "
                             f"(it carries {', '.join(available) or 'none'}){face}")
        want = set(req)
    return {k: v for k, v in available.items() if k in want}, [k for k in available if k not in want]


def build(values: dict, rep_of_corner: np.ndarray, corner_src: np.ndarray) -> Attributes:
    """Wedges from per-source-vertex values: corner_src (m,3) source vertex of each corner, rep_of_corner
    (m,3) its welded vertex. Corners with the same welded vertex and equal values share a wedge."""
    M = np.concatenate([values[k] for k in KINDS if k in values], 1)
    src = corner_src.reshape(-1)
    rep = rep_of_corner.reshape(-1).astype(np.int64)
    vals = M[src]
    n = int(rep.max()) + 1 if len(rep) else 0
    if not _differs_from_first(rep, vals).any() and np.bincount(rep, minlength=n).all():
        # no seams and every vertex used: one wedge per vertex, numbered as the vertices (what sorting
        # the (vertex, values) rows would give, without the sort)
        first = np.empty(n, np.int64)
        first[rep[::-1]] = np.arange(len(rep) - 1, -1, -1)
        a = Attributes(rep.reshape(-1, 3), np.arange(n, dtype=np.int64), {k: values[k] for k in values})
        a.values = a.split(vals[first].copy())
        return a
    uniq, inv = _wedge_rows(rep, src, M)
    a = Attributes(inv.reshape(-1, 3).astype(np.int64), uniq[:, 0].astype(np.int64), {k: values[k] for k in values})
    a.values = a.split(uniq[:, 1:].copy())
    return a


def _wedge_rows(rep: np.ndarray, src: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_unique_rows` of the corners' rows [rep, M[src]] (welded vertex, then its source vertex's values),
    the same arrays, bit for bit: the distinct (rep, src) pairs first, by an integer sort (a source vertex
    has one row of values, so a welded vertex sees a few), in the order each first appears among the
    corners, then their rows (fewer than the corners). Among rows that compare equal (0.0 and
    -0.0), the first corner's stays the representative, as the sort of every corner keeps it. Values
    with a NaN take every corner's row (a NaN row is a wedge of its own at each corner)."""
    if len(rep) == 0 or np.isnan(M).any():  # (a NaN row equals nothing, itself neither: every corner)
        return _unique_rows(np.concatenate([rep.reshape(-1, 1).astype(np.float64), M[src]], 1))
    pair = rep * np.int64(max(len(M), 1)) + src
    _, first, pinv = np.unique(pair, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # the pairs in order of first appearance
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    at = first[order]
    uniq, inv = _unique_rows(np.concatenate([rep[at].reshape(-1, 1).astype(np.float64), M[src[at]]], 1))
    return uniq, inv[rank[pinv.reshape(-1)]]


def _unique_rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct rows of key (k,c) in lexicographic order, each row's index among them): what
    ``np.unique(key, axis=0, return_inverse=True)`` gives, by one lexsort (several times faster)."""
    if len(key) == 0:
        return key[:0], np.zeros(0, np.int64)
    order = np.lexsort(key.T[::-1])
    ks = key[order]
    new = np.ones(len(ks), bool)
    new[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    group = np.cumsum(new) - 1
    inv = np.empty(len(key), np.int64)
    inv[order] = group
    return ks[new], inv


# default weights per kind (`python experiments/figures/attribute_defaults.py`, README "Appearance attributes"): for
# colours and normals, the largest weight (with every smaller one) whose runs keep the rule on every seamless
# case: rms and warm time within docs/attributes.md's bounds ("The cost") of attributes=None. Any weight > 0
# costs more time than that (the 23-float attribute state), so both are 0: the cost is the positions' and
# the values are interpolated along each contraction. UVs always come with seams here, so they are kept
# only when asked for; when they are, 0.03 is spot's measured best (the geometric rms of weight 0 with a
# lower UV deviation, lower both than 0.1 or 0.3).
DEFAULT_WEIGHTS = {"uv": 0.03, "color": 0.0, "normal": 0.0}


def check_weights(weights) -> dict:
    """{kind: weight} from ``attribute_weights`` (None: `DEFAULT_WEIGHTS`; a number for every kind; or a
    dict, kinds not named keep their default); ValueError names a bad one."""
    if weights is None:
        weights = {}
    items = weights.items() if isinstance(weights, dict) else [(k, weights) for k in KINDS]
    out = dict(DEFAULT_WEIGHTS)
    for k, w in items:
        if k not in KINDS:
            raise ValueError(f"attribute_weights: unknown kind {k!r}; choose from {KINDS}")
        if isinstance(w, bool) or not isinstance(w, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(w) and w >= 0):
            raise ValueError(f"attribute_weights must be finite numbers >= 0, got {w!r} for {k}")
        out[k] = float(w)
    return out


def channel_weights(attrs: Attributes, kind_weights: dict) -> np.ndarray:
    """(Σk,) the weight of each channel of ``attrs.matrix()``."""
    return np.concatenate([np.full(SIZES[k], kind_weights[k]) for k in KINDS if k in attrs.values])


def check_kinds(attributes) -> None:
    """ValueError unless ``attributes`` is 'auto', None (or False), a kind of `KINDS` or a tuple, list or set
    of them (naming the first that is not one)."""
    if attributes is None or attributes is False or (isinstance(attributes, str) and attributes == "auto"):
        return
    if not isinstance(attributes, (str, tuple, list, set, frozenset)):
        raise ValueError(f"attributes must be 'auto', None, or kinds from {KINDS}; got {attributes!r}")
    bad = [k for k in ((attributes,) if isinstance(attributes, str) else attributes)
           if not isinstance(k, str) or k not in KINDS]
    if bad:
        raise ValueError(f"attributes must be 'auto', None, or kinds from {KINDS}; got {bad[0]!r}")


def is_image(x) -> bool:
    """Whether ``x`` is a PIL image (PIL not imported: it cannot be one, and is not imported to say so)."""
    image = sys.modules.get("PIL.Image")
    return image is not None and isinstance(x, image.Image)


def check_texture(texture) -> None:
    """ValueError unless ``texture`` is None, an image file's path or a PIL image."""
    if texture is None or isinstance(texture, (str, os.PathLike)) or is_image(texture):
        return
    raise ValueError(f"texture= takes an image file's path or a PIL image, got {type(texture).__name__}"
                     + (" (a numpy array: PIL.Image.fromarray(array))" if isinstance(texture, np.ndarray) else ""))


def load_texture(texture):
    """A trimesh SimpleMaterial holding ``texture`` (a path or a PIL image); ValueError naming the file."""
    from PIL import Image
    from trimesh.visual.material import SimpleMaterial

    if isinstance(texture, Image.Image):
        return SimpleMaterial(image=texture)
    check_texture(texture)  # (an array would be printed whole in the error below)
    try:
        img = Image.open(texture)
        img.load()
    except Exception as exc:
        raise ValueError(f"could not read texture {texture}: {exc}") from exc
    return SimpleMaterial(image=img)


def _jit():
    """The compiled seam rule (`seam_rule`), imported on first use: loading a mesh does not need numba."""
    from . import seam_rule

    return seam_rule


class Tracker:
    """The wedges during a run: C (m,3) wedge per corner of each face row, V (w,k) wedge values.

    `constrain` prices pairs touching seams at their allowed endpoint, `allowed` / `refused` is the
    validity rule and `contract` / `contract_many` update the corners (and, between single-wedge vertices,
    the kept wedge's value). The per-pair work runs in compiled loops (`seam_rule`) over the faces' lists
    (`incidence.FaceLists`), with the float64 arithmetic of the rule as written in Python
    (tests/wedges_reference.py)."""

    def __init__(self, corners: np.ndarray, values: np.ndarray, n: int, F: np.ndarray, model=None,
                 solved=None, frozen=None):
        self.C = np.array(corners, np.int64)
        self.val = np.array(values, np.float64)
        # locked vertices (n,) bool: a contraction onto one keeps its wedge's value, as it keeps its position
        self.frozen = np.zeros(n, np.bool_) if frozen is None else np.ascontiguousarray(frozen, np.bool_)
        # the model's cost at a point (attribute quadrics: `_costs.attributes`, m channels; else the
        # quadric error: m = -1), and its optimal attributes for the channels marked in ``solved`` (the
        # rest are interpolated)
        cost_at = getattr(model, "cost_at", None)
        if cost_at is not None and getattr(model, "channels", None) is None:
            raise TypeError(f"{type(model).__name__}: a host cost_at without channels is not supported by "
                            "the seam rule")
        self.m = int(model.channels) if cost_at is not None else -1
        k = self.val.shape[1]
        attrs = solved is not None and getattr(model, "attributes_at", None) is not None
        self.m_solved = self.m if attrs else -1
        self.solved = np.zeros(k, bool) if not attrs else np.asarray(solved, bool)
        self.weights = (np.asarray(model.weights, np.float64) if attrs else np.ones(k))
        # seam candidates: vertices with two or more wedges (a flag that may stay set after faces die,
        # which only sends a pair through the exact per-pair test)
        # each wedge belongs to one vertex: count the wedges in use per vertex (np.unique's values, by count)
        used = np.flatnonzero(np.bincount(self.C.reshape(-1), minlength=len(self.val)))
        vertex_of = np.zeros(len(self.val), np.int64)
        vertex_of[self.C.reshape(-1)] = np.asarray(F).reshape(-1)
        self.multi = np.bincount(vertex_of[used], minlength=n) > 1
        self.seam_in = int(np.count_nonzero(self.multi))  # vertices on a seam in the input
        self.wedge_in = np.zeros(n, np.int64)  # a wedge of each vertex in the input, and the input's seam
        self.wedge_in[vertex_of[used]] = used  # flags (a batch of the greedy queue changes ``multi``)
        self.multi_in = self.multi.copy()

    @staticmethod
    def _lists(faces):
        return faces.F, faces.alive, faces.cnt, faces.off, faces.pool

    # -- per pair -------------------------------------------------------------------------------------
    def _corners(self, faces, v):
        """(live faces at v, their rows, v's corner in each, its wedge there)."""
        f, k, w = (np.empty(int(faces.cnt[v]), np.int64) for _ in range(3))
        j = _jit().corners(*self._lists(faces), self.C, int(v), f, k, w)
        return f[:j], faces.F[f[:j]], k[:j], w[:j]

    def modes(self, faces, a: int, b: int):
        """(free, map b->a or None, map a->b or None): free when both have one wedge; a map when keeping
        that endpoint is allowed (every wedge of the other maps one to one through the shared faces)."""
        J = _jit()
        T, _ = J.scratch(np.array([[a, b]], np.int64), faces.cnt, 0)
        free, nba, nab, _, _ = J.modes(*self._lists(faces), self.C, self.multi, int(a), int(b), T)
        as_map = lambda k, v, n: None if n < 0 else dict(zip(T[k, :n].tolist(), T[v, :n].tolist()))  # noqa: E731
        return bool(free), as_map(J.KBA, J.VBA, nba), as_map(J.KAB, J.VAB, nab)

    def held(self, v: int) -> np.ndarray | None:
        """The values a frozen vertex v holds, as the attribute model weighs them ((k,): each solved channel
        times its weight, 0 for the others), or None when v is on a seam of the input (several wedges; its
        contractions map wedges and change no value). A frozen vertex keeps its wedge and that wedge's
        value, so the answer depends on the input alone, wherever the run is (the same in a batch of the
        greedy queue, whose speculation changes the seam flags, as in its one-at-a-time loop)."""
        if self.multi_in[v]:
            return None
        return self.val[self.wedge_in[v]] * self.weights * self.solved  # a frozen wedge's value never changes

    def allowed(self, faces, VQ, a: int, b: int, x) -> bool:
        """The validity rule for contracting b into a at x (module docstring)."""
        if not (self.multi[a] or self.multi[b]):
            return True
        P = np.array([[a, b]], np.int64)
        X = np.asarray(x, VQ.dtype).reshape(1, 3)
        return not bool(self.refused(faces, VQ, P, X, np.ones(1, bool))[0])

    def refused(self, faces, VQ, P, X, check) -> np.ndarray:
        """(K,) bool: `allowed` is False for pair P[i] (K,2) at X[i] (K,3), tested in order where ``check``
        (K,) is set (the others are not refused)."""
        P = np.asarray(P)
        if len(P) == 0:
            return np.zeros(0, bool)
        return _jit().refused(*self._lists(faces), self.C, self.multi, VQ, P,
                                  np.asarray(X, VQ.dtype).reshape(-1, 3), np.asarray(check, bool))

    def constrain(self, faces, VQ, P: np.ndarray, x: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """For pairs P (K,2) touching a seam vertex: x and cost (updated in place) at the allowed endpoint
        with the smaller quadric error. Returns (K,) bool: pairs with no allowed placement."""
        P = np.asarray(P)
        if len(P) == 0:
            return np.zeros(0, bool)
        return _jit().constrain(*self._lists(faces), self.C, self.multi, VQ, P, x, cost, self.m)

    def constrain_rows(self, faces, VQ, E: np.ndarray, d: np.ndarray, x: np.ndarray, cost: np.ndarray,
                       bad: np.ndarray, code: int) -> None:
        """`constrain` of the pairs E[d], in place: rows d of x and cost, and bad[row] = ``code`` for a pair
        with no allowed placement (a round's newly priced pairs: no gather and scatter of every row d)."""
        if len(d):
            _jit().constrain_rows(*self._lists(faces), self.C, self.multi, VQ, E, np.asarray(d, np.int64), x, cost,
                                  bad, code, self.m)

    def contract(self, faces, VQ, a: int, b: int, x) -> None:
        """Update the corners for contracting b into a at x (before the faces are relinked)."""
        self._contract(faces, VQ, np.array([[a, b]], np.int64), np.asarray(x).reshape(1, 3), one=True)

    def contract_many(self, faces, VQ, P, X) -> None:
        """`contract` for vertex-disjoint pairs P (K,2) at X (K,3) (a round's: 1-rings apart). Pairs of
        single-wedge vertices (most of them: every pair away from seams) first, together, then the others
        one by one."""
        self._contract(faces, VQ, P, X, one=False)

    def _contract(self, faces, VQ, P, X, one: bool) -> None:
        """`contract` (``one``: the single pair P[0]) or `contract_many`."""
        P, X = np.asarray(P), np.asarray(X)
        if len(P) == 0:
            return
        args = (*self._lists(faces), self.C, self.val, self.multi, VQ)
        X64, Xv = np.asarray(X, np.float64), np.asarray(X, VQ.dtype)
        if one:
            ok = _jit().contract(*args, int(P[0, 0]), int(P[0, 1]), X64[0], Xv[0], self.m_solved,
                                 self.solved, self.weights, self.frozen)
            i = -1 if ok else 0
        else:
            i = _jit().contract_many(*args, P, X64, Xv, self.m_solved, self.solved, self.weights, self.frozen)
        if i >= 0:
            raise AssertionError(f"seam rule broken for pair ({int(P[i, 0])}, {int(P[i, 1])})")


def seam_edges(F: np.ndarray, C: np.ndarray) -> np.ndarray:
    """(k,2) the edges of faces F (m,3) whose faces name different wedges (corners C (m,3)) at either
    endpoint: the seams, which `simplify` constrains like boundary edges (feature-edge planes)."""
    u, v = F[:, [0, 1, 2]].reshape(-1), F[:, [1, 2, 0]].reshape(-1)
    wu, wv = C[:, [0, 1, 2]].reshape(-1), C[:, [1, 2, 0]].reshape(-1)
    swap = u > v
    lo, hi = np.where(swap, v, u), np.where(swap, u, v)
    wlo, whi = np.where(swap, wv, wu), np.where(swap, wu, wv)
    # by (lo, hi, wlo, whi) as two int64 keys (the order of a four-key lexsort, at half its passes)
    n, w = int(max(hi.max(initial=0), lo.max(initial=0))) + 1, int(max(whi.max(initial=0), wlo.max(initial=0))) + 1
    ek = lo.astype(np.int64) * n + hi
    order = np.lexsort((wlo.astype(np.int64) * w + whi, ek))
    lo, hi, wlo, whi, ek = lo[order], hi[order], wlo[order], whi[order], ek[order]
    same_edge = ek[1:] == ek[:-1]
    differ = same_edge & ((wlo[1:] != wlo[:-1]) | (whi[1:] != whi[:-1]))
    E = np.stack([lo[1:][differ], hi[1:][differ]], 1)
    if not len(E):
        return np.zeros((0, 2), np.int64)
    first = np.ones(len(E), bool)  # sorted already: np.unique(E, axis=0) keeps each run's first row
    first[1:] = np.any(E[1:] != E[:-1], axis=1)
    return E[first]


def seam_count(E: np.ndarray) -> int:
    """The number of seams: connected pieces of the seam edges E (k,2) (`seam_edges`)."""
    if not len(E):
        return 0
    from .part_labels import labels  # numba: imported when first used

    ids, E = np.unique(E, return_inverse=True)
    E = E.reshape(-1, 2).astype(np.int64)
    return int(labels(E[:, 0], E[:, 1], len(ids))[0])  # (every vertex of the graph is on an edge)


def output(C: np.ndarray, values: np.ndarray, F: np.ndarray, fids: np.ndarray, ids: np.ndarray):
    """Per-output-corner wedges: from the run's corner wedges C (m,3), wedge values (w,k), the output
    faces F (j,3) (indices into the output vertices), the surviving face rows fids and the output
    vertices' run ids. Returns (wedge faces (j,3) int64, wedge vertex (u,) int64, values (u,k))."""
    Cw = C[fids]
    key = F.astype(np.int64).reshape(-1) * (int(Cw.max()) + 1 if Cw.size else 1) + Cw.reshape(-1)
    uniq, inv = np.unique(key, return_inverse=True)
    first = np.zeros(len(uniq), np.int64)
    first[inv.reshape(-1)] = np.arange(inv.size)
    wv = F.reshape(-1)[first].astype(np.int64)
    wid = Cw.reshape(-1)[first]
    return inv.reshape(-1, 3).astype(np.int64), wv, values[wid]


def warn_unsupported(kinds, what: str, stacklevel: int):
    """Warn that ``what`` (e.g. "method='esqem'") drops the attributes ``kinds``."""
    warnings.warn(f"{what} does not keep appearance attributes ({', '.join(kinds)}): the result "
                  "has positions and faces only (method='qem' keeps them)", stacklevel=stacklevel + 1)
