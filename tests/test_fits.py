"""A mesh too large for one process (`qemjax._pipeline.fits`): refused before it is read, with the way to run
it partitioned, unless ``partition=False`` / ``--no-partition`` asks for one process regardless. The
machine's available memory is replaced by a small one here; the faces of each file format are counted
against what was written."""
from __future__ import annotations

import numpy as np
import pytest

import qemjax
from qemjax import _cli
from qemjax._partition.write import write_binary_ply
from qemjax._pipeline import fits
from qemjax.shapes import icosphere


@pytest.fixture
def small_machine(monkeypatch):
    """A machine with 1 MiB available: a mesh of more than 2,048 faces needs more (`fits.BYTES_PER_FACE`)."""
    monkeypatch.setattr(fits, "available", lambda: 1 << 20)


def test_available_memory_is_read():
    room = fits.available()
    assert room is not None and 0 < room < 1 << 50


def test_a_mesh_too_large_is_refused_before_it_is_read(tmp_path, monkeypatch):
    # a PLY whose header declares 3,000 faces and whose body is missing: the reader would call it truncated.
    # 1 KiB available: less than the faces its 203 bytes could hold need, so its header is read
    monkeypatch.setattr(fits, "available", lambda: 1 << 10)
    path = tmp_path / "big.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1500\nproperty float x\n"
                     b"property float y\nproperty float z\nelement face 3000\nproperty list uchar int "
                     b"vertex_indices\nend_header\n")
    with pytest.raises(fits.TooLargeError) as err:
        qemjax.simplify(str(path), ratio=0.5)
    text = str(err.value)
    assert isinstance(err.value, MemoryError) and isinstance(err.value, ValueError)
    assert "\n" not in text and "3,000 faces" in text and "--partition" in text and "partition=False" in text
    with pytest.raises(ValueError, match="truncated|damaged") as err:  # regardless: read, and found wanting
        qemjax.simplify(str(path), ratio=0.5, partition=False)
    assert not isinstance(err.value, fits.TooLargeError)


def test_arrays_too_large_are_refused_and_run_when_asked(small_machine):
    V, F = icosphere(4)  # 5,120 faces
    with pytest.raises(fits.TooLargeError, match="5,120 faces"):
        qemjax.simplify((V, F), target_faces=500)
    res = qemjax.simplify((V, F), target_faces=500, partition=False)
    assert len(res.faces) == 500
    small = icosphere(2)  # 320 faces: within the 1 MiB
    assert len(qemjax.simplify(small, target_faces=100).faces) == 100


def test_the_command_line_refuses_and_runs_with_no_partition(tmp_path, small_machine, capsys):
    V, F = icosphere(4)
    src, out = tmp_path / "sphere.ply", tmp_path / "out.ply"
    write_binary_ply(src, V.astype(np.float32), F.astype(np.int32))
    assert _cli.main(["simplify", str(src), str(out), "--faces", "500"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("qemjax: error: ") and "5,120 faces" in err and "--partition" in err
    assert len(err.splitlines()) == 1 and not out.exists()
    assert _cli.main(["simplify", str(src), str(out), "--faces", "500", "--no-partition"]) == 0
    assert out.exists()
    levels = tmp_path / "levels"
    assert _cli.main(["lod", str(src), str(levels), "--ratios", "0.5", "0.2"]) == 2
    err = capsys.readouterr().err  # not the partitioned run, which lod does not offer
    assert "lod_chain (qemjax lod) runs in one process" in err and "run it partitioned" not in err
    assert "--no-partition" in err and not any(levels.glob("*lod*"))
    off = tmp_path / "sphere.off"  # a format a partitioned run does not read: not offered either
    off.write_text(f"OFF\n{len(V)} {len(F)} 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in V)
                   + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))
    assert _cli.main(["simplify", str(off), str(out), "--faces", "500"]) == 2
    err = capsys.readouterr().err
    assert "a partitioned run reads PLY, OBJ and STL files" in err and "--no-partition" in err
    assert _cli.main(["lod", str(src), str(levels), "--ratios", "0.5", "0.2", "--no-partition"]) == 0
    assert len(list(levels.glob("sphere-lod*"))) == 2


@pytest.mark.parametrize("block", [1, 2, 5, 1 << 24])
def test_the_faces_of_each_format_are_counted(tmp_path, monkeypatch, block):
    """Every format's count equals the faces written, whatever the blocks the counted ones are read in (a
    face line cut at a block's end counted once)."""
    monkeypatch.setattr(fits, "_BLOCK", block)
    V, F = icosphere(2)
    obj = tmp_path / "m.obj"
    obj.write_text("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F[:3])  # face lines first: the start
                   + "".join(f"v {x} {y} {z}\n" for x, y, z in V) + "# f not a face\n"
                   + "".join(f"f\t{a + 1} {b + 1} {c + 1}\r\n" for a, b, c in F[3:]))
    assert fits.file_faces(obj) == len(F)
    ply = tmp_path / "m.ply"
    write_binary_ply(ply, V.astype(np.float32), F.astype(np.int32))
    assert fits.file_faces(ply) == len(F)
    import trimesh

    mesh = trimesh.Trimesh(V, F, process=False)
    for name, kind in (("b.stl", "stl"), ("a.stl", "stl_ascii"), ("m.off", "off")):
        (tmp_path / name).write_bytes(_export(mesh, kind))
        assert fits.file_faces(tmp_path / name) == len(F), name
    assert fits.file_faces(tmp_path / "missing.obj") is None
    (tmp_path / "m.glb").write_bytes(b"glTF")
    assert fits.file_faces(tmp_path / "m.glb") is None


def _export(mesh, kind):
    data = mesh.export(file_type=kind)
    return data.encode() if isinstance(data, str) else data


def test_a_small_file_is_not_counted(tmp_path, monkeypatch):
    """A file that fits however many faces its bytes could hold is not read for its count."""
    V, F = icosphere(2)
    path = tmp_path / "m.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    monkeypatch.setattr(fits, "file_faces", lambda p: pytest.fail("a small file was counted"))
    assert fits.faces_of(str(path), fits.available()) is None
    fits.check(str(path))  # the whole check, on this machine: nothing counted, nothing refused
    monkeypatch.setattr(fits, "file_faces", lambda p: 7)
    assert fits.faces_of(str(path), 1 << 10) == 7
