"""qemjax.render draws PNGs of meshes given in any of the accepted forms."""

import numpy as np
import pytest

pytest.importorskip("matplotlib")
trimesh = pytest.importorskip("trimesh")

import matplotlib  # noqa: E402

matplotlib.use("Agg")

from qemjax.render import render, render_pair  # noqa: E402


def _icosphere():
    return trimesh.creation.icosphere(subdivisions=2)  # 320 faces


def _png_pixels(path):
    import matplotlib.image as mpimg

    return mpimg.imread(path)


def test_render_writes_a_nontrivial_png(tmp_path):
    path = tmp_path / "sphere.png"
    render(_icosphere(), path=path, edges=True)
    assert path.exists()
    assert path.stat().st_size > 2_000
    pixels = _png_pixels(path)[..., :3]
    # the sphere is drawn: a good share of pixels is not background white, and they are shaded, not flat
    drawn = pixels[(pixels < 0.98).any(axis=-1)]
    assert len(drawn) > 0.05 * pixels.shape[0] * pixels.shape[1]
    assert drawn.std() > 0.02


@pytest.mark.parametrize("form", ["trimesh", "tuple", "attributes"])
def test_render_accepts_mesh_forms(form, tmp_path):
    sphere = _icosphere()
    mesh = {
        "trimesh": sphere,
        "tuple": (np.asarray(sphere.vertices), np.asarray(sphere.faces)),
        "attributes": type("Result", (), {"vertices": sphere.vertices, "faces": sphere.faces})(),
    }[form]
    ax = render(mesh, view=(30, 45), up="z")
    assert ax.name == "3d"
    import matplotlib.pyplot as plt

    plt.close(ax.figure)


def test_render_thins_large_meshes():
    import matplotlib.pyplot as plt

    sphere = trimesh.creation.icosphere(subdivisions=4)  # 5120 faces
    ax = render(sphere, max_faces=1000)
    (collection,) = ax.collections
    assert len(collection.get_paths()) <= 1000
    plt.close(ax.figure)


def test_render_pair(tmp_path):
    sphere = _icosphere()
    coarse = trimesh.creation.icosphere(subdivisions=1)
    path = tmp_path / "pair.png"
    render_pair(sphere, coarse, path=path)
    assert path.exists() and path.stat().st_size > 2_000


def test_render_rejects_non_mesh():
    with pytest.raises(TypeError):
        render(42)


def test_face_texture_colors_of_a_mesh_without_uvs_says_so():
    """Its own ValueError, not an AttributeError from inside (a result without UVs, a trimesh without
    texture visuals)."""
    import qemjax
    from qemjax.render import face_texture_colors

    res = qemjax.simplify(qemjax.shapes.icosphere(2), ratio=0.5)
    for mesh in (res, res.to_trimesh()):
        with pytest.raises(ValueError, match="the mesh carries no UVs"):
            face_texture_colors(mesh)


def _quad_cube():
    V = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    Q = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    return V, Q


def _drawn(collection) -> set:
    """The (projected corners, face colour) of each polygon a drawn 3-D collection holds."""
    return {(tuple(map(tuple, np.round(p.vertices[:3], 6))), tuple(np.round(c, 6)))
            for p, c in zip(collection.get_paths(), collection.get_facecolors())}


def test_render_draws_quads_as_two_triangles_each():
    """(m, 4) faces were reshaped to (-1, 3): 3 quads became 4 triangles of other corners, 1 quad an error
    from numpy. Each polygon is drawn as a fan of triangles, its per-face colour on each."""
    import matplotlib.pyplot as plt

    V, Q = _quad_cube()
    for faces in (Q, Q[:3], Q[:1]):
        colors = np.linspace(0.2, 0.8, 3 * len(faces)).reshape(-1, 3)
        ax = render((V, faces), color=colors, up="z")
        ax.figure.canvas.draw()  # a 3-D collection's paths are its projected polygons, made when drawn
        (collection,) = ax.collections
        assert len(collection.get_paths()) == 2 * len(faces)
        drawn = _drawn(collection)
        plt.close(ax.figure)
        # each quad's two triangles, each in its quad's colour, drawn alike (a colour of another face fails)
        tris = np.stack([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]], 1).reshape(-1, 3)
        ax = render((V, tris), color=np.repeat(colors, 2, 0), up="z")
        ax.figure.canvas.draw()
        (want,) = ax.collections
        assert drawn == _drawn(want) and len(drawn) == 2 * len(faces)
        plt.close(ax.figure)
    with pytest.raises(ValueError, match=r"^color: 5 per-face colours for 6 faces$"):
        render((V, Q), color=np.zeros((5, 3)))


def test_render_max_faces_counts_the_faces_given():
    """``max_faces`` is a cap on the faces as given: it counted a polygon's triangles, so a quad mesh of
    ``max_faces`` quads was thinned to half its area, and thinning split quads. A quad is drawn or left out
    with both its triangles, each in its colour."""
    import matplotlib.pyplot as plt

    n = 6
    V = np.array([[x, y, 0.0] for y in range(n + 1) for x in range(n + 1)])
    Q = np.array([[i + j * (n + 1), i + 1 + j * (n + 1), i + 1 + (j + 1) * (n + 1), i + (j + 1) * (n + 1)]
                  for j in range(n) for i in range(n)])
    colors = np.stack([np.linspace(0.1, 0.9, len(Q)), np.full(len(Q), 0.5), np.full(len(Q), 0.5)], 1)
    for cap, drawn in ((len(Q), len(Q)), (len(Q) - 1, len(Q) - 1), (5, 5)):
        ax = render((V, Q), color=colors, up="z", view=(90, 0), max_faces=cap)
        (collection,) = ax.collections
        reds = np.round(collection.get_facecolors()[:, 0], 9)
        plt.close(ax.figure)
        _, counts = np.unique(reds, return_counts=True)
        assert len(reds) == 2 * drawn and len(counts) == drawn and (counts == 2).all()


@pytest.mark.parametrize("mesh, message", [
    ((np.zeros((4, 3)), np.array([[0, 1]])), r"^render: faces must be \(m, 3\) triangles or \(m, k\) polygons"),
    ((np.zeros((4, 2)), np.array([[0, 1, 2]])), r"^render: vertices must be \(n, 3\), got shape \(4, 2\)$"),
])
def test_render_refuses_what_is_not_a_mesh_by_its_shape(mesh, message):
    with pytest.raises(ValueError, match=message):
        render(mesh)


def test_render_frames_the_vertices_drawn():
    """The view is set by the vertices the faces use: junk in an unused vertex (NaN, which simplify drops, or
    a point far away) made matplotlib refuse NaN axis limits, or shrank the mesh to a dot."""
    import matplotlib.pyplot as plt

    V, Q = _quad_cube()
    ax = render((V, Q), up="z")
    want = (ax.get_xlim(), ax.get_ylim(), ax.get_zlim())
    plt.close(ax.figure)
    for junk in ([np.nan, 0.0, 0.0], [1e6, -1e6, 1e6]):
        ax = render((np.vstack([V, junk]), Q), up="z")
        assert (ax.get_xlim(), ax.get_ylim(), ax.get_zlim()) == want
        plt.close(ax.figure)


@pytest.mark.parametrize("faces, message", [
    (np.array([[0, 1, 7]]), r"^render: face indices must lie in \[0, 4\), got \[0, 7\]$"),
    (np.array([[0, 1, -1]]), r"^render: face indices must lie in \[0, 4\), got \[-1, 1\]$"),
    (np.array([[0, 1, 2.7]]), r"^render: faces must hold integer vertex indices, got dtype float64$"),
])
def test_render_refuses_faces_that_name_no_vertex(faces, message):
    """An index past the vertices raised numpy's IndexError; a negative one was drawn as the last vertex (numpy's
    indexing wraps it) and 2.7 as vertex 2 (the cast to int64 cut it), without a word."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    with pytest.raises(ValueError, match=message):
        render((V, faces))


@pytest.mark.parametrize("kwargs, message", [
    (dict(view=(10,)), r"^render: view must be \(elevation, azimuth\) in degrees, got \(10,\)$"),
    (dict(view=(10, "east")), r"^render: view must be \(elevation, azimuth\) in degrees"),
    (dict(view=(float("nan"), 0)), r"^render: view must be \(elevation, azimuth\) in degrees"),
    (dict(max_faces=-1), r"^render: max_faces must be a whole number >= 0, got -1$"),
    (dict(max_faces=2.5), r"^render: max_faces must be a whole number >= 0, got 2.5$"),
])
def test_render_refuses_a_view_or_cap_it_cannot_use(kwargs, message):
    """A one-number view raised IndexError, a text azimuth numpy's ufunc error, a negative max_faces numpy's
    'negative dimensions are not allowed' (on a mesh above the cap): each is now one line naming it."""
    with pytest.raises(ValueError, match=message):
        render(_icosphere(), **{"max_faces": 10, **kwargs})


@pytest.mark.parametrize("kwargs, name", [(dict(titles=["only"]), "titles"), (dict(titles="ab"), "titles"),
                                          (dict(titles=["a", "b", "c"]), "titles"),
                                          (dict(colors=[(1.0, 0.0, 0.0)]), "colors")])
def test_render_pair_takes_two_titles_and_colors(kwargs, name):
    """One title drew the first mesh alone (zip stopped at the shorter), without a word; a string of two
    letters was taken as two titles."""
    with pytest.raises(ValueError, match=f"^render_pair: {name} takes two, one for each mesh"):
        render_pair(_icosphere(), _icosphere(), **kwargs)


def test_render_takes_a_colour_name_and_refuses_what_is_no_colour():
    """color="red" raised numpy's "could not convert string to float", None an IndexError: a matplotlib
    colour name is now the colour it names, and what is no colour is refused in render's words."""
    import matplotlib.pyplot as plt

    shown = []
    for color in ("red", (1.0, 0.0, 0.0)):
        ax = render(_icosphere(), color=color)
        shown.append(ax.collections[0].get_facecolors())
        plt.close(ax.figure)
    np.testing.assert_array_equal(shown[0], shown[1])
    for bad, message in ((None, "color must be RGB"), ((1.0, 0.0), "color must be RGB"),
                         ("reddish", "color 'reddish' is not a colour matplotlib knows")):
        with pytest.raises(ValueError, match=f"^render: {message}"):
            render(_icosphere(), color=bad)


def test_render_draws_a_trimesh_scene():
    """`trimesh.load` of a glTF gives a Scene, which simplify and the metrics take (concatenated): render
    refused it ("expected a mesh, ... got Scene")."""
    import matplotlib.pyplot as plt

    ax = render(trimesh.Scene([_icosphere()]))
    assert len(ax.collections[0].get_facecolors()) == 320
    plt.close(ax.figure)


def test_face_texture_colors_takes_an_image_as_a_path_or_an_array(tmp_path):
    """A path or an array as ``image`` raised AttributeError ("'str' object has no attribute 'convert'"): they
    give the texels the PIL image gives, and what is no image is refused in words."""
    from PIL import Image

    from qemjax.render import face_texture_colors

    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (8, 16, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(tmp_path / "t.png")
    sphere = _icosphere()
    uv = rng.random((len(sphere.vertices), 2))
    mesh = trimesh.Trimesh(sphere.vertices, sphere.faces, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    want = face_texture_colors(mesh, Image.fromarray(pixels))
    for image in (tmp_path / "t.png", str(tmp_path / "t.png"), pixels, pixels / 255.0):
        np.testing.assert_array_equal(face_texture_colors(mesh, image), want)
    with pytest.raises(ValueError, match="^image must be a PIL image, an image file's path or an"):
        face_texture_colors(mesh, np.zeros((8, 16)))
