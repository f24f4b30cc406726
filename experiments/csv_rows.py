"""Appending result rows to a CSV under experiments/results (the header written when the file is new)."""
from __future__ import annotations

import csv
from pathlib import Path


def append(path: Path, rows: list[dict]) -> None:
    """Append ``rows`` (dicts with the same keys) to ``path``; a new file gets the keys as its header."""
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        if new:
            w.writeheader()
        w.writerows(rows)
