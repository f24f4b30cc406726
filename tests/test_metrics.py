"""Tests of qemjax.metrics: exactness against brute force, known values on hand-made meshes, input checks."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from qemjax import metrics
from qemjax._mesh import nearest as _nearest
from qemjax.metrics import _distance

SHARED_MESHES = Path(__file__).resolve().parents[1].parent / "shared" / "meshes"


# ---------------------------------------------------------------------------------------------- helpers


def reference_distance(p, a, b, c):
    """Point-triangle distance by enumeration, in extended precision: the unconstrained minimiser over the
    plane when it falls inside the triangle, else the best of the three clamped edge projections."""
    p, a, b, c = (np.asarray(x, dtype=np.longdouble) for x in (p, a, b, c))
    best = np.full(np.broadcast_shapes(p.shape, a.shape)[:-1], np.inf, dtype=np.longdouble)
    for o, e in ((a, b - a), (a, c - a), (b, c - b)):
        ee = (e * e).sum(-1)
        t = np.clip(((p - o) * e).sum(-1) / np.where(ee > 0, ee, 1), 0, 1)
        r = p - o - t[..., None] * e
        best = np.minimum(best, (r * r).sum(-1))
    ab, ac, ap = b - a, c - a, p - a
    g11, g12, g22 = (ab * ab).sum(-1), (ab * ac).sum(-1), (ac * ac).sum(-1)
    r1, r2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    det = g11 * g22 - g12 * g12
    ok = det > 1e-30 * g11 * g22
    det = np.where(ok, det, 1)
    s, t = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    ok &= (s >= 0) & (t >= 0) & (s + t <= 1)
    r = ap - s[..., None] * ab - t[..., None] * ac
    best = np.where(ok, np.minimum(best, (r * r).sum(-1)), best)
    return np.sqrt(best).astype(np.float64)


def brute_force(points, vertices, faces):
    """Distance from every point to every face, minimum per point: (q,). In blocks of 256 points, whose
    temporaries stay in the caches (2048 took four times as long, with the same values)."""
    tri = vertices[faces]
    out = np.empty(len(points))
    for s in range(0, len(points), 256):
        d = metrics.point_triangle_distance(points[s : s + 256, None], tri[None, :, 0], tri[None, :, 1],
                                            tri[None, :, 2])
        out[s : s + 256] = d.min(axis=1)
    return out


def sphere(subdivisions=2, radius=1.0, center=(0, 0, 0)):
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + np.asarray(center, dtype=float), np.asarray(m.faces, dtype=np.int64)


def grid(nx, ny, size=1.0):
    """An open nx-by-ny grid of squares in z = 0, each split into two triangles."""
    x, y = np.meshgrid(np.linspace(0, size, nx + 1), np.linspace(0, size, ny + 1), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 2), a + 1
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def scalar_row(row):
    return {k: v for k, v in row.items() if k != "time_s"}


def same(x, y):
    return x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))


# ------------------------------------------------------------------------------ point-triangle distance


def random_triangles(rng, n):
    a, b, c = rng.normal(size=(3, n, 3))
    k = n // 4
    # Slivers and needles of width 1e-12 .. 1e-1 relative, exactly collinear, repeated corners.
    width = 10.0 ** rng.uniform(-12, -1, size=k)
    c[:k] = a[:k] + rng.uniform(-0.5, 1.5, (k, 1)) * (b[:k] - a[:k]) + width[:, None] * rng.normal(size=(k, 3))
    c[k : k + 200] = a[k : k + 200] + 0.3 * (b[k : k + 200] - a[k : k + 200])
    b[k + 200 : k + 400] = a[k + 200 : k + 400]
    c[k + 200 : k + 300] = a[k + 200 : k + 300]
    return a, b, c


def test_point_triangle_distance_matches_reference():
    rng = np.random.default_rng(0)
    n = 20_000
    a, b, c = random_triangles(rng, n)
    p = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-2, 1, size=(n, 1))
    # Half the points close to their triangle, at distances down to 1e-9.
    near = slice(n // 2, n)
    w = rng.dirichlet([1, 1, 1], size=n // 2)
    p[near] = w[:, :1] * a[near] + w[:, 1:2] * b[near] + w[:, 2:] * c[near]
    p[near] += 10.0 ** rng.uniform(-9, 0, size=(n // 2, 1)) * rng.normal(size=(n // 2, 3))
    got = metrics.point_triangle_distance(p, a, b, c)
    want = reference_distance(p, a, b, c)
    scale = np.abs(np.stack([p, a, b, c])).max(axis=(0, 2))
    # float64 inputs carry ~1e-16 * scale of noise: relative 1e-6 above that floor.
    np.testing.assert_array_less(np.abs(got - want), 1e-6 * want + 1e-13 * scale)
    np.testing.assert_allclose(metrics.point_triangle_distance(p, a, b, c, squared=True), got**2, rtol=1e-12)


@pytest.mark.parametrize("power", [-600, -530, 530, 600])
def test_point_triangle_distance_at_extreme_scales_is_that_at_scale_one(power):
    """At 2^±530 (about 1e±160) the squared lengths inside overflowed to inf (distances came back NaN) or
    underflowed (0 for 1e-200): measured where the largest coordinate is about 1, as the metrics measure, each
    distance is that at scale one times the scale, bit for bit."""
    rng = np.random.default_rng(2)
    a, b, c = random_triangles(rng, 2000)
    p = rng.normal(size=(2000, 3)) * 2
    want = metrics.point_triangle_distance(p, a, b, c)
    scaled = [np.ldexp(x, power) for x in (p, a, b, c)]
    with np.errstate(all="raise"):  # no overflow or NaN on the way
        got = metrics.point_triangle_distance(*scaled)
    np.testing.assert_array_equal(got, np.ldexp(want, power))


def test_point_triangle_distance_against_dense_sampling():
    rng = np.random.default_rng(1)
    a, b, c = rng.normal(size=(3, 50, 3))
    p = rng.normal(size=(50, 3)) * 2
    got = metrics.point_triangle_distance(p, a, b, c)
    u, v = np.meshgrid(np.linspace(0, 1, 401), np.linspace(0, 1, 401))
    inside = u + v <= 1
    u, v = u[inside], v[inside]
    for i in range(50):
        q = a[i] + u[:, None] * (b[i] - a[i]) + v[:, None] * (c[i] - a[i])
        sampled = np.linalg.norm(q - p[i], axis=1).min()
        spacing = np.linalg.norm(np.stack([b[i] - a[i], c[i] - a[i]]), axis=1).max() / 400
        assert got[i] <= sampled + 1e-12
        assert sampled - got[i] <= spacing


def test_point_triangle_distance_known_values_and_broadcasting():
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    pts = np.array([[0.2, 0.2, 3.0], [-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.5, -2.0, 0.0], [1.0, 1.0, 0.0]])
    want = [3.0, math.sqrt(2), 1.0, 2.0, math.sqrt(0.5)]
    np.testing.assert_allclose(metrics.point_triangle_distance(pts, a, b, c), want, rtol=1e-14)
    # (5, 1, 3) points against (1, 4, 3) triangles -> (5, 4).
    many = np.stack([a, a + 1, a + 2, a + 3])
    out = metrics.point_triangle_distance(pts[:, None], many[None], (many + b)[None], (many + c)[None])
    assert out.shape == (5, 4)
    np.testing.assert_allclose(out[:, 0], want, rtol=1e-14)
    # A fully degenerate triangle (one point) measures the distance to that point.
    np.testing.assert_allclose(metrics.point_triangle_distance(pts, a, a, a), np.linalg.norm(pts, axis=1))


@pytest.mark.parametrize(
    "args",
    [
        (np.zeros((4, 2)), np.zeros(3), np.zeros(3), np.zeros(3)),
        (np.zeros((4, 3)), np.zeros((2, 3)), np.zeros(3), np.zeros(3)),
        (np.full((4, 3), np.nan), np.zeros(3), np.zeros(3), np.zeros(3)),
    ],
)
def test_point_triangle_distance_rejects_bad_input(args):
    with pytest.raises(ValueError):
        metrics.point_triangle_distance(*args)


# -------------------------------------------------------------------------- exact nearest-triangle search


def mixed_size_mesh():
    """A fine sphere inside a coarse box (12 huge triangles next to 1280 small ones): exercises the
    subdivision of large triangles into pieces."""
    v1, f1 = sphere(3, radius=0.5)
    box = trimesh.creation.box(extents=(2.0, 3.0, 1.5))
    v2, f2 = np.asarray(box.vertices), np.asarray(box.faces)
    return np.concatenate([v1, v2]), np.concatenate([f1, f2 + len(v1)])


@pytest.fixture(scope="module")
def mixed_size_case():
    rng = np.random.default_rng(2)
    v, f = mixed_size_mesh()
    mesh = metrics._common.as_mesh((v, f))
    # Points on, near and far from the surface, some outside the mesh's bounding box.
    on = _distance.sample_points(mesh, 1500, rng)
    pts = np.concatenate([on + rng.normal(scale=s, size=on.shape) for s in (0.0, 1e-3, 0.05)])
    pts = np.concatenate([pts, rng.uniform(-4, 4, size=(300, 3))])
    return v, f, mesh, pts, brute_force(pts, v, f)


@pytest.mark.parametrize("structure", ["kdtree", "grid"])
def test_nearest_triangles_exact(structure, mixed_size_case):
    v, f, mesh, pts, want = mixed_size_case
    tris = _nearest.Triangles(mesh.corners)
    tree = _nearest.TriangleIndex(tris)
    if structure == "kdtree":
        dist, face = tree.query(pts)
    else:
        # A margin that most (not all) points satisfy, so that the fallback runs too.
        index = _nearest.GridIndex(tris, delta=0.01, fallback=tree)
        dist, face = index.query(pts)
        assert (dist > 0.01).any() and (dist <= 0.01).mean() > 0.5
    np.testing.assert_allclose(dist, want, rtol=1e-9, atol=1e-13)
    # The reported face attains the distance.
    tri = v[f[face]]
    got = metrics.point_triangle_distance(pts, tri[:, 0], tri[:, 1], tri[:, 2])
    np.testing.assert_allclose(got, dist, rtol=1e-12, atol=1e-15)


def thin_tube(n_around=256, n_along=8, length=4.0, radius=0.5):
    """An open tube of long thin triangles: each quad of the n_around-by-n_along band is split in two, so the
    faces are length / n_along long and about 2πr / n_around wide (aspect ratio ~80 here)."""
    t = np.arange(n_around) * 2 * np.pi / n_around
    z = np.linspace(0.0, length, n_along + 1)
    v = np.stack([np.tile(radius * np.cos(t), n_along + 1), np.tile(radius * np.sin(t), n_along + 1),
                  np.repeat(z, n_around)], axis=1)
    i, j = np.meshgrid(np.arange(n_along), np.arange(n_around), indexing="ij")
    a = (i * n_around + j).ravel()
    b = (i * n_around + (j + 1) % n_around).ravel()
    return v, np.concatenate([np.stack([a, b, b + n_around], 1), np.stack([a, b + n_around, a + n_around], 1)])


def test_nearest_triangles_exact_on_long_thin_triangles():
    """Slivers are cut into strips across their long side: the KD-tree's answers stay the brute-force float64
    distances (the same kernel: the same bits), and its pieces stay narrow, so a query's candidate ball does
    not grow with the faces' length (the regular subdivision's pieces, within this budget, were a third of a
    face's length across)."""
    rng = np.random.default_rng(11)
    v, f = thin_tube()
    mesh = metrics._common.as_mesh((v, f))
    on = _distance.sample_points(mesh, 1500, rng)
    pts = np.concatenate([on + rng.normal(scale=s, size=on.shape) for s in (0.0, 1e-3, 0.05)])
    pts = np.concatenate([pts, rng.uniform(-1.5, 5.5, size=(300, 3)), v[rng.integers(0, len(v), 200)]])
    tris = _nearest.Triangles(mesh.corners)
    tree = _nearest.TriangleIndex(tris)
    length = 4.0 / 8
    assert tree.max_radius < length / 4
    want = brute_force(pts, v, f)
    exact = np.sqrt(_all_pairs_min(tris, pts))
    for dist, face in (tree.query(pts), _nearest.nearest_triangles(mesh.corners, pts)):
        np.testing.assert_allclose(dist, want, rtol=1e-9, atol=1e-13)
        np.testing.assert_array_equal(dist, exact)
        tri = v[f[face]]
        got = metrics.point_triangle_distance(pts, tri[:, 0], tri[:, 1], tri[:, 2])
        np.testing.assert_allclose(got, dist, rtol=1e-12, atol=1e-15)


def test_nearest_triangles_picks_grid_for_dense_points():
    rng = np.random.default_rng(3)
    v, f = sphere(2)  # 320 faces
    noisy_v = v * (1 + 0.02 * rng.normal(size=(len(v), 1)))
    mesh = metrics._common.as_mesh((noisy_v, f))
    pts = _distance.sample_points(metrics._common.as_mesh((v, f)), 20_000, rng)
    assert len(pts) >= 8 * len(f)  # the grid path
    dist, _ = _nearest.nearest_triangles(mesh.corners, pts)
    np.testing.assert_allclose(dist, brute_force(pts, noisy_v, f), rtol=1e-9, atol=1e-13)


def _all_pairs_sq(tris, pts):
    """(q, m) squared distances of every point to every face, with the search's own kernel (float64)."""
    m = len(tris)
    owner = np.repeat(np.arange(len(pts)), m)
    return tris.sq_dist(np.ascontiguousarray(pts[owner].T), np.tile(np.arange(m), len(pts))).reshape(len(pts), m)


def _all_pairs_min(tris, pts, block=256):
    """(q,) each point's smallest `_all_pairs_sq`, in blocks of points (the same values, without a (q, m)
    array: 12,000 points by 4,096 faces took 1.2 GB per coordinate)."""
    return np.concatenate([_all_pairs_sq(tris, pts[s:s + block]).min(axis=1) for s in range(0, len(pts), block)])


def _dense_points_case(seed=6):
    """A perturbed sphere (320 faces), dense points on and near the unperturbed one, some of them exactly at
    mesh vertices (distance 0 to several faces: exact ties), and a few far away (the fallback)."""
    rng = np.random.default_rng(seed)
    v, f = sphere(2)
    noisy_v = v * (1 + 0.02 * rng.normal(size=(len(v), 1)))
    mesh = metrics._common.as_mesh((noisy_v, f))
    pts = _distance.sample_points(metrics._common.as_mesh((v, f)), 20_000, rng)
    pts[:500] = noisy_v[rng.integers(0, len(v), 500)]  # on a vertex: every face around it ties at 0
    pts[500:700] *= 1.5  # far from the surface
    return noisy_v, f, mesh, pts


def test_nearest_triangles_grid_face_is_the_largest_nearest_index():
    """On the grid path, a point within the margin gets the largest index among the faces at its minimum
    distance (exact ties included); every other point gets the KD-tree's answer; all distances are the
    brute-force float64 ones."""
    v, f, mesh, pts = _dense_points_case()
    tris = _nearest.Triangles(mesh.corners)
    d2 = _all_pairs_sq(tris, pts)
    best = d2.min(axis=1)
    largest = np.array([np.flatnonzero(row == b).max() for row, b in zip(d2, best)])
    assert (np.sum(d2 == best[:, None], axis=1) > 1).sum() >= 400  # the vertex points tie
    dist, face = _nearest.nearest_triangles(mesh.corners, pts)
    np.testing.assert_allclose(dist, brute_force(pts, v, f), rtol=1e-9, atol=1e-13)
    np.testing.assert_array_equal(dist, np.sqrt(best))  # the same kernel: the same bits
    # delta as the 99th percentile of the pilot's exact distances (what the grid's own pilot must give)
    pilot = np.random.default_rng(0).choice(len(pts), _nearest._GRID_PILOT, replace=False)
    floor = 1e-9 * float(np.sqrt(((mesh.corners[1] - mesh.corners[0]) ** 2).sum(axis=0)).max())
    delta = max(float(np.quantile(np.sqrt(best[pilot]), _nearest._GRID_QUANTILE)), floor)
    near = np.sqrt(best) <= delta
    assert 0.9 < near.mean() < 1.0
    np.testing.assert_array_equal(face[near], largest[near])
    tree_face = _nearest.TriangleIndex(tris).query(pts[~near])[1]
    np.testing.assert_array_equal(face[~near], tree_face)


@pytest.mark.parametrize("delta", [1e-3, 0.05])
def test_grid_lists_every_face_within_delta_of_its_cells(delta):
    """Every (point, face) pair within delta is listed in the point's cell (float64 brute force), for thin
    and large margins (the cell size follows delta when delta is large)."""
    v, f, mesh, pts = _dense_points_case(7)
    tris = _nearest.Triangles(mesh.corners)
    grid = _nearest.GridIndex(tris, delta, _nearest.TriangleIndex(tris))
    pts = pts[700:3700]
    within = np.sqrt(_all_pairs_sq(tris, pts)) <= delta
    cell = np.floor((pts - grid.origin) / grid.h).astype(np.int64).T
    key = grid._key(cell)
    listed = {k: set(grid.cell_face[s : s + n]) for k, s, n in zip(grid.cell_key, grid.cell_start, grid.cell_count)}
    for i in np.flatnonzero(within.any(axis=1)):
        assert set(np.flatnonzero(within[i])) <= listed.get(key[i], set())


def test_squared_distance_with_given_edge_products_is_bitwise_the_same():
    from qemjax._mesh.pointtri import edge_products, squared_distance_cf

    rng = np.random.default_rng(8)
    p, a, ab, ac = (rng.normal(size=(3, 5000)) * 10 ** rng.uniform(-3, 3, size=(1, 5000)) for _ in range(4))
    ac[:, :100] = 2.5 * ab[:, :100]  # flat ones too
    np.testing.assert_array_equal(squared_distance_cf(p, a, ab, ac),
                                  squared_distance_cf(p, a, ab, ac, None, edge_products(ab, ac)))


# -------------------------------------------------------------------------------------- surface distance


def test_surface_distance_matches_brute_force():
    rng = np.random.default_rng(4)
    v, f = sphere(3)
    # A coarse, perturbed stand-in for a simplification.
    vs, fs = sphere(1)
    vs = vs * (1 + 0.03 * rng.normal(size=(len(vs), 1)))
    n = 2000
    got = metrics.surface_distance((v, f), (vs, fs), n_samples=n, seed=7)
    # Same sampling as surface_distance: the seed's two spawned streams, original first.
    rng_o, rng_s = (np.random.default_rng(s) for s in np.random.SeedSequence(7).spawn(2))
    po = _distance.sample_points(metrics._common.as_mesh((v, f)), n, rng_o)
    ps = _distance.sample_points(metrics._common.as_mesh((vs, fs)), n, rng_s)
    fwd, bwd = brute_force(po, vs, fs), brute_force(ps, v, f)
    both = np.concatenate([fwd, bwd])
    diag = np.linalg.norm(v.max(0) - v.min(0))
    want = {
        "hausdorff": both.max(),
        "mean": both.mean(),
        "rms": np.sqrt((both**2).mean()),
        "e_gh": (both**2).mean(),
        "hausdorff_fwd": fwd.max(),
        "hausdorff_bwd": bwd.max(),
        "mean_fwd": fwd.mean(),
        "mean_bwd": bwd.mean(),
    }
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-9), key
        scale = diag**2 if key == "e_gh" else diag
        assert got[key + "_rel"] == pytest.approx(value / scale, rel=1e-9), key
    assert got["n_points_fwd"] == len(v) + n and got["n_points_bwd"] == len(vs) + n
    assert got["bbox_diagonal"] == pytest.approx(diag)


def test_identical_meshes_have_zero_distance():
    v, f = sphere(3)
    d = metrics.surface_distance((v, f), (v, f), n_samples=5000)
    assert d["hausdorff"] < 1e-12 and d["rms"] < 1e-12


def test_translated_plane_distance_equals_translation():
    v, f = grid(8, 8)
    shift = 0.0125
    d = metrics.surface_distance((v, f), (v + [0, 0, shift], f), n_samples=5000)
    for key in ("hausdorff", "mean", "rms", "hausdorff_fwd", "hausdorff_bwd"):
        assert d[key] == pytest.approx(shift, rel=1e-9), key
    assert d["e_gh"] == pytest.approx(shift**2, rel=1e-9)
    assert d["hausdorff_rel"] == pytest.approx(shift / math.sqrt(2), rel=1e-9)


def test_scaled_sphere_distance_is_bounded_by_radius_change():
    # Icospheres of radius 1 and 1.1 share their vertex directions: every distance lies between the gap of
    # the circumscribed and inscribed radii and 0.1 (sampled points are inside the outer sphere).
    v, f = sphere(3)
    d = metrics.surface_distance((v, f), (1.1 * v, f), n_samples=5000)
    assert 0.09 < d["mean"] < 0.1 + 1e-9
    assert d["hausdorff"] <= 0.1 + 1e-9


# ------------------------------------------------------------------------------------------- topology


def test_topology_icosphere():
    t = metrics.topology_report(sphere(2))
    assert t["euler"] == 2 and t["genus"] == 0 and t["closed"] and t["orientable"]
    assert t["components"] == 1 and t["boundary_edges"] == 0
    assert t["non_manifold_edges"] == 0 and t["non_manifold_vertices"] == 0
    assert t["faces"] == 320 and t["edges"] == 480


def test_topology_torus_has_genus_one():
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=24, minor_sections=12)
    t = metrics.topology_report(torus)
    assert t["euler"] == 0 and t["genus"] == 1 and t["closed"]


def test_genus_is_an_int_and_prints_as_one():
    for mesh, genus in [(sphere(2), 0), (trimesh.creation.torus(1.0, 0.3, major_sections=24, minor_sections=12), 1)]:
        t = metrics.topology_report(mesh)
        assert type(t["genus"]) is int and t["genus"] == genus and f"genus {t['genus']}" == f"genus {genus}"
    row = metrics.evaluate(sphere(2), sphere(2), n_samples=100)
    assert type(row["genus"]) is int and type(row["genus_before"]) is int
    # two tetrahedra pinched at a vertex: closed and orientable, but a half-integer count; no genus,
    # also when the fans check that finds the pinch is skipped
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [0, 4, 5], [0, 6, 4], [0, 5, 6], [4, 6, 5]])
    for fans in (True, False):
        t = metrics.topology_report((V, F), fans=fans)
        assert t["closed"] and t["orientable"] and math.isnan(t["genus"]), fans


def test_topology_open_grid_boundary():
    t = metrics.topology_report(grid(5, 3))
    assert t["boundary_edges"] == 2 * (5 + 3)
    assert not t["closed"] and math.isnan(t["genus"])
    assert t["euler"] == 1 and t["components"] == 1 and t["non_manifold_vertices"] == 0


def test_topology_two_spheres_are_two_components():
    v1, f1 = sphere(1)
    v2, f2 = sphere(1, center=(5, 0, 0))
    t = metrics.topology_report((np.concatenate([v1, v2]), np.concatenate([f1, f2 + len(v1)])))
    assert t["components"] == 2 and t["euler"] == 4 and t["genus"] == 0


def test_topology_non_manifold_edge_and_vertex():
    # Three triangles on edge 0-1 (a "book" with three pages):
    #        2
    #   3 -- 0 -- 4        all three faces contain edge 0-1 (1 lies below 0, out of the drawing plane)
    v = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0], [-1, 0, 0], [1, 0, 0]], dtype=float)
    book = metrics.topology_report((v, np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])))
    assert book["non_manifold_edges"] == 1 and book["boundary_edges"] == 6
    assert book["non_manifold_vertices"] == 2  # the non-manifold edge's endpoints
    # Bowtie: two triangles that share only vertex 0.
    #   1       3
    #   | \   / |
    #   |   0   |
    #   | /   \ |
    #   2       4
    v = np.array([[0, 0, 0], [-1, 1, 0], [-1, -1, 0], [1, 1, 0], [1, -1, 0]], dtype=float)
    bowtie = metrics.topology_report((v, np.array([[0, 1, 2], [0, 4, 3]])))
    assert bowtie["non_manifold_vertices"] == 1 and bowtie["non_manifold_edges"] == 0
    assert bowtie["components"] == 1


def test_topology_orientability_and_flips():
    v, f = sphere(2)
    flipped = f.copy()
    flipped[:7] = flipped[:7, ::-1]
    t = metrics.topology_report((v, flipped), original=(v, f), target_faces=300)
    assert t["flipped_faces"] == 7 and t["flipped_fraction"] == pytest.approx(7 / 320)
    # Inconsistently wound, but a sphere is still orientable.
    assert t["orientable"] and t["closed"] and t["genus"] == 0
    assert t["target_faces"] == 300 and t["target_error"] == pytest.approx(320 / 300 - 1)
    # A Moebius strip is not orientable.
    n = 12
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    half = ang / 2
    ring = lambda s: np.stack([np.cos(ang) * (1 + s * np.cos(half)), np.sin(ang) * (1 + s * np.cos(half)), s * np.sin(half)], 1)
    v = np.concatenate([ring(-0.2), ring(0.2)])  # vertex i: inner, n + i: outer
    i = np.arange(n)
    j = (i + 1) % n
    # The last quad joins with a half twist: inner(n-1) meets outer(0) and vice versa.
    ji = np.where(j == 0, n + 0, j)
    jo = np.where(j == 0, 0, n + j)
    f = np.concatenate([np.stack([i, n + i, jo], 1), np.stack([i, jo, ji], 1)])
    t = metrics.topology_report((v, f))
    assert not t["orientable"] and t["boundary_edges"] > 0


# ------------------------------------------------------------------------------- quality, area, volume


def test_quality_equilateral_and_right_triangle():
    eq = (np.array([[0, 0, 0], [1, 0, 0], [0.5, math.sqrt(3) / 2, 0]]), np.array([[0, 1, 2]]))
    q = metrics.triangle_quality(eq)
    assert q["min_angle_min"] == pytest.approx(60) and q["aspect_ratio_max"] == pytest.approx(1)
    assert q["sliver_fraction"] == 0 and q["degenerate_faces"] == 0
    right = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    q = metrics.triangle_quality(right)
    assert q["min_angle_min"] == pytest.approx(45)
    assert q["aspect_ratio_mean"] == pytest.approx((1 + math.sqrt(2)) / math.sqrt(3))
    counts, edges = metrics.min_angle_histogram(right)
    assert counts.sum() == 1 and counts[9] == 1 and len(edges) == 13  # bin [45, 50)


def test_quality_sliver_and_degenerate():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.01, 0], [2, 0, 0]], dtype=float)
    q = metrics.triangle_quality((v, np.array([[0, 1, 2], [0, 1, 3]])))
    assert q["sliver_fraction"] == 1.0 and q["degenerate_faces"] == 1 and q["min_angle_min"] == 0
    assert np.isfinite(q["aspect_ratio_max"])


def test_area_volume():
    v, f = sphere(3)
    r = metrics.area_volume((v, f), (v, f))
    assert r["area_retention"] == pytest.approx(1) and r["volume_change"] == pytest.approx(0, abs=1e-12)
    assert r["volume_before"] == pytest.approx(trimesh.Trimesh(v, f).volume)
    r = metrics.area_volume((v, f), (1.1 * v, f))
    assert r["area_retention"] == pytest.approx(1.21) and r["volume_change"] == pytest.approx(0.331)
    r = metrics.area_volume((v, f), grid(3, 3))
    assert math.isnan(r["volume_after"]) and math.isnan(r["volume_change"])


# ------------------------------------------------------------------------------------------ evaluate


def test_evaluate_row_is_flat_deterministic_and_accepts_mesh_kinds():
    v, f = sphere(3)
    vs, fs = sphere(1)

    class Result:  # any object with .vertices / .faces
        vertices, faces = vs, fs

    a = metrics.evaluate(trimesh.Trimesh(v, f, process=False), Result(), target_faces=80, n_samples=3000, seed=3)
    b = metrics.evaluate((v, f), (vs, fs), target_faces=80, n_samples=3000, seed=3)
    assert all(isinstance(x, (int, float, bool, np.bool_)) for x in a.values())
    assert a["time_s"] > 0
    assert scalar_row(a).keys() == scalar_row(b).keys()
    assert all(same(a[k], b[k]) for k in scalar_row(a)), "same seed, same numbers"
    c = metrics.evaluate((v, f), (vs, fs), target_faces=80, n_samples=3000, seed=4)
    assert c["mean"] != a["mean"]
    import tempfile  # a file's path, as attribute_deviation takes it (surface_distance and evaluate refused it)

    from qemjax import load

    with tempfile.TemporaryDirectory() as tmp:
        trimesh.Trimesh(v, f, process=False).export(f"{tmp}/o.ply", encoding="ascii")
        read = metrics.evaluate(f"{tmp}/o.ply", (vs, fs), target_faces=80, n_samples=3000, seed=3)
        ref = metrics.evaluate(load(f"{tmp}/o.ply"), (vs, fs), target_faces=80, n_samples=3000, seed=3)
        assert all(same(read[k], ref[k]) for k in scalar_row(ref) if k != "time_s")
        assert metrics.surface_distance(f"{tmp}/o.ply", (vs, fs))["hausdorff"] == ref["hausdorff"]
    assert a["faces_after"] == 80 and a["target_error"] == 0 and a["genus"] == 0 and a["genus_before"] == 0
    assert a["volume_change"] < 0 and a["area_retention"] < 1 and a["flipped_faces"] == 0
    for key in ("hausdorff_rel", "rms_rel", "e_gh_rel", "min_angle_mean", "aspect_ratio_max", "components"):
        assert key in a


def test_a_bad_seed_is_named():
    """A seed numpy refuses was refused in numpy's words (SeedSequence), or taken (1.5)."""
    v, f = sphere(1)
    for seed in ("x", -1, 1.5, True):
        with pytest.raises(ValueError, match="seed must be a non-negative integer"):
            metrics.surface_distance((v, f), (v, f), n_samples=10, seed=seed)


def test_evaluate_without_target_keeps_the_columns():
    v, f = sphere(1)
    row = metrics.evaluate((v, f), (v, f), n_samples=100)
    assert math.isnan(row["target_faces"]) and math.isnan(row["target_error"])
    assert row["hausdorff"] < 1e-12 and row["area_retention"] == pytest.approx(1)


@pytest.mark.parametrize(
    "bad",
    [
        (np.zeros((4, 2)), np.array([[0, 1, 2]])),  # vertices not (n, 3)
        (np.zeros((4, 3)), np.array([0, 1, 2])),  # faces not (m, 3)
        (np.zeros((0, 3)), np.zeros((0, 3), dtype=int)),  # empty
        (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), np.array([[0, 1, 2]])),  # non-finite
        (np.eye(3), np.array([[0, 1, 3]])),  # index out of range
        (np.eye(3), np.array([[0, 1, -1]])),  # negative index
        (np.eye(3), np.array([[0, 1, 1.5]])),  # non-integer index
        (np.eye(3),),  # not a pair
        "mesh",  # not a mesh
    ],
)
def test_bad_meshes_raise_value_error(bad):
    good = sphere(1)
    with pytest.raises(ValueError):
        metrics.evaluate(bad, good)
    with pytest.raises(ValueError):
        metrics.topology_report(bad)


def test_bad_arguments_raise_value_error():
    good = sphere(1)
    with pytest.raises(ValueError):
        metrics.evaluate(good, good, n_samples=-1)
    with pytest.raises(ValueError):
        metrics.evaluate(good, good, target_faces=0)


# ------------------------------------------------------------------------------------------ real meshes


def shared_mesh(name):
    path = SHARED_MESHES / name
    if not path.exists():
        pytest.skip(f"{path} not available (../shared/meshes exists on development and CI machines only)")
    return trimesh.load(path, process=False, force="mesh")


@pytest.mark.shared
@pytest.mark.parametrize("name, genus", [("3holes.off", 3), ("fertility.off", 4), ("rocker-arm-small.off", 1)])
def test_shared_mesh_genus(name, genus):
    t = metrics.topology_report(shared_mesh(name))
    assert t["closed"] and t["genus"] == genus and t["components"] == 1


@pytest.mark.shared
def test_shared_mesh_known_counts():
    # The cow is watertight but pinched at one vertex (Euler 1): genus is undefined there.
    cow = metrics.topology_report(shared_mesh("cow.obj"))
    assert cow["closed"] and cow["non_manifold_vertices"] == 1 and cow["euler"] == 1 and math.isnan(cow["genus"])
    # Borders as listed in shared/README.md.
    assert metrics.topology_report(shared_mesh("stanford-bunny.obj"))["boundary_edges"] == 223
    truck = metrics.topology_report(shared_mesh("truck.obj"))
    assert truck["boundary_edges"] == 1388 and truck["components"] == 50


@pytest.mark.shared
def test_shared_mesh_evaluate_against_itself():
    arm = shared_mesh("rocker-arm.obj")
    row = metrics.evaluate(arm, arm, n_samples=5000)
    assert row["hausdorff"] < 1e-12 and row["volume_change"] == pytest.approx(0, abs=1e-12)
    assert row["flipped_faces"] == 0 and row["genus"] == row["genus_before"] == 1


def test_nearest_triangles_single_face_and_far_points():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    pts = np.random.default_rng(5).normal(scale=3.0, size=(500, 3))
    dist, face = _nearest.nearest_triangles(metrics._common.as_mesh((v, f)).corners, pts)
    np.testing.assert_allclose(dist, brute_force(pts, v, f), rtol=1e-12)
    assert (face == 0).all()


@pytest.fixture(scope="module")
def examples(tmp_path_factory):
    from qemjax import shapes

    folder = tmp_path_factory.mktemp("examples")
    shapes.write_examples(folder, subdivisions=3)
    return folder


def test_attribute_deviation_takes_what_simplify_takes(examples):
    """The original as a path (read as simplify reads it: UVs kept) or a trimesh, the simplified mesh as a
    result; a qemjax.load Mesh carries positions only, and the error says what to pass instead."""
    import qemjax

    path = examples / "textured.obj"
    res = qemjax.simplify(path, ratio=0.25, texture=examples / "textured.png", progress=False)
    by_path = metrics.attribute_deviation(path, res, n_samples=3000)
    by_str = metrics.attribute_deviation(str(path), res, n_samples=3000)
    by_trimesh = metrics.attribute_deviation(trimesh.load(path, process=False), res, n_samples=3000)
    assert by_path == by_str == by_trimesh
    assert 0 < by_path["uv_dev_rms"] < 0.01  # seams held: no sample reads a value from another chart
    assert by_path["uv_dev_max"] < 0.05  # also where the re-fit put the output within a hair of the input
    assert metrics.attribute_deviation(path, path, n_samples=1000)["uv_dev_max"] < 1e-9
    with pytest.warns(UserWarning, match="carries uv, which qemjax does not keep"):
        m = qemjax.load(path)
        plain = qemjax.simplify(path, ratio=0.25, attributes=None, progress=False)
    with pytest.raises(ValueError, match="original .Mesh. carries no uv: qemjax.load meshes .* pass the file's path"):
        metrics.attribute_deviation(m, res)
    with pytest.raises(ValueError, match="the simplified carries no uv"):
        metrics.attribute_deviation(path, plain)
    with pytest.raises(ValueError, match="the original carries no uv"):
        metrics.attribute_deviation(examples / "bumpy.obj", res)


@pytest.mark.parametrize("scale", [2.0 ** -300, 1e100])
def test_attribute_deviation_at_extreme_scales_is_that_at_scale_one(examples, scale):
    """Its samples are placed by area, a cross product's length, which was 0 or inf beyond about 1e±77 mesh
    units; it measures in the frame of the other metrics (`test_metrics_at_extreme_scales_are_those_at_scale_one`)."""
    import qemjax

    path = examples / "textured.obj"
    out = qemjax.simplify(path, ratio=0.25, texture=examples / "textured.png", progress=False).to_trimesh()
    given = trimesh.load(path, process=False)
    base = metrics.attribute_deviation(given, out, n_samples=2000)
    for mesh in (given, out):
        mesh.vertices = np.asarray(mesh.vertices) * scale
    row = metrics.attribute_deviation(given, out, n_samples=2000)
    assert row == base if math.frexp(scale)[0] == 0.5 else row == pytest.approx(base, rel=1e-6)


def test_the_diagonal_is_summed_left_to_right_in_every_place():
    """Every relative distance divides by the bounding box's diagonal: its squares summed left to right (no
    BLAS dot, whose kernel, and so the last bit, changes with the CPU), the same in the metrics and in the
    run's stats, on random boxes of every scale."""
    import qemjax
    from qemjax._mesh.arrays import box_diagonal
    from qemjax.shapes import bumpy_sphere

    rng = np.random.default_rng(7)
    for _ in range(500):
        lo = rng.normal(size=3) * 10.0 ** rng.integers(-4, 5)
        hi = lo + rng.random(3) * 10.0 ** rng.integers(-4, 5, size=3)
        d = hi - lo
        assert box_diagonal(lo, hi) == math.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    mesh = bumpy_sphere(3)
    V = np.asarray(mesh.vertices, np.float64) * np.array([3.7, 0.013, 11.1])  # three unlike extents
    F = np.asarray(mesh.faces)
    d = V.max(0) - V.min(0)
    want = math.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    assert metrics.surface_distance((V, F), (V, F), n_samples=10)["bbox_diagonal"] == want
    stats = qemjax.simplify((V, F), ratio=0.5).stats
    for key in ("distance_max", "distance_rms", "distance_p95"):
        assert stats[key + "_rel"] == stats[key] / want


_LENGTHS = {"hausdorff", "mean", "rms", "p50", "p95", "p99", "hausdorff_fwd", "hausdorff_bwd", "mean_fwd",
            "mean_bwd", "bbox_diagonal"}


def _power(key: str) -> int:
    """The power of the mesh's length unit a metric is in (0: a ratio, an angle or a count)."""
    key = key.split(".")[-1]
    return 1 if key in _LENGTHS else 2 if key in ("e_gh", "area_before", "area_after") else \
        3 if key in ("volume_before", "volume_after") else 0


@pytest.mark.parametrize("scale", [2.0 ** -300, 2.0 ** 300, 1e-100, 1e100])
def test_metrics_at_extreme_scales_are_those_at_scale_one(scale):
    """Squared distances, areas (a cross product's squared length) and the products of normals that find
    flipped faces left float64's range beyond about 1e±77 mesh units: areas of 0 or inf, angles of 0, NaN
    ratios, samples only at the vertices, no flipped face. The metrics measure in a frame of the mesh's
    size, scaled by a power of two, and report in mesh units: a power-of-two scale gives exactly the values
    at scale 1 times the scale (to the power of the value's unit), another the same within rounding."""
    centre = (0.3, -0.2, 0.1)
    o, s = sphere(3, center=centre), sphere(1, center=centre)
    s[1][:5] = s[1][:5, ::-1]  # five flipped faces

    def measure(k):
        O, S = (o[0] * k, o[1]), (s[0] * k, s[1])
        row = {"ev." + a: b for a, b in scalar_row(metrics.evaluate(O, S, n_samples=2000)).items()}
        for name, part in (("sd", metrics.surface_distance(O, S, n_samples=2000)), ("av", metrics.area_volume(O, S)),
                           ("tq", metrics.triangle_quality(S)), ("tr", metrics.topology_report(S, original=O))):
            row.update({f"{name}.{a}": b for a, b in part.items()})
        row["histogram"] = tuple(metrics.min_angle_histogram(S)[0])
        return row

    base, row = measure(1.0), measure(scale)
    assert base["ev.flipped_faces"] == base["tr.flipped_faces"] == 5 and base["ev.area_retention"] < 1
    exact = math.frexp(scale)[0] == 0.5
    for key, value in base.items():
        if isinstance(value, float) and not math.isnan(value):
            want = value * scale ** _power(key)
            assert row[key] == want if exact else row[key] == pytest.approx(want, rel=1e-9), key
        else:
            assert same(row[key], value), key


def test_equilateral_faces_are_in_the_last_bin():
    """An equilateral face's smallest angle computes as 60.000...01, past the last edge: the histogram left
    it out (16 of an icosahedron's 20 faces counted)."""
    from qemjax import shapes

    ico = shapes.icosphere(0)
    assert metrics.min_angle_histogram(ico)[0].sum() == len(ico.faces)
    V = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [1.5, 3.0 * np.sqrt(3.0) / 2.0, 0.0]])
    counts, _ = metrics.min_angle_histogram((V, [[0, 1, 2]]))
    assert counts.sum() == 1 and counts[-1] == 1


def test_evaluate_without_samples_and_a_bad_target_on_a_textured_mesh():
    """n_samples=0 (vertices only) on meshes with UVs crashed in the deviation, which needs samples: it
    is left out; a target that is not a positive integer is named (it was int()'s words, or 2.7 taken as 2)."""
    from qemjax import shapes

    V, F = shapes.icosphere(2)
    tm = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=np.asarray(V)[:, :2]))
    row = metrics.evaluate(tm, tm, n_samples=0)
    assert row["hausdorff"] == 0.0 and not any(k.startswith("uv_dev") for k in row)
    assert "uv_dev_rms" in metrics.evaluate(tm, tm, n_samples=100)
    for bad in ("abc", float("nan"), 2.7, True, 0):
        with pytest.raises(ValueError, match="target_faces must be a positive integer"):
            metrics.evaluate(tm, tm, target_faces=bad, n_samples=10)
    with pytest.raises(ValueError, match="n_samples must be a positive integer"):
        metrics.attribute_deviation(tm, tm, n_samples=0)


@pytest.mark.parametrize("scale", [1.0, 1e100])
def test_unused_non_finite_vertices_are_not_measured(scale):
    """The metrics refused a mesh with NaN or inf in a vertex no face uses (simplify drops such a vertex):
    they measure it as the mesh without that vertex, bit for bit (vertex counts still count it, as they count
    every vertex given); NaN in a vertex a face uses is still refused."""
    from qemjax import shapes

    m, s = shapes.bumpy_sphere(2), shapes.icosphere(1)
    V, F = np.asarray(m.vertices) * scale, np.asarray(m.faces)
    J = np.vstack([V[:10], [[np.nan] * 3, [np.inf, 0.0, 0.0]], V[10:]])
    FJ = np.where(F >= 10, F + 2, F)
    S = (np.asarray(s.vertices) * scale, np.asarray(s.faces))
    SJ = (np.vstack([S[0], [[0.0, -np.inf, np.nan]]]), S[1])
    a, b = metrics.evaluate((V, F), S, n_samples=500), metrics.evaluate((J, FJ), SJ, n_samples=500)
    assert (b["vertices_before"], b["vertices_after"]) == (a["vertices_before"] + 2, a["vertices_after"] + 1)
    differ = [k for k in a if k not in ("time_s", "vertices_before", "vertices_after")
              and not (a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]))]
    assert differ == [], [(k, a[k], b[k]) for k in differ]
    assert metrics.area_volume((V, F), S) == metrics.area_volume((J, FJ), SJ)
    assert metrics.surface_distance((V, F), S, n_samples=200) == metrics.surface_distance((J, FJ), SJ, n_samples=200)
    assert metrics.triangle_quality((V, F)) == metrics.triangle_quality((J, FJ))
    J[FJ[0, 0]] = np.nan
    with pytest.raises(ValueError, match=r"^original: vertices contain NaN or infinite values$"):
        metrics.evaluate((J, FJ), S)


def test_a_trimesh_scene_is_measured_as_simplify_takes_it():
    """`trimesh.load` of a glTF gives a Scene, which simplify (and attribute_deviation) take, concatenated: the
    other metrics and `peers.simplify` refused it ("expected a trimesh.Trimesh, ... got Scene")."""
    from qemjax import peers

    mesh = trimesh.creation.icosphere(subdivisions=2)
    scene = trimesh.Scene([mesh])
    simplified = (mesh.vertices[:], mesh.faces[::2])
    np.testing.assert_equal(metrics.evaluate(scene, simplified, n_samples=500) | {"time_s": 0},
                            metrics.evaluate(mesh, simplified, n_samples=500) | {"time_s": 0})  # NaN == NaN
    np.testing.assert_equal(metrics.topology_report(scene), metrics.topology_report(mesh))
    if "meshoptimizer" in peers.available():
        assert len(peers.simplify("meshoptimizer", scene, 100).faces) == 100
    with pytest.raises(ValueError, match="^original: expected a triangle mesh, got a point cloud"):
        metrics.surface_distance(trimesh.PointCloud(mesh.vertices), simplified)


@pytest.mark.parametrize("mesh, message", [
    (([[0, 0, 0], [1, 0], [0, 1, 0]], [[0, 1, 2]]), "^original: vertices must be a rectangular array, got a ragged"),
    (([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [0, 1]]), "^original: faces must be a rectangular array, got a"),
])
def test_a_ragged_list_is_refused_naming_the_mesh(mesh, message):
    """numpy's "setting an array element with a sequence. The requested array has an inhomogeneous shape ..."
    named neither the mesh nor its vertices or faces."""
    tri = (np.eye(3), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match=message):
        metrics.surface_distance(mesh, tri)


@pytest.mark.parametrize("kwargs, message", [
    (dict(eps=float("nan")), r"^eps must be a finite number >= 0 \(UV units\), got nan$"),
    (dict(eps=-1e-3), r"^eps must be a finite number >= 0 \(UV units\), got -0.001$"),
    (dict(chunk=0), r"^chunk must be a whole number >= 1, got 0$"),
    (dict(chunk=-4), r"^chunk must be a whole number >= 1, got -4$"),
    (dict(chunk=64.0), r"^chunk must be a whole number >= 1, got 64.0$"),
])
def test_uv_chart_integrity_refuses_eps_and_chunk_it_cannot_use(kwargs, message):
    """eps=NaN placed no point in any input triangle, so every face read as spanning a seam, without a word;
    chunk=0 raised range's 'arg 3 must not be zero', a negative one set.intersection's TypeError."""
    from qemjax import shapes

    V, F = shapes.grid(4)
    tm = trimesh.Trimesh(V, F, visual=trimesh.visual.TextureVisuals(uv=V[:, :2]), process=False)
    assert metrics.uv_chart_integrity(tm, tm)["faces_spanning"] == 0
    with pytest.raises(ValueError, match=message):
        metrics.uv_chart_integrity(tm, tm, **kwargs)


def test_a_face_that_repeats_a_vertex_is_one_face_on_its_edge():
    """A face (a, a, b) runs along its one edge both ways: both half-edges were counted, so the edge was "in two
    faces", and a lone such face read as a closed surface of genus 0 with a volume; beside a closed mesh, on
    one of its edges, it made that edge one of four faces. It is one face there, one fan at its vertex."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    for face in ([0, 0, 1], [0, 1, 1], [0, 1, 0]):
        t = metrics.topology_report((V, np.array([face])))
        assert (t["edges"], t["boundary_edges"], t["closed"], t["non_manifold_vertices"]) == (1, 1, False, 0)
        assert math.isnan(t["genus"])
        assert math.isnan(metrics.area_volume((V, np.array([face])), (V, [face]))["volume_before"])
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    t = metrics.topology_report((V, np.vstack([tet, [[0, 0, 1]]])))
    assert (t["edges"], t["non_manifold_edges"], t["boundary_edges"]) == (6, 1, 0)
    assert metrics._common.as_mesh((V, np.vstack([tet, [[0, 0, 1]]]))).edges.count.max() == 3
    assert metrics.topology_report((V, tet)) == {**t, "faces": 4, "euler": 2, "closed": True, "genus": 0,
                                                 "non_manifold_edges": 0, "non_manifold_vertices": 0}


def quad_torus(nu=16, nv=8):
    """A torus of nu-by-nv quads, (V, (m, 4) faces)."""
    u, v = np.meshgrid(np.arange(nu) * 2 * np.pi / nu, np.arange(nv) * 2 * np.pi / nv, indexing="ij")
    V = np.stack([(2 + np.cos(v)) * np.cos(u), (2 + np.cos(v)) * np.sin(u), np.sin(v)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")

    def at(a, b):
        return (a % nu) * nv + b % nv

    return V, np.stack([at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)], -1).reshape(-1, 4)


def test_polygon_faces_are_measured_as_simplify_triangulates_them():
    """simplify takes polygons (it fan-triangulates them), and the metrics refused them ("faces must have shape
    (m, 3)"), so evaluate(quads, simplify(quads)) failed: they take them now, as the triangles simplify ran on."""
    import qemjax
    from qemjax._io.mesh import as_arrays

    V, Q = quad_torus()
    tris = as_arrays((V, Q)).faces  # simplify's triangles of these quads
    res = qemjax.simplify((V, Q), ratio=0.5, progress=False)
    row, same_row = (metrics.evaluate(m, res, n_samples=500) for m in ((V, Q), (V, tris)))
    assert row["faces_before"] == 2 * len(Q) and row["genus_before"] == 1
    assert row.keys() == same_row.keys() and all(same(row[k], same_row[k]) for k in scalar_row(row))
    assert metrics.topology_report((V, Q)) == metrics.topology_report((V, tris))
    assert metrics.triangle_quality((V, Q.tolist())) == metrics.triangle_quality((V, tris))
    pentagon = np.array([[0, 1, 2, 3, 4]])
    ring = np.c_[np.cos(np.arange(5) * 1.2566), np.sin(np.arange(5) * 1.2566), np.zeros(5)]
    assert metrics.topology_report((ring, pentagon))["faces"] == 3
    with pytest.raises(ValueError, match=r"^mesh: faces must have shape \(m, 3\) \(or \(m, k>=3\) polygons\), got \(5, 2\)$"):
        metrics.topology_report((ring, [[0, 1]] * 5))


@pytest.mark.parametrize("bin_edges", ["abc", [[0, 5], [10]], None, np.linspace(0, 60, 200)[::-1].reshape(20, 10)])
def test_min_angle_histogram_refuses_bin_edges_it_cannot_read_in_one_line(bin_edges):
    """Text (or a ragged list) raised numpy's "could not convert string to float: 'abc'", naming no argument;
    an array numpy prints on several lines gave a message of as many."""
    with pytest.raises(ValueError, match="^bin_edges must be a 1-D increasing array of at least 2 values, got ") as e:
        metrics.min_angle_histogram(sphere(1), bin_edges=bin_edges)
    assert "\n" not in str(e.value)


def test_charts_refuses_faces_it_cannot_read_in_the_user_s_terms():
    """charts read three columns of (m, 4) faces and let the fourth go without a word; wedge_faces of another
    shape gave numpy's "operands could not be broadcast together"; fractional indices were truncated."""
    F = np.array([[0, 1, 2], [0, 2, 3]])
    W = np.array([[0, 1, 2], [0, 2, 4]])  # the same wedges at both ends of their edge 0-2: one chart
    assert metrics.charts(F, W).tolist() == metrics.charts(F.tolist(), W.astype(float)).tolist() == [0, 0]
    assert metrics.charts(F, np.array([[0, 1, 2], [5, 2, 4]])).tolist() == [0, 1]
    for faces, wedges, says in (
            (np.c_[F, F[:, :1]], np.c_[W, W[:, :1]], r"faces must have shape \(m, 3\) .*, got \(2, 4\)"),
            (F, W[:1], r"wedge_faces must have the shape of faces \(2, 3\) .*, got \(1, 3\)"),
            (F, W.T, r"wedge_faces must have the shape of faces \(2, 3\) .*, got \(3, 2\)"),
            (F + 0.5, W, "faces must hold integer indices, got dtype float64"),
            (F, [[0, 1], [2]], "wedge_faces must be a rectangular array of vertex indices, got a ragged list")):
        with pytest.raises(ValueError, match="^" + says + "$"):
            metrics.charts(faces, wedges)


def test_a_face_on_no_edge_is_no_closed_surface():
    """A face (a, a, a) has no edge, so no edge was "not in two faces": a mesh of such faces read as closed,
    genus 0, with a volume of 0, where it has no surface at all; beside a closed tetrahedron it kept it
    "closed". A face on no edge keeps a mesh from being closed; meshes without one read as before."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 2, 2]], float)
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    for F in ([[0, 0, 0]], [[0, 0, 0], [1, 1, 1]], np.vstack([tet, [[4, 4, 4]]]), np.vstack([tet, [[0, 0, 0]]])):
        t = metrics.topology_report((V, F))
        assert not t["closed"] and math.isnan(t["genus"]), F
        assert t["boundary_edges"] == 0 and t["edges"] == (6 if len(F) > 2 else 0)
        assert math.isnan(metrics.area_volume((V, F), (V, F))["volume_before"])
        assert math.isnan(metrics.evaluate((V, tet), (V, F), n_samples=10)["genus"])
    t = metrics.topology_report((V, tet))
    assert t["closed"] and t["genus"] == 0
    assert metrics.area_volume((V, tet), (V, tet))["volume_before"] == pytest.approx(1 / 6)


def test_a_mesh_split_at_uv_seams_has_the_topology_of_its_surface(examples):
    """res.to_trimesh() of a textured result has its vertices split along the UV seams (as trimesh loads a
    textured OBJ): evaluate read 6 components, hundreds of boundary edges and no genus where evaluate(path, res)
    read one closed sphere, and the textured input read so too (components_before 6). A trimesh or file that
    carries UVs (colours, normals) is measured with its coincident vertices joined, as simplify welds them; the
    distances take the mesh as given, and arrays with coincident vertices are measured as given."""
    import qemjax

    path = examples / "textured.obj"
    with pytest.warns(UserWarning):
        res = qemjax.simplify(path, ratio=0.25, texture=examples / "textured.png", progress=False)
    tm = res.to_trimesh()
    assert len(tm.vertices) > len(res.vertices)  # split at the seams
    assert metrics.topology_report(tm) == metrics.topology_report(res)
    keys = ["edges", "boundary_edges", "non_manifold_edges", "non_manifold_vertices", "components", "euler",
            "closed", "orientable", "genus", "volume_after", "volume_change", "flipped_faces",
            *(f"{k}_before" for k in ("boundary_edges", "components", "euler", "closed", "genus"))]
    by_res, by_trimesh = (metrics.evaluate(path, s, n_samples=500) for s in (res, tm))
    assert by_trimesh["components"] == by_trimesh["components_before"] == 1
    assert by_trimesh["genus"] == by_trimesh["genus_before"] == 0 and by_trimesh["boundary_edges"] == 0
    assert {k: by_trimesh[k] for k in keys} == pytest.approx({k: by_res[k] for k in keys}, rel=1e-12)
    split = (np.asarray(tm.vertices), np.asarray(tm.faces))  # the same arrays, no UVs: measured as given
    assert metrics.topology_report(split)["components"] > 1
    assert metrics.topology_report(trimesh.Trimesh(*split, process=False))["components"] > 1
    as_arrays = metrics.evaluate(trimesh.load(path, process=False), split, n_samples=500)
    for k in ("hausdorff", "mean", "rms", "p95", "hausdorff_fwd", "mean_bwd", "area_after", "min_angle_mean"):
        assert by_trimesh[k] == as_arrays[k], k
    assert math.isnan(as_arrays["genus"]) and as_arrays["genus_before"] == 0
