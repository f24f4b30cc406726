"""A copy of the package under another name runs its own modules (experiments/ab_compare.py compares old
code with new in one process this way): no absolute ``qemjax.`` module names inside the package."""
from __future__ import annotations

import importlib
import shutil
import sys
from pathlib import Path

import qemjax


def test_a_renamed_copy_uses_its_own_schedulers_and_submodules(tmp_path):
    shutil.copytree(Path(qemjax.__file__).parent, tmp_path / "qemjax_copy",
                    ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, str(tmp_path))
    try:
        copy = importlib.import_module("qemjax_copy")
        sch = importlib.import_module("qemjax_copy._schedulers")
        for name in sch.names():
            assert sch.get(name).__module__.startswith("qemjax_copy."), name
        assert copy.shapes.__name__ == "qemjax_copy.shapes"
    finally:
        sys.path.remove(str(tmp_path))
        for k in [k for k in sys.modules if k == "qemjax_copy" or k.startswith("qemjax_copy.")]:
            del sys.modules[k]
