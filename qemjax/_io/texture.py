"""Texture images written as they were read.

trimesh writes a material's texture image by encoding it again in its format (an OBJ's image beside it,
a GLB's packed in); for JPEG and WebP that encoding is lossy at its default quality, so a texture that
simplification never changes came back with other pixels. `remember_read` keeps the bytes a texture was
decoded from when a file is read (`load` those of a texture given as a file), and `verbatim` gives a
copy of a material whose image trimesh then writes as those bytes, where its pixels are still theirs.
"""
from __future__ import annotations

import io

import numpy as np

SOURCE = "qemjax_source_bytes"  # key in the PIL image's info: the encoded file it was read from
_LOSSY = ("JPEG", "WEBP")  # formats whose writing by trimesh (PIL's default quality) changes pixels


def _images(material) -> list:
    return [getattr(material, k) for k in ("image", "baseColorTexture") if getattr(material, k, None) is not None]


def remember(image, data: bytes) -> None:
    """Keep ``data`` (the encoded file) with ``image`` when its format is one trimesh writes lossily."""
    if getattr(image, "format", None) in _LOSSY and isinstance(getattr(image, "info", None), dict):
        image.info[SOURCE] = bytes(data)


def load(texture):
    """`_mesh.wedges.load_texture` of ``texture`` (a path or a PIL image), a file's bytes kept (`remember`)."""
    import os

    from .._mesh.wedges import load_texture

    material = load_texture(texture)
    if isinstance(texture, (str, os.PathLike)):
        with open(texture, "rb") as f:
            remember(material.image, f.read())
    return material


def remember_read(obj) -> None:
    """Keep the bytes each texture image of a mesh trimesh just read was decoded from: PIL holds the
    stream trimesh opened it from until its pixels are first loaded."""
    for image in _images(getattr(getattr(obj, "visual", None), "material", None)):
        fp = getattr(image, "fp", None)
        if isinstance(fp, io.BytesIO):
            remember(image, fp.getvalue())


def _unchanged_source(image) -> bytes | None:
    """The bytes ``image`` was read from, when they decode to its format, mode, size and pixels; else None."""
    data = getattr(image, "info", {}).get(SOURCE)
    if data is None or image.format not in _LOSSY:
        return None
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as src:
            same = (src.format == image.format and src.mode == image.mode and src.size == image.size
                    and np.array_equal(np.asarray(src), np.asarray(image)))
    except Exception:  # not an image PIL reads back: encode the pixels as trimesh does
        return None
    return data if same else None


def verbatim(material):
    """A copy of ``material`` (trimesh's) whose JPEG or WebP texture image, written by trimesh in its own
    format, is the bytes it was read from, when its pixels are still theirs; otherwise written as trimesh
    writes it. ``material`` itself is left as it is."""
    if material is None or not any(SOURCE in getattr(i, "info", {}) for i in _images(material)):
        return material
    out = material.copy()
    for image in _images(out):
        data = _unchanged_source(image)
        if data is None:
            continue
        encode = image.save

        def save(fp, format=None, image=image, data=data, encode=encode, **params):
            if hasattr(fp, "write") and str(format).upper() == image.format and not params:
                fp.write(data)
            else:
                encode(fp, format, **params)

        image.save = save  # on this copy's image only: trimesh calls image.save(file, format=...)
    return out
