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
