"""The scripts of experiments/ as tools: each answers ``--help`` without running, and a quick run leaves the
results files the docs cite alone."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
# scripts whose options another script parses (late_shape hands its arguments to figures/rank_peers.py)
DELEGATE = {"late_shape.py"}


def _programs():
    return sorted(p for p in EXPERIMENTS.rglob("*.py") if 'if __name__ == "__main__":' in p.read_text())


def test_every_script_parses_its_options():
    """A script run as a program parses its command line with argparse, so that ``--help`` prints its
    docstring and exits instead of running the whole experiment."""
    programs = _programs()
    assert len(programs) > 80
    silent = [str(p.relative_to(ROOT)) for p in programs
              if p.name not in DELEGATE and "ArgumentParser" not in p.read_text()]
    assert not silent


@pytest.mark.parametrize("script", ["meshes.py", "figures/appearance.py", "figures/docs_figures.py",
                                    "figures/refit_uv.py", "probes/shape_gate.py"])
def test_help_prints_the_docstring_and_exits(script):
    run = subprocess.run([sys.executable, str(EXPERIMENTS / script), "--help"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage:")
    first = (EXPERIMENTS / script).read_text().split('"""')[1].split()[:3]
    assert " ".join(first) in " ".join(run.stdout.split())

