"""Exact nearest-triangle queries for many points: a KD-tree over triangle pieces, and a sparse grid.

Both are exact (the same distances as comparing every point with every triangle, up to float64 rounding);
they differ in cost, and `nearest_triangles` picks one.

KD-tree (`TriangleIndex`). Every triangle is cut into n^2 congruent pieces (regular subdivision; n = 1 for
most triangles) so that each piece lies in a ball of radius <= R around its centroid; a cKDTree holds the
centroids. For a point p, the face of the nearest centroid gives an upper bound U on the distance, and any
face closer than U has a piece centroid within U + R of p. So the k nearest centroids are enough when the
k-th lies at least U + R away; otherwise a ball query of radius U + R lists every candidate. Candidates
whose lower bound |p - centroid| - radius is not below U are skipped before the exact test. Splitting the
few large triangles keeps R close to the typical piece size (otherwise one huge face would widen every ball).
A thin triangle is cut into strips across its longest side instead (`_Strips`: pieces are balls around
rectangles that cover the face, not sub-triangles), where that takes fewer pieces: a sliver of length L
needs about L / 2R strips but (L / 2R)^2 sub-triangles, so within the same piece budget a mesh of long
thin triangles (a finely subdivided capsule) keeps R near its faces' width instead of their length. That
is done only when it at least halves the widest piece (`STRIP_GAIN`); other meshes keep the regular
subdivision, and with it the same index and the same answers as without strips.

Grid (`GridIndex`), for many points near a coarser mesh. A cell (a cube of side h, about 2/5 of the median
edge) lists every face that a point of the cube can lie within delta of: the faces whose box and plane,
grown by delta, meet the cube and that lie within delta + (half the cube's diagonal) of its centre. The
cells of a face are enumerated column by column along the axis nearest its normal, each column cut to the
slab around the plane, so the work follows the listed pairs rather than the face's whole box. A point is
compared with the faces listed in its own cell only: a handful, and no tree walk. If the best distance
found is <= delta it is exact (every face within delta of the point is listed), and the face returned is
the largest index among the nearest (so it does not depend on the lists' order). Other points go to the
KD-tree. delta is the 99th percentile of the exact distances of a small pilot sample, which the grid
measures itself (`nearest_triangles`).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from . import threads
from .pointtri import edge_products, flat_triangles, squared_distance_cf

_BLOCK = 32_768  # point-triangle pairs per kernel call (temporaries stay in cache)
_CHUNK = 65_536  # query points per block (bounds temporary memory)
_K_NEAREST = 16  # centroids asked of the KD-tree per point before falling back to a ball query
_BALL_BATCH = 4_000_000  # candidates per ball-query batch (bounds memory)
_MIN_THREAD_POINTS = 16_384  # points per thread below which a grid query stays on one thread
_THREADED_QUERY = 16_384  # points from which a KD-tree query uses every core
_LEAFSIZE = 16  # KD-tree leaf size (bigger builds faster, queries a little slower)
_SLACK = 1e-9  # relative padding of every exactness bound against rounding
_PIECES_PER_FACE = 1.5  # KD-tree piece budget: <= this * faces + _MIN_PIECES
_MIN_PIECES = 16_384
_GRID_BUDGET = 4_000_000  # (triangle, cell) pairs enumerated while filling the grid
_GRID_PILOT = 2_048  # points measured exactly first to choose the grid's margin delta
_GRID_QUANTILE = 0.99  # fraction of pilot points the margin covers
_PILOT_PIECES = 8  # nearest pieces whose faces bound a pilot point's distance (a grid margin near delta)
_GRID_MAX_LIST = 32  # mean faces per cell above which the grid is not used
_GRID_CELLS_PER_EDGE = 2.5  # grid cell size: the median edge length over this (or delta / 2 if larger)
_DENSE_PER_PAIR = 8  # grid cells per listed (face, cell) pair up to which lookups use a dense table
_CELL_PAD = 1e-6  # cells (fraction of a cell) added to each side of a computed range against rounding
STRIP_GAIN = 0.5  # thin faces are cut into strips only when that makes the widest piece this much narrower


class Triangles:
    """A mesh's faces as the kernel wants them: corners (3 corners, 3 axes, m) float64 component-first; per
    face, computed once: a (3, m) the first corners, ab, ac (3, m) the edge vectors, products (3, m) their
    dot products (`edge_products`) and flat (m,) bool (too thin for the barycentric solve: measured as three
    segments)."""

    def __init__(self, corners: np.ndarray):
        self.corners = corners
        self.a = corners[0]  # (3, m), contiguous
        self.ab = corners[1] - corners[0]
        self.ac = corners[2] - corners[0]
        self.products = edge_products(self.ab, self.ac)
        self.flat = flat_triangles(self.ab, self.ac)

    def __len__(self) -> int:
        return self.corners.shape[2]

    def sq_dist(self, points_cf: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Squared distances (n,) from points (3, n) to faces (n,) int64, pair by pair."""
        out = np.empty(len(faces))
        for s in range(0, len(faces), _BLOCK):
            f = faces[s : s + _BLOCK]
            out[s : s + _BLOCK] = squared_distance_cf(
                points_cf[:, s : s + _BLOCK],
                np.take(self.a, f, axis=1),
                np.take(self.ab, f, axis=1),
                np.take(self.ac, f, axis=1),
                np.take(self.flat, f),
                np.take(self.products, f, axis=1),
            )
        return out


def _morton_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Order points along a Z-curve so that consecutive queries touch nearby tree nodes (cache locality)."""
    lo = points.min(axis=0)
    extent = float((points.max(axis=0) - lo).max())
    q = ((points - lo) * ((2**bits - 1) / extent if extent > 0 else 0.0)).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def _ragged_arange(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For counts (n,) int64 return owner and local, each (counts.sum(),): local runs 0..counts[i]-1 for
    owner i."""
    owner = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, local


def _segment_argmin(d2: np.ndarray, faces: np.ndarray, counts: np.ndarray):
    """Per segment of consecutive pairs (lengths counts > 0): the minimum of d2 and a face attaining it."""
    seg = np.cumsum(counts) - counts
    best = np.minimum.reduceat(d2, seg)
    owner = np.repeat(np.arange(len(counts)), counts)
    at = np.maximum.reduceat(np.where(d2 <= best[owner], np.arange(len(d2)), -1), seg)
    return best, faces[at]


def _pieces(tris: Triangles, radius: np.ndarray, levels: np.ndarray):
    """Centroids (P, 3), radii (P,) and parent faces (P,) of the regular subdivision of each face f into
    levels[f]^2 pieces (none for a face whose level is 0: it is cut into `_Strips`)."""
    c = tris.corners
    cents, radii, parents = [np.zeros((0, 3))], [np.zeros(0)], [np.zeros(0, np.int64)]
    for n in np.unique(levels[levels > 0]):  # a handful of distinct levels, not a loop over faces
        faces = np.flatnonzero(levels == n)
        a = np.take(c[0], faces, axis=1).T  # (k, 3)
        ab = np.take(c[1], faces, axis=1).T - a
        ac = np.take(c[2], faces, axis=1).T - a
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        up = i + j <= n - 1
        down = i + j <= n - 2
        # Barycentric (u, v) of the piece centroids: upward piece (i, j) -> ((3i+1)/3n, (3j+1)/3n),
        # downward piece -> ((3i+2)/3n, (3j+2)/3n).
        u = np.concatenate([3 * i[up] + 1, 3 * i[down] + 2]) / (3.0 * n)
        v = np.concatenate([3 * j[up] + 1, 3 * j[down] + 2]) / (3.0 * n)
        cent = a[:, None, :] + u[None, :, None] * ab[:, None, :] + v[None, :, None] * ac[:, None, :]
        cents.append(cent.reshape(-1, 3))
        # Each piece is the face scaled by 1/n (downward ones also point-reflected about their centroid), so
        # its centroid-to-corner radius is the face's divided by n.
        radii.append(np.repeat(radius[faces] / n, len(u)))
        parents.append(np.repeat(faces, len(u)))
    return np.concatenate(cents), np.concatenate(radii), np.concatenate(parents)


class _Strips:
    """Thin faces cut across their longest side: a face with longest side AB (length L) and height h above
    it lies in the rectangle [0, L] x [0, h] of its plane (AB longest: the apex projects onto AB), so k cuts
    across AB give k strips, each inside a ball of radius ½·sqrt((L/k)² + h²) around its rectangle's
    centre. For a sliver (h small beside L) that is about L / 2R pieces of radius R where the regular
    subdivision needs (L / 2R)²; there, the pieces had to stay wide to fit the budget, and every query's
    ball (its radius grows with the widest piece) then held many faces' pieces as candidates."""

    def __init__(self, corners: np.ndarray):
        sides = np.stack([_sq_norm(corners[(j + 1) % 3] - corners[j]) for j in range(3)])  # (3, m)
        self.j = np.argmax(sides, axis=0)  # the longest side runs from corner j to corner j + 1
        cols = np.arange(corners.shape[2])
        self.a = corners[self.j, :, cols].T  # (3, m)
        self.ab = corners[(self.j + 1) % 3, :, cols].T - self.a
        self.length = np.sqrt(_sq_norm(self.ab))
        ac = corners[(self.j + 2) % 3, :, cols].T - self.a
        along = np.divide(_dot3(ac, self.ab), self.length**2, out=np.zeros_like(self.length), where=self.length > 0)
        self.up = ac - along * self.ab  # from the apex's foot on AB to the apex: the height vector
        self.height = np.sqrt(_sq_norm(self.up))

    def count(self, target: float) -> np.ndarray:
        """(m,) float64 strips per face for pieces of radius at most ``target`` (inf where the face is too
        wide for strips of that radius)."""
        room = 4.0 * target * target - self.height**2
        with np.errstate(divide="ignore"):
            k = np.ceil(self.length / np.sqrt(np.maximum(room, 0.0)))
        return np.where(room > 2.0 * target * target, np.maximum(k, 1.0), np.inf)

    def radius(self, k: np.ndarray) -> np.ndarray:
        """(m,) the radius of each face's strips when it is cut into k (m,) of them."""
        with np.errstate(invalid="ignore"):
            return 0.5 * np.sqrt((self.length / k) ** 2 + self.height**2)

    def pieces(self, faces: np.ndarray, k: np.ndarray):
        """Centres (P, 3), radii (P,) and parent faces (P,) of faces (f,) cut into k (f,) strips each."""
        owner, local = _ragged_arange(k)
        f = faces[owner]
        t = (local + 0.5) / k[owner]
        cents = (np.take(self.a, f, axis=1) + t * np.take(self.ab, f, axis=1) + 0.5 * np.take(self.up, f, axis=1)).T
        radii = 0.5 * np.sqrt((self.length[f] / k[owner]) ** 2 + self.height[f] ** 2)  # as `radius`
        return cents, radii, f


def _thin_split(strip: _Strips, radius: np.ndarray, budget: float, target: float):
    """The pieces when thin faces may be cut into strips: (levels (m,), strips (m,), which faces are cut
    (m,) bool, the widest piece's radius), for the smallest radius (from ``target`` in steps of 1.25) whose
    pieces fit the budget; None when no face is cut then."""

    def split(target):
        levels = np.maximum(np.ceil(radius / target), 1).astype(np.int64)
        strips = strip.count(target)
        cut = strips < levels**2  # thin faces: fewer pieces as strips than as a regular subdivision
        return levels, strips, cut, float(np.where(cut, strips, levels.astype(np.float64) ** 2).sum())

    while True:
        levels, strips, cut, total = split(target)
        if total <= budget:
            break
        target *= 1.25
    # with faces cut into strips the count no longer follows sum (r / R)^2, and the first guess may leave
    # most of the budget unspent: shrink the radius while the pieces still fit
    while cut.any():
        smaller = split(target / 1.25)
        if smaller[3] > budget:
            break
        target /= 1.25
        levels, strips, cut, _ = smaller
    if not cut.any():
        return None
    widest = max(float((radius / levels)[~cut].max(initial=0.0)), float(strip.radius(strips)[cut].max()))
    return levels, strips, cut, widest


class TriangleIndex:
    """Exact closest-face search over one mesh with a KD-tree of face pieces (see the module notes).

    Args:
      tris: the mesh's `Triangles`.
    """

    def __init__(self, tris: Triangles):
        self.tris = tris
        corners = tris.corners
        centroid = corners.mean(axis=0)  # (3, m)
        radius = np.sqrt(np.max([((corners[k] - centroid) ** 2).sum(axis=0) for k in range(3)], axis=0))
        strip = _Strips(corners)
        m = len(tris)
        budget = _PIECES_PER_FACE * m + _MIN_PIECES
        # Piece radius about as small as the budget allows (count ~ m + sum (r / R)^2), grown until it fits.
        first = float(np.sqrt((radius**2).sum() / max(budget - m, 1.0))) or 1.0
        target = first
        while True:
            levels = np.maximum(np.ceil(radius / target), 1).astype(np.int64)
            if float((levels.astype(np.float64) ** 2).sum()) <= budget:
                break
            target *= 1.25
        cut, strips = np.zeros(m, bool), None
        thin = _thin_split(strip, radius, budget, first)
        # Strips only where they at least halve the widest piece (a mesh of long thin triangles): on meshes of
        # ordinary triangles they narrow it a little, too little to pay for a different index, which would
        # change which of two equally near faces a query reports (`attribute_deviation` reads it).
        if thin is not None and thin[3] <= STRIP_GAIN * float((radius / levels).max()):
            levels, strips, cut = thin[:3]
        cents, radii, parents = _pieces(tris, radius, np.where(cut, 0, levels))
        if cut.any():
            c, r, f = strip.pieces(np.flatnonzero(cut), strips[cut].astype(np.int64))
            cents, radii, parents = np.concatenate([cents, c]), np.concatenate([radii, r]), np.concatenate([parents, f])
        self.centroid = cents
        self.piece_radius = radii * (1 + _SLACK)
        self.max_radius = float(self.piece_radius.max())
        self.parent = parents
        self.tree = cKDTree(cents, leafsize=_LEAFSIZE, balanced_tree=False, compact_nodes=False)

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact distance from each point to the mesh, and a nearest face.

        Args:
          points: (q, 3) float64.
        Returns:
          dist (q,) float64 in mesh units and face (q,) int64 (when several faces tie, any one of them).
        """
        points = np.asarray(points, dtype=np.float64)
        dist = np.empty(len(points))
        face = np.empty(len(points), dtype=np.int64)
        if len(points) == 0:
            return dist, face
        order = _morton_order(points)
        for s in range(0, len(points), _CHUNK):
            idx = order[s : s + _CHUNK]
            dist[idx], face[idx] = self._query_block(points[idx])
        return dist, face

    def _query_block(self, points: np.ndarray):
        pts_cf = np.ascontiguousarray(points.T)
        k = min(_K_NEAREST, len(self.parent))
        cd, ci = self.tree.query(points, k=k, workers=_workers(len(points)))
        cd, ci = cd.reshape(len(points), k), ci.reshape(len(points), k)
        parent = self.parent[ci]
        best2 = self.tris.sq_dist(pts_cf, parent[:, 0])
        best_face = parent[:, 0].copy()
        # Candidates whose bounding ball could beat the nearest centroid's face.
        lower = cd[:, 1:] - self.piece_radius[ci[:, 1:]]
        rows, cols = np.nonzero((lower * np.abs(lower) < best2[:, None]) & (parent[:, 1:] != parent[:, :1]))
        self._improve(pts_cf, rows, parent[rows, cols + 1], best2, best_face)
        # Exact where the k-th centroid lies beyond best + R; elsewhere a ball query finds every candidate.
        ub = np.sqrt(best2)
        redo = np.flatnonzero(cd[:, -1] < (ub + self.max_radius) * (1 + _SLACK)) if k < len(self.parent) else []
        if len(redo):
            radius = (ub[redo] + self.max_radius) * (1 + _SLACK)
            # Batches of bounded size: points far from the mesh can have very many candidates.
            sizes = self.tree.query_ball_point(points[redo], radius, workers=_workers(len(redo)), return_length=True)
            batch = np.cumsum(sizes) // _BALL_BATCH
            for b in np.unique(batch):
                sel = batch == b
                self._ball(points, pts_cf, redo[sel], radius[sel], ub, best2, best_face)
        return np.sqrt(best2), best_face

    def _ball(self, points, pts_cf, rows, radius, ub, best2, best_face):
        """Exact answers for points[rows] (sorted): every piece within radius (>= ub + R) is a candidate."""
        lists = self.tree.query_ball_point(points[rows], radius, workers=_workers(len(rows)), return_sorted=False)
        counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        piece = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=int(counts.sum()))
        rows = np.repeat(rows, counts)
        gap = self.centroid[piece] - points[rows]
        lower = np.sqrt(np.einsum("ij,ij->i", gap, gap)) - self.piece_radius[piece]
        keep = lower < ub[rows]
        self._improve(pts_cf, rows[keep], self.parent[piece[keep]], best2, best_face)

    def _improve(self, pts_cf, rows, faces, best2, best_face):
        """Lower best2 / best_face in place with the exact distances of the (rows, faces) pairs; rows sorted."""
        if len(rows) == 0:
            return
        d2 = self.tris.sq_dist(np.take(pts_cf, rows, axis=1), faces)
        counts = np.bincount(rows, minlength=len(best2))
        has = np.flatnonzero(counts)
        seg_best, seg_face = _segment_argmin(d2, faces, counts[has])
        better = seg_best < best2[has]
        best2[has[better]] = seg_best[better]
        best_face[has[better]] = seg_face[better]


class GridIndex:
    """Exact closest-triangle search for many points near a (coarser) mesh: a sparse uniform grid.

    See the module notes. Points the grid cannot settle (best > delta, or an empty cell) go to `fallback`.

    Args:
      tris: the mesh's `Triangles`.
      delta: margin (mesh units) within which the grid's answer is exact.
      fallback: a `TriangleIndex` over the same mesh.
    """

    def __init__(self, tris: Triangles, delta: float, fallback: TriangleIndex):
        self.tris = tris
        self.fallback = fallback
        self.delta = delta
        corners = tris.corners
        lo_t = corners.min(axis=0)  # (3, m)
        hi_t = corners.max(axis=0)
        edge = np.sqrt(_sq_norm(corners[1] - corners[0]))
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0], axis=0)
        length = np.sqrt(_sq_norm(normal))
        normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
        flat = tris.flat | ~(length > 0)  # no reliable normal: every cell of the box, exact test only
        h = max(float(np.median(edge)) / _GRID_CELLS_PER_EDGE, delta / 2.0, 1e-300)
        margin = delta * (1 + _SLACK)
        while True:
            reach = delta + h * np.sqrt(3.0) / 2.0
            origin = lo_t.min(axis=1) - reach - h
            dims = np.floor((hi_t.max(axis=1) + reach - origin) / h).astype(np.int64) + 2
            # A cell lists a face when some point of the cell (a cube) can lie within delta of it. Three
            # necessary conditions select the cells: the cube meets the face's box grown by delta (here), it
            # meets the face's plane grown by delta (`_slab_cells`), and its centre lies within
            # delta + (half the cube's diagonal) of the face (below).
            c0 = np.floor((lo_t - margin - origin[:, None]) / h - _CELL_PAD).astype(np.int64)
            c1 = np.floor((hi_t + margin - origin[:, None]) / h + _CELL_PAD).astype(np.int64)
            span = c1 - c0 + 1  # (3, m) cells per axis
            if (span.prod(axis=0).sum() <= max(_GRID_BUDGET, 8 * len(tris))
                    and float(np.prod(dims.astype(float))) < 2.0**62):
                break
            h *= 1.25
        self.h, self.origin, self.dims = h, origin, dims
        limit = reach * (1 + _SLACK)
        # Half-thickness of the slab of centres whose cube meets the plane grown by delta.
        slab = (0.5 * h * np.abs(normal).sum(axis=0) + delta) * (1 + _SLACK)
        owner, cell = self._slab_cells(tris, normal, flat, c0, span, slab)
        # Keep the cells whose centre is within the limit of the face (exact distance).
        keep = tris.sq_dist(origin[:, None] + (cell + 0.5) * h, owner) <= limit * limit
        key = self._key(cell[:, keep])
        owner = owner[keep]
        order = np.argsort(key)  # any order of the faces within a cell (the query breaks ties by index)
        key = key[order]
        self.cell_face = owner[order]
        first = np.ones(len(key), dtype=bool)
        first[1:] = key[1:] != key[:-1]
        self.cell_key = key[first]
        self.cell_start = np.flatnonzero(first)
        self.cell_count = np.diff(np.append(self.cell_start, len(key)))
        # A dense table from key to listed cell when it is small beside the lists (a lookup instead of a
        # binary search per point).
        self.table = None
        if float(np.prod(dims.astype(float))) <= _DENSE_PER_PAIR * len(key):
            self.table = np.full(int(np.prod(dims)), -1, dtype=np.int64)
            self.table[self.cell_key] = np.arange(len(self.cell_key))

    def _slab_cells(self, tris, normal, flat, c0, span, slab):
        """Candidate (face, cell) pairs: for each face, the columns of its box of cells along the axis its
        normal is closest to, each cut to the cells whose centre lies within slab (m,) of the face's plane
        (all of the column for a flat face). Returns owner (n,) int64 and cell (3, n) int64."""
        h, origin = self.h, self.origin
        axis = np.argmax(np.abs(normal), axis=0)  # (m,) column axis of each face
        owners, cells = [], []
        for k in range(3):  # the faces of each column axis together: axes are then plain rows
            i, j = (k + 1) % 3, (k + 2) % 3
            faces = np.flatnonzero(axis == k)
            si, sj, sk = span[i, faces], span[j, faces], span[k, faces]
            col, local = _ragged_arange(si * sj)
            ci = c0[i, faces][col] + local // sj[col]
            cj = c0[j, faces][col] + local % sj[col]
            f = faces[col]
            # The plane's k-coordinate above each column's centre, and the slab's half-height along k.
            a, n = np.take(tris.a, f, axis=1), np.take(normal, f, axis=1)
            is_flat = flat[f]
            nk = np.where(is_flat, 1.0, n[k])
            zk = a[k] - (n[i] * (origin[i] + (ci + 0.5) * h - a[i]) + n[j] * (origin[j] + (cj + 0.5) * h - a[j])) / nk
            half = slab[f] / np.abs(nk)
            k0 = c0[k, f]
            k1 = k0 + sk[col] - 1
            lo = np.ceil((zk - half - origin[k]) / h - 0.5 - _CELL_PAD)
            hi = np.floor((zk + half - origin[k]) / h - 0.5 + _CELL_PAD)
            lo = np.where(is_flat, k0, np.clip(lo, k0, k1 + 1)).astype(np.int64)
            hi = np.where(is_flat, k1, np.clip(hi, k0 - 1, k1)).astype(np.int64)
            c, local = _ragged_arange(np.maximum(hi - lo + 1, 0))
            cell = np.empty((3, len(c)), dtype=np.int64)
            cell[i], cell[j], cell[k] = ci[c], cj[c], lo[c] + local
            owners.append(f[c])
            cells.append(cell)
        return np.concatenate(owners), np.concatenate(cells, axis=1)

    def _key(self, cell: np.ndarray) -> np.ndarray:
        return (cell[0] * self.dims[1] + cell[1]) * self.dims[2] + cell[2]

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Same contract as `TriangleIndex.query`."""
        points = np.asarray(points, dtype=np.float64)
        return self.finish(points, *self.settle(points), self.delta)

    def settle(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grid's answers alone: dist (q,), exact where it is <= delta (else an upper bound, or inf when
        the point's cell lists no face), and face (q,): the largest index among the nearest faces listed."""
        dist = np.full(len(points), np.inf)
        face = np.zeros(len(points), dtype=np.int64)
        # Each point on its own (no order needed), blocks on threads (numpy releases the GIL in its loops).
        n_blocks = max(-(-len(points) // _CHUNK), min(threads.count(), len(points) // _MIN_THREAD_POINTS), 1)
        bounds = np.linspace(0, len(points), n_blocks + 1).astype(np.int64)

        def block(i):
            a, b = bounds[i], bounds[i + 1]
            dist[a:b], face[a:b] = self._query_block(points[a:b])

        threads.each(block, range(n_blocks))
        return dist, face

    def finish(self, points, dist, face, within: float):
        """`settle`'s answers kept where dist <= within (<= delta), the fallback's elsewhere (in place)."""
        redo = np.flatnonzero(~(dist <= within))
        if redo.size:
            dist[redo], face[redo] = self.fallback.query(points[redo])
        return dist, face

    def _query_block(self, points: np.ndarray):
        dist = np.full(len(points), np.inf)
        face = np.zeros(len(points), dtype=np.int64)
        cell = np.floor((points - self.origin) / self.h).astype(np.int64).T
        inside = ((cell >= 0) & (cell < self.dims[:, None])).all(axis=0)
        if self.table is not None:
            pos = np.where(inside, self.table[np.where(inside, self._key(cell), 0)], -1)
            count = np.where(pos >= 0, self.cell_count[pos], 0)
        else:
            key = np.where(inside, self._key(cell), -1)
            pos = np.minimum(np.searchsorted(self.cell_key, key), len(self.cell_key) - 1)
            count = np.where(self.cell_key[pos] == key, self.cell_count[pos], 0)
        has = np.flatnonzero(count)
        if has.size == 0:
            return dist, face
        count = count[has]
        owner, local = _ragged_arange(count)
        cand = self.cell_face[self.cell_start[pos[has]][owner] + local]
        d2 = self.tris.sq_dist(np.take(np.ascontiguousarray(points[has].T), owner, axis=1), cand)
        seg = np.cumsum(count) - count
        best = np.minimum.reduceat(d2, seg)
        best_face = np.maximum.reduceat(np.where(d2 <= best[owner], cand, -1), seg)  # ties: largest index
        dist[has] = np.sqrt(best)
        face[has] = best_face
        return dist, face


def _workers(n: int) -> int:
    """Threads for a KD-tree query of n points: one for a small query (starting threads costs more)."""
    return -1 if n >= _THREADED_QUERY else 1


def _dot3(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


def _sq_norm(x: np.ndarray) -> np.ndarray:
    return _dot3(x, x)


def nearest_triangles(corners: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact distance from each point to a triangle mesh, and the index of a nearest triangle.

    Args:
      corners: (3, 3, m) float64 triangle corners, component-first (`MeshArrays.corners`).
      points: (q, 3) float64.
    Returns:
      dist (q,) float64 in mesh units, face (q,) int64.

    Uses the grid when the points far outnumber the triangles (dense points on a coarser mesh: a few
    candidates per point and no tree walk), else the KD-tree. Both are exact.
    """
    points = np.asarray(points, dtype=np.float64)
    tris = Triangles(corners)
    tree = TriangleIndex(tris)
    if len(points) < 8 * len(tris) or len(points) < 8 * _GRID_PILOT:
        return tree.query(points)
    pilot = np.random.default_rng(0).choice(len(points), _GRID_PILOT, replace=False)
    # A tiny floor keeps points lying on the surface (distance ~1e-17 from rounding) on the grid's side.
    floor = 1e-9 * float(np.sqrt(_sq_norm(corners[1] - corners[0])).max())
    # The grid's margin delta is the _GRID_QUANTILE quantile of the pilot points' exact distances. The grid
    # measures them itself: built with a margin no smaller than the largest order statistic the quantile
    # reads (bounded above by the distances of the pilot points to the faces of their nearest pieces), it
    # settles those order statistics exactly.
    k = min(_PILOT_PIECES, len(tree.parent))
    _, piece = tree.tree.query(points[pilot], k=k, workers=1)
    pts = np.ascontiguousarray(np.repeat(points[pilot], k, axis=0).T)
    bound = np.sqrt(tris.sq_dist(pts, tree.parent[piece.reshape(-1)]).reshape(-1, k).min(axis=1))
    need = int(np.ceil((_GRID_PILOT - 1) * _GRID_QUANTILE))
    grid = GridIndex(tris, max(float(np.partition(bound, need)[need]), floor), tree)
    if len(grid.cell_face) > _GRID_MAX_LIST * len(grid.cell_key):
        return tree.query(points)  # points far from the mesh: lists too long for the grid to pay off
    dist, face = grid.settle(points)
    pilot_dist = np.where(dist[pilot] <= grid.delta, dist[pilot], np.inf)
    delta = max(float(np.quantile(pilot_dist, _GRID_QUANTILE)), floor)
    return grid.finish(points, dist, face, delta)
