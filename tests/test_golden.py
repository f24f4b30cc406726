"""Golden outputs: `qemjax.simplify` must keep giving bit-identical results on the cases of golden_cases.py
(hashes in golden_hashes.json, written by experiments/golden.py). Shared-mesh cases skip where
../shared/meshes is absent; the generated-mesh cases always run."""
from __future__ import annotations

from pathlib import Path

import golden_cases as gc
import pytest
from conftest import shared_mesh

import qemjax

CASES = gc.cases()
FILE = gc.load_golden()
GOLDEN = FILE["cases"]
CPUS = FILE.get("versions", {}).get("cpus")


def test_golden_file_lists_exactly_the_cases():
    ids = [c.id for c in CASES]
    missing = [i for i in ids if i not in GOLDEN]
    stale = [i for i in GOLDEN if i not in ids]
    assert not missing and not stale, (
        f"{gc.HASHES.name} is out of step with golden_cases.py: no hash for {missing}, no case for {stale}. "
        f"After a deliberate change of the case list: {gc.REGENERATE}")


@pytest.mark.filterwarnings("ignore:stopped at")  # beetle, truck, suzanne stop above the target: expected
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c.shared else c for c in CASES],
                         ids=[c.id for c in CASES])  # real meshes: the slow tier; generated ones: the fast tier too
def test_golden(case):
    if case.shared:
        shared_mesh(case.mesh)  # skips when ../shared/meshes lacks the file
    want = GOLDEN.get(case.id)
    if want is None:
        pytest.fail(f"{case.id}: no golden hash in {gc.HASHES.name}; add it with {gc.REGENERATE}")
    got = gc.run(case, shared_mesh)
    assert got["hash"] == want["hash"], (
        f"{case.id}: the outputs of qemjax.simplify({case.mesh!r}, **{case.kwargs}) changed "
        f"(hash {want['hash']} -> {got['hash']}, faces_out {want['faces_out']} -> {got['faces_out']}, "
        f"contractions {want.get('contractions')} -> {got['contractions']}). They must stay bit-identical; "
        f"if the change is deliberate, regenerate: {gc.REGENERATE}  [qemjax from {Path(qemjax.__file__).parent}; "
        f"hashes made with {CPUS} usable CPUs, this process has {gc.usable_cpus()}]")
