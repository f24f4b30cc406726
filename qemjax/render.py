"""Quick pictures of triangle meshes with matplotlib (an optional dependency: ``pip install matplotlib``).

``render(mesh)`` draws one mesh with flat Lambert shading; ``render_pair(before, after)`` draws two side by
side with their face counts. A mesh is a ``trimesh.Trimesh`` (or a ``trimesh.Scene``, its meshes
concatenated), a ``(vertices, faces)`` pair, or any object with ``.vertices`` and ``.faces`` (e.g. the result
of ``qemjax.simplify``).

This is a convenience for notebooks and reports, not a renderer: matplotlib sorts polygons by depth (painter's
algorithm), which costs time per face and gets some overlaps wrong. To keep it quick, meshes with more than
``max_faces`` faces (default 60 000) are thinned for display: faces turned away from the camera are dropped
first (invisible on a closed, consistently oriented mesh), then, if still too many, a fixed random subset
(seed 0) is kept, which shows as speckle. The mesh itself is never changed.
"""

from __future__ import annotations

import numpy as np

from ._io.mesh import _as_trimesh, _triangulate
from ._mesh.arrays import whole_numbers

__all__ = ["face_texture_colors", "render", "render_pair"]

DEFAULT_VIEW = (20.0, -60.0)  # (elevation, azimuth) in degrees, matplotlib's convention
DEFAULT_COLOR = (0.72, 0.77, 0.88)
DEFAULT_MAX_FACES = 60_000
AMBIENT = 0.25  # share of the colour kept on faces turned away from the light
EDGE_COLOR = (0.1, 0.1, 0.15)
ZOOM = 1.35


def _pyplot():
    try:
        import matplotlib.pyplot as plt
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "qemjax.render needs matplotlib: pip install matplotlib (or pip install 'qemjax[plot]')"
        ) from exc
    return plt, Poly3DCollection


def _as_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64, faces (m, k) int64, k >= 3: triangles, quads or other polygons) from a
    trimesh, a (V, F) pair or a .vertices/.faces object; ValueError naming a shape that is neither."""
    if type(mesh).__module__.startswith("trimesh"):  # a Scene (a glTF's), concatenated as simplify takes it
        mesh = _as_trimesh(mesh)
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        V, F = mesh.vertices, mesh.faces
    elif isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        V, F = mesh
    else:
        raise TypeError(f"expected a mesh, a (vertices, faces) pair, or .vertices/.faces; got {type(mesh)!r}")
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F)
    # indices as given: a cast to int64 would cut 2.7 to 2, and numpy's indexing would wrap -1 to the last vertex
    if F.size and not whole_numbers(F):
        raise ValueError(f"render: faces must hold integer vertex indices, got dtype {F.dtype}")
    F = F.astype(np.int64)
    if V.ndim == 1 and V.size % 3 == 0:  # flat x, y, z triples
        V = V.reshape(-1, 3)
    if F.ndim == 1 and F.size % 3 == 0:  # flat triangles
        F = F.reshape(-1, 3)
    # a reshape to (-1, 3) of anything else cut quads and (n, 2) points into rows that are not faces
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"render: vertices must be (n, 3), got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] < 3:
        raise ValueError(f"render: faces must be (m, 3) triangles or (m, k) polygons with k >= 3 corners, "
                         f"got shape {F.shape}")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError(f"render: face indices must lie in [0, {len(V)}), got [{F.min()}, {F.max()}]")
    return V, F


def _rotate_up(V: np.ndarray, up: str) -> np.ndarray:
    """Turn the mesh so that its ``up`` axis points along matplotlib's vertical (z) axis."""
    if up == "z":
        return V
    if up == "y":  # rotate +90 degrees about x: y -> z, z -> -y
        return np.stack([V[:, 0], -V[:, 2], V[:, 1]], axis=1)
    if up == "x":
        return np.stack([V[:, 1], V[:, 2], V[:, 0]], axis=1)
    raise ValueError(f"up must be 'x', 'y' or 'z', got {up!r}")


def _check_view(view) -> tuple[float, float]:
    """``view`` as (elevation, azimuth) floats; ValueError in render's words unless it is two finite numbers
    (a short tuple raised IndexError deep in the drawing)."""
    try:
        elev, azim = (float(x) for x in view)
    except (TypeError, ValueError):
        elev = azim = float("nan")
    if not (np.isfinite(elev) and np.isfinite(azim)):
        raise ValueError(f"render: view must be (elevation, azimuth) in degrees, got {view!r}")
    return elev, azim


def _base_color(color) -> np.ndarray:
    """``color`` as float64 RGB(A): a matplotlib colour name ("red", "#4477aa"), 3 or 4 numbers, or (m, 3|4)
    per face; ValueError in render's words for anything else (None or a name raised numpy's errors)."""
    if isinstance(color, str):
        from matplotlib.colors import to_rgb

        try:
            return np.asarray(to_rgb(color), dtype=np.float64)
        except ValueError:
            raise ValueError(f"render: color {color!r} is not a colour matplotlib knows") from None
    try:
        base = np.asarray(color, dtype=np.float64)
    except (TypeError, ValueError):
        base = None
    if base is None or base.ndim not in (1, 2) or base.shape[-1] not in (3, 4):
        raise ValueError(f"render: color must be RGB (3 numbers in 0..1), a colour name or one per face (m, 3), "
                         f"got {color!r}")
    return base


def _view_direction(view) -> np.ndarray:
    """Unit vector from the scene towards the camera for matplotlib's (elev, azim) in degrees."""
    elev, azim = np.radians(view[0]), np.radians(view[1])
    return np.array([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)])


def _thin(tris: np.ndarray, normals: np.ndarray, eye: np.ndarray, max_faces: int, colors=None, per: int = 1):
    """Drop back faces, then keep a seeded random subset, until at most ``max_faces`` faces remain. A face is
    one as given: its ``per`` triangles (consecutive rows of ``tris``, a polygon's fan) are kept or dropped
    together, and it faces the camera when one of them does. Per-triangle ``colors`` (t,3), when given, are
    thinned alike and returned third."""
    faces = len(tris) // per
    if faces <= max_faces:
        return (tris, normals) if colors is None else (tris, normals, colors)
    kept = np.flatnonzero((normals @ eye > 0).reshape(faces, per).any(axis=1))
    if len(kept) > max_faces:
        kept = kept[np.sort(np.random.default_rng(0).choice(len(kept), size=max_faces, replace=False))]
    rows = (kept[:, None] * per + np.arange(per)).reshape(-1)
    tris, normals = tris[rows], normals[rows]
    return (tris, normals) if colors is None else (tris, normals, colors[rows])


def render(
    mesh,
    ax=None,
    *,
    view=DEFAULT_VIEW,
    color=DEFAULT_COLOR,
    edges: bool = False,
    path=None,
    up: str = "y",
    max_faces: int = DEFAULT_MAX_FACES,
    title: str | None = None,
    figsize=(5, 5),
    dpi: int = 120,
):
    """Draw ``mesh`` with flat shading; returns the matplotlib 3-D Axes.

    Args:
        mesh: trimesh.Trimesh, (vertices, faces) pair, or object with ``.vertices`` and ``.faces``. Faces are
            (m, 3) triangles, or (m, k) quads or other polygons (k >= 3), drawn as a fan of triangles each.
        ax: a 3-D Axes to draw into (``projection="3d"``); a new figure is made when None.
        view: (elevation, azimuth) in degrees. The light comes from the camera, a little above and left.
        color: RGB base colour (0..1) or a matplotlib colour name ("red"), or one per face (m, 3) (e.g. a
            texture sampled at each face's UVs: `face_texture_colors`), scaled by Lambert shading
            ``AMBIENT + (1 - AMBIENT) * |n . l|`` (two-sided, so meshes with mixed orientation still look lit).
        edges: also draw the triangle edges (useful on small, simplified meshes).
        path: when given, the figure is saved there; a figure made here is then closed.
        up: the mesh's up axis ("y" for most scanned / OBJ models, "z" for CAD), shown vertically.
        max_faces: display cap on the faces as given (a polygon counts once, and is drawn or left out with
            all its triangles); meshes with more are thinned as the module docstring explains.
        title: optional Axes title.
        figsize, dpi: the size (inches) and resolution of a figure made here (not used with ``ax``).
    """
    plt, Poly3DCollection = _pyplot()
    V, F = _as_arrays(mesh)
    view = _check_view(view)
    if isinstance(max_faces, bool) or not isinstance(max_faces, (int, np.integer)) or max_faces < 0:
        raise ValueError(f"render: max_faces must be a whole number >= 0, got {max_faces!r}")
    sides = F.shape[1]
    polygons = len(F)
    if sides > 3:  # quads and other polygons: a fan of triangles each, drawn and shaded as its own face
        F = _triangulate(F)
    V = _rotate_up(V, up)
    created = ax is None
    if created:
        fig = plt.figure(figsize=figsize, dpi=dpi)
        ax = fig.add_subplot(projection="3d")

    tris = V[F]  # (m, 3, 3)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)

    eye = _view_direction(view)
    base = _base_color(color)
    if base.ndim == 2:
        if base.shape[0] != polygons:
            raise ValueError(f"color: {base.shape[0]} per-face colours for {polygons} faces")
        base = np.repeat(base, sides - 2, axis=0)  # one per triangle of each face's fan
        tris, normals, base = _thin(tris, normals, eye, max_faces, base[:, :3], per=sides - 2)
    else:
        tris, normals = _thin(tris, normals, eye, max_faces, per=sides - 2)
        base = base[None, :3]

    # light from the camera, tilted up and to the left so that silhouettes and creases read
    up_dir = np.array([0.0, 0.0, 1.0])
    left = np.cross(up_dir, eye)
    light = eye + 0.5 * up_dir + 0.3 * left
    light /= np.linalg.norm(light)
    shade = AMBIENT + (1.0 - AMBIENT) * np.abs(normals @ light)
    rgb = np.clip(base * shade[:, None], 0.0, 1.0)

    collection = Poly3DCollection(
        tris,
        facecolors=rgb,
        # without edges, outline each face in its own colour: hides the hairline seams of antialiasing
        edgecolors=EDGE_COLOR if edges else rgb,
        linewidths=0.3 if edges else 0.2,
    )
    ax.add_collection3d(collection)

    shown = V[np.unique(F)] if len(F) else V  # the vertices drawn: an unused one (junk a mesh may carry,
    shown = shown[np.isfinite(shown).all(axis=1)]  # NaN even, which simplify drops) does not set the view
    if len(shown):
        lo, hi = shown.min(axis=0), shown.max(axis=0)
        center, half = (lo + hi) / 2, max((hi - lo).max() / 2, 1e-12)
        ax.set_xlim(center[0] - half, center[0] + half)
        ax.set_ylim(center[1] - half, center[1] + half)
        ax.set_zlim(center[2] - half, center[2] + half)
    # equal aspect (the limits above are a cube); zoom in, as the cube's corners leave a wide margin
    ax.set_box_aspect((1, 1, 1), zoom=ZOOM)
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_axis_off()
    if title is not None:
        ax.set_title(title)

    if path is not None:
        ax.figure.savefig(path, bbox_inches="tight")
        if created:
            plt.close(ax.figure)
    return ax


def face_texture_colors(mesh, image=None) -> np.ndarray:
    """(m, 3) RGB in [0, 1] per face: the texture sampled (nearest texel) at each face's UV centroid, for
    `render`'s per-face ``color``. ``mesh``: a qemjax result with UVs (``uv``, ``wedge_faces``,
    ``material``) or a trimesh with `TextureVisuals`; ``image``: a PIL image, an image file's path or an
    (h, w, 3) array (default: the material's)."""
    if getattr(mesh, "wedge_faces", None) is not None:
        uv, corners, material = mesh.uv, np.asarray(mesh.wedge_faces), mesh.material
    else:  # (a result without UVs has no wedges; a trimesh without them, other visuals)
        visual = getattr(mesh, "visual", None)
        uv, corners, material = getattr(visual, "uv", None), np.asarray(mesh.faces), getattr(visual, "material", None)
    if uv is None:
        raise ValueError("the mesh carries no UVs")
    if image is None:
        image = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
    if image is None:
        raise ValueError("no texture image: give image=")
    tex = _texels(image)
    h, w = tex.shape[:2]
    c = np.asarray(uv, np.float64)[corners].mean(axis=1)
    x = np.clip((c[:, 0] % 1.0) * w, 0, w - 1).astype(int)
    y = np.clip((1.0 - c[:, 1] % 1.0) * h, 0, h - 1).astype(int)  # v points up, image rows down
    return tex[y, x]


def _texels(image) -> np.ndarray:
    """(h, w, 3) RGB in [0, 1] of a PIL image, an image file's path, or an (h, w, 3|4) array (integers 0..255,
    or floats 0..1); ValueError for anything else (a path or an array raised AttributeError: no .convert)."""
    import os

    if isinstance(image, (str, os.PathLike)):
        from PIL import Image

        with Image.open(image) as opened:
            image = opened.convert("RGB")
    if hasattr(image, "convert"):
        return np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
    tex = np.asarray(image)
    if tex.ndim != 3 or tex.shape[2] not in (3, 4) or not (np.issubdtype(tex.dtype, np.integer)
                                                           or np.issubdtype(tex.dtype, np.floating)):
        raise ValueError(f"image must be a PIL image, an image file's path or an (h, w, 3) array of RGB values, "
                         f"got {type(image).__name__} {getattr(tex, 'shape', '')}")
    scale = 255.0 if np.issubdtype(tex.dtype, np.integer) else 1.0
    return tex[..., :3].astype(np.float64) / scale


def render_pair(before, after, path=None, *, titles=None, figsize=(10, 5), dpi: int = 120, **kwargs):
    """Draw two meshes side by side (titled with their face counts); returns the Figure.

    ``kwargs`` go to :func:`render` (view, color, edges, up, max_faces); ``titles`` and ``colors`` (per-face
    colours, as `render`'s ``color``) take two, (before, after). When ``path`` is given the figure is saved
    there and closed. ``figsize``, ``dpi``: the figure's size (inches) and resolution.
    """
    plt, _ = _pyplot()
    meshes = [_as_arrays(before), _as_arrays(after)]
    colors = kwargs.pop("colors", None)  # optional (before, after) per-face colours
    if titles is None:
        titles = [f"before: {len(meshes[0][1]):,} faces", f"after: {len(meshes[1][1]):,} faces"]
    # one each: zip stopped at the shorter, so a single title drew the first mesh alone, without a word
    for name, value in (("titles", titles), ("colors", colors)):
        if value is not None and (isinstance(value, str) or len(value) != 2):
            raise ValueError(f"render_pair: {name} takes two, one for each mesh (before, after), got {value!r}")
    fig = plt.figure(figsize=figsize, dpi=dpi)
    for i, (mesh, title) in enumerate(zip(meshes, titles)):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        if colors is not None:
            kwargs["color"] = colors[i]
        render(mesh, ax, title=title, **kwargs)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, bbox_inches="tight")
        plt.close(fig)
    return fig
