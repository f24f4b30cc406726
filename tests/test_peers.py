"""Peers (`qemjax.peers`) as methods of `qemjax.sweep`: same cells, same columns, same metric function."""
import builtins

import numpy as np
import pytest

import qemjax
from qemjax import peers
from qemjax.metrics import evaluate

MESH = {"sphere": qemjax.shapes.bumpy_sphere(subdivisions=3)}


@pytest.mark.parametrize("name", list(peers.PEERS))
def test_peer_in_a_sweep_beside_qemjax(name):
    pytest.importorskip(peers._MODULES[name])
    df = qemjax.sweep(MESH, {"method": ["qem", name], "boundary_weight": [1000.0]}, [0.1], progress=False)
    qem, peer = df.iloc[0], df.iloc[1]
    assert list(df["method"]) == ["qem", name] and (df["error"] == "").all()
    # same columns, every metric set for both
    assert qem.index.equals(peer.index)
    assert np.isfinite(peer["rms_rel"]) and np.isfinite(peer["hausdorff_rel"]) and peer["run_s"] > 0
    # a setting the peer has no such thing as is marked "n/a" (not NaN, which means None)
    assert peer["stop_reason"] == "peer" and peer["boundary_weight"] == "n/a" and qem["boundary_weight"] == 1000.0
    assert abs(peer["faces_out"] - qem["target_faces"]) <= 0.05 * qem["target_faces"]
    # the peer's output measured by the same function as qemjax's
    res = peers.simplify(name, qemjax._io.mesh.as_arrays(MESH["sphere"]), int(peer["target_faces"]))
    direct = evaluate(qemjax._io.mesh.as_arrays(MESH["sphere"]), res, target_faces=int(peer["target_faces"]))
    assert peer["rms_rel"] == pytest.approx(direct["rms_rel"], rel=1e-12)
    assert peer["hausdorff_rel"] == pytest.approx(direct["hausdorff_rel"], rel=1e-12)
    F = res.faces
    assert F.min() >= 0 and F.max() < len(res.vertices) and len(res.faces) == peer["faces_out"]


def test_peer_results_compare_by_identity():
    """A `PeerResult` holds arrays: `==` raised numpy's "truth value of an array is ambiguous"."""
    V, F = qemjax.shapes.icosphere(1)
    a, b = peers.PeerResult(V, F, {}), peers.PeerResult(V.copy(), F.copy(), {})
    assert a == a and a != b and len({a, b, a}) == 2


def test_missing_peer_is_a_one_line_error_naming_the_extra(monkeypatch):
    real = builtins.__import__

    def fake(name, *args, **kwargs):
        if name.split(".")[0] == "pymeshlab":
            raise ImportError("No module named 'pymeshlab'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake)
    monkeypatch.setattr(peers.importlib, "import_module", lambda n: fake(n))
    assert "pymeshlab" not in peers.available()
    V, F = qemjax._io.mesh.as_arrays(MESH["sphere"])
    with pytest.raises(ValueError, match=r"pip install 'qemjax\[bench\]'") as err:
        peers.simplify("pymeshlab", (V, F), 100)
    assert "\n" not in str(err.value) and "pymeshlab" in str(err.value)
    df = qemjax.sweep(MESH, {"method": ["pymeshlab"]}, [0.1], progress=False, metrics=False)
    assert "qemjax[bench]" in df["error"].iloc[0]
    with pytest.raises(ValueError, match="unknown peer"):
        peers.simplify("nope", (V, F), 100)


def test_the_sweeps_peer_names_are_the_peers():
    """`_sweep` names the peers without importing `qemjax.peers` (lazy); the two lists must agree."""
    from qemjax._sweep import run as _sweep

    assert sorted(_sweep.PEER_NAMES) == sorted(peers.PEERS)


def test_a_peer_cell_runs_on_the_cleaned_input_as_a_qemjax_cell_does(tmp_path):
    """A mesh with repeated faces: a peer's cell gets the cleaned input a qemjax cell runs on, so its ratio
    target is the same (it was taken of the raw faces, a third more here); and a config file may name a
    peer as a method."""
    name = next(iter(peers.available()), None)
    if name is None:
        pytest.skip("no peer installed")
    V, F = qemjax.shapes.torus(n_major=24, n_minor=12)
    doubled = (V, np.vstack([F, F[: len(F) // 3]]))
    df = qemjax.sweep({"dup": doubled}, {"method": ["qem", name]}, [0.2], metrics=False, progress=False, workers=1)
    assert (df["error"] == "").all()
    assert df["faces_in"].nunique() == 1 and df["faces_in"].iloc[0] == len(F)
    assert df["target_faces"].nunique() == 1 and df["target_faces"].iloc[0] == round(0.2 * len(F))
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "p.toml"
    cfg.write_text(f'meshes = ["shapes.torus"]\ntargets = [0.5]\n[grid]\nmethod = ["qem", "{name}"]\n')
    assert _sweep_config.load(cfg).grid["method"] == ["qem", name]


@pytest.mark.parametrize("name", ["meshoptimizer", "libigl", "pyfqmr"])
def test_a_malformed_mesh_is_refused_before_a_peer_sees_it(name):
    """An index out of range or faces that are not triangles crashed the interpreter inside meshoptimizer and
    libigl (a segfault): refused here in words, installed or not, as is a target below 1."""
    V, F = qemjax.shapes.icosphere(2)
    with pytest.raises(ValueError, match=r"face indices must lie in \[0, 162\)"):
        peers.simplify(name, (V, F + 5), 100)
    with pytest.raises(ValueError, match=r"faces must have shape \(m, 3\)"):
        peers.simplify(name, (V, np.c_[F, F[:, 0]]), 100)
    with pytest.raises(ValueError, match="target_faces must be a whole number of at least 1"):
        peers.simplify(name, (V, F), -5)


@pytest.mark.parametrize("name", list(peers.PEERS))
def test_a_target_above_the_faces_is_the_whole_mesh_as_for_qemjax(name):
    """A target at or above the input's faces: fast-simplification raised its own "target_reduction must be
    between 0 and 1" for it, and every peer's row reported the target asked for where qemjax's reports the
    faces there are (`simplify` returns the mesh unchanged): the same target_faces (and target_error) now."""
    pytest.importorskip(peers._MODULES[name])
    V, F = qemjax.shapes.icosphere(2)
    res = peers.simplify(name, (V, F), 10 * len(F))
    assert res.stats["target_faces"] == len(F) and 0 < len(res.faces) <= len(F)
    if name == "fast-simplification":
        assert len(res.faces) == len(F)
        V2, F2 = peers.simplify_fast_simplification(V, F, 10 * len(F))
        assert len(F2) == len(F)



@pytest.mark.parametrize("name", list(peers.PEERS))
def test_a_peer_runs_a_mesh_far_from_its_range_in_a_frame_of_its_own(name):
    """At 1e40 mesh units meshoptimizer, fast-simplification and pyfqmr returned the input unchanged (their
    squared lengths overflowed), at 1e-40 they lost detail, and libigl's error was many times worse 1e8 units
    from the origin: such a mesh runs centred and scaled by a power of two, its output taken back to the
    input's units; a mesh of ordinary extent runs as it is (the same bits as the adapter's own call)."""
    pytest.importorskip(peers._MODULES[name])
    V, F = qemjax.shapes.icosphere(3)
    plain = peers.simplify(name, (V, F), 100)
    V2, F2 = peers.PEERS[name](V, F, 100)
    assert np.array_equal(plain.vertices, V2) and np.array_equal(plain.faces, F2)
    ref = evaluate((V, F), plain, n_samples=4000)["hausdorff_rel"]
    for scale, offset in ((1e40, 0.0), (1e-40, 0.0), (1.0, 1e8)):
        W = V * scale + offset
        res = peers.simplify(name, (W, F), 100)
        assert len(res.faces) <= 110, (scale, offset, len(res.faces))
        assert np.all(np.abs(res.vertices - offset) <= 1.1 * scale)  # in the input's units, about the sphere
        assert evaluate((W, F), res, n_samples=4000)["hausdorff_rel"] < 2 * ref, (scale, offset)
    # a vertex no face uses, far away, sets no frame: the mesh runs as it is
    Vfar = np.vstack([V, [[1e10, 0.0, 0.0]]])
    far, (V2, F2) = peers.simplify(name, (Vfar, F), 100), peers.PEERS[name](Vfar, F, 100)
    assert np.array_equal(far.vertices, V2) and np.array_equal(far.faces, F2)


@pytest.mark.parametrize("target", [float("inf"), float("nan"), None, "abc", "10", 2.5, True, [10]])
def test_a_target_that_is_not_a_whole_number_is_refused_in_words(target):
    """An infinite, missing or text target raised float's or int's own error ("cannot convert float infinity
    to integer", "float() argument must be ..."), and a numeric string was taken as a number."""
    V, F = qemjax.shapes.icosphere(2)
    with pytest.raises(ValueError, match="^target_faces must be a whole number of at least 1, got "):
        peers.simplify("meshoptimizer", (V, F), target)


@pytest.mark.parametrize("name", ["meshoptimizer", "libigl"])
def test_the_public_adapters_check_the_mesh_as_simplify_does(name):
    """`run_peer` and the adapters (`simplify_meshoptimizer`, ...) are public too, and handed faces out of range
    to the peer's C code, which crashed the interpreter (a segfault); `run_peer` of an unknown name raised
    PEERS' KeyError. Run in a child process, so that a crash is a failure here, not the end of the session."""
    import subprocess
    import sys

    pytest.importorskip(peers._MODULES[name])
    adapter = "simplify_" + name.replace("-", "_")
    code = f"""
import qemjax
from qemjax import peers
V, F = qemjax.shapes.icosphere(2)
for call in (lambda: peers.run_peer({name!r}, V, F + 5, 100), lambda: peers.{adapter}(V, F + 5, 100),
             lambda: peers.run_peer("meshopt", V, F, 100)):
    try:
        call()
    except ValueError as exc:
        print(str(exc).splitlines()[0])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines() == ["mesh: face indices must lie in [0, 162), got [5, 166]"] * 2 + [
        f"unknown peer 'meshopt'; peers are {list(peers.PEERS)}"]
