"""`built_loops`: an install's compiled loops are copied into a checkout only where every source is the same."""
from __future__ import annotations

import base64
import hashlib
from pathlib import Path

import pytest
from built_loops import copy_into, installed

SOURCES = {"qemjax/__init__.py": b"x = 1\n", "qemjax/_mesh/grid.py": b"def f():\n    return 2\n"}
BUILT = {"qemjax/_mesh/__pycache__/grid.f-1.py311.nbi": b"index", "qemjax/_mesh/__pycache__/grid.f-1.py311.0.nbc": b"code"}


def _site(tmp: Path, built=BUILT) -> Path:
    """A site-packages folder holding qemjax 0.0 as a wheel installs it: its files and a RECORD of them."""
    site = tmp / "site"
    rows = []
    for name, data in {**SOURCES, **built}.items():
        (site / name).parent.mkdir(parents=True, exist_ok=True)
        (site / name).write_bytes(data)
        digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
        rows.append(f"{name},sha256={digest},{len(data)}")
    info = site / "qemjax-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: qemjax\nVersion: 0.0\n")
    (info / "RECORD").write_text("\n".join(rows + ["qemjax-0.0.dist-info/RECORD,,"]) + "\n")
    return site


def _checkout(tmp: Path, sources=SOURCES) -> Path:
    repo = tmp / "repo"
    for name, data in sources.items():
        (repo / name).parent.mkdir(parents=True, exist_ok=True)
        (repo / name).write_bytes(data)
    return repo


def test_the_same_sources_get_the_built_loops(tmp_path):
    dist = installed([str(_site(tmp_path))])
    repo = _checkout(tmp_path)
    assert copy_into(dist, repo) == 2
    for name, data in BUILT.items():
        assert (repo / name).read_bytes() == data
    assert copy_into(dist, repo) == 0  # already there: kept


def test_a_file_already_there_is_kept(tmp_path):
    dist = installed([str(_site(tmp_path))])
    repo = _checkout(tmp_path)
    mine = repo / next(iter(BUILT))
    mine.parent.mkdir(parents=True)
    mine.write_bytes(b"compiled here")
    assert copy_into(dist, repo) == 1
    assert mine.read_bytes() == b"compiled here"


@pytest.mark.parametrize("change", ["edited", "added", "removed"])
def test_any_other_source_gets_nothing(tmp_path, change):
    sources = dict(SOURCES)
    if change == "edited":  # a callee's module edited: its callers' cached code would run the old one
        sources["qemjax/_mesh/grid.py"] = b"def f():\n    return 3\n"
    elif change == "added":
        sources["qemjax/new.py"] = b""
    else:
        del sources["qemjax/__init__.py"]
    dist = installed([str(_site(tmp_path))])
    repo = _checkout(tmp_path, sources)
    assert copy_into(dist, repo) == 0
    assert not list(repo.rglob("*.nb[ic]"))


def test_an_install_without_compiled_loops_gets_nothing(tmp_path):
    dist = installed([str(_site(tmp_path, built={}))])
    repo = _checkout(tmp_path)
    assert copy_into(dist, repo) == 0
    assert installed([str(tmp_path / "nowhere")]) is None
