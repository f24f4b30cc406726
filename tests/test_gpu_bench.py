"""`experiments/figures/gpu_bench.py` keeps working (issue 42): on a machine without an accelerator it reports the CPU
column alone, with the kernel's rows and whole runs whose outputs are the same bits run to run."""
from __future__ import annotations

import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments" / "figures"


def test_gpu_bench_reports_kernels_and_runs(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    import gpu_bench

    out = tmp_path / "bench.md"
    assert gpu_bench.main(["--meshes", "bumpy-2", "--repeats", "1", "--out", str(out)]) == 0
    text = out.read_text()
    import jax
    if jax.default_backend() == "cpu":
        assert "(no accelerator: one column, the CPU's)" in text
    kernel_rows = [line for line in text.splitlines() if line.startswith("| place_pairs |")]
    assert [row.split("|")[2].strip() for row in kernel_rows] == ["256", "4096", "65536"]
    runs = [line for line in text.splitlines() if line.startswith("| bumpy-2 |")]
    assert [row.split("|")[3].strip() for row in runs] == ["default", "classic"]
    assert all(row.rstrip(" |").endswith("yes") for row in runs) or jax.default_backend() != "cpu"
    sys.modules.pop("gpu_bench", None)
