"""The command line."""
from __future__ import annotations

import trimesh

from qemjax import _cli, shapes


def test_simplify_command(tmp_path, capsys):
    V, F = shapes.bumpy_sphere(3)
    src, dst = tmp_path / "in.ply", tmp_path / "out.obj"
    trimesh.Trimesh(V, F, process=False).export(src)
    assert _cli.main(["simplify", str(src), str(dst), "--faces", "200", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "1280 -> 200" in out and "max error" in out
    assert len(trimesh.load(dst, process=False, force="mesh").faces) == 200


def test_simplify_command_bad_input(tmp_path, capsys):
    assert _cli.main(["simplify", str(tmp_path / "missing.obj"), str(tmp_path / "o.obj"),
                      "--ratio", "0.5", "--quiet"]) == 2
    assert "not found" in capsys.readouterr().err


def test_demo_command(tmp_path, capsys):
    dst = tmp_path / "demo.obj"
    assert _cli.main(["demo", "--output", str(dst), "--subdivisions", "4", "--quiet"]) == 0
    assert "5120 faces" in capsys.readouterr().out and dst.exists()
