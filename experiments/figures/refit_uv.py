"""Why the default's re-fit is skipped when UVs are kept: texture-space deviation of the textured example
(`qemjax.shapes.write_examples(subdivisions=3)`, 1,280 faces, six UV charts) simplified to 25 % with and
without the re-fit, and with the re-fit forced on (positions moved, UVs left as they are).

    python experiments/figures/refit_uv.py

The forced rows run the re-fit on the kept-UV result's own faces (`qemjax._pipeline.refit.refit`, seam
vertices held as the default holds them) and measure what the UVs would then map to.
"""
from __future__ import annotations

import dataclasses
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import qemjax  # noqa: E402
from qemjax import metrics  # noqa: E402
from qemjax._pipeline import refit as _refit  # noqa: E402


def main() -> None:
    warnings.simplefilter("ignore")
    folder = Path(tempfile.mkdtemp())
    qemjax.shapes.write_examples(folder, subdivisions=3)
    path, png = folder / "textured.obj", folder / "textured.png"
    lines = ["| run | refit rounds run | uv_dev_rms | rms_rel (geometry) |", "|---|---|---|---|"]
    m = qemjax.load(path)
    for label, kw in (("classic", dict(method="classic")), ("default (re-fit skipped: UVs kept)", {}),
                      ("default, refit=0", dict(refit=0))):
        r = qemjax.simplify(path, ratio=0.25, texture=png, **kw)
        d = metrics.attribute_deviation(path, r, n_samples=3000)["uv_dev_rms"]
        g = metrics.surface_distance(m, r)["rms_rel"]
        lines.append(f"| {label} | {r.stats['refit']} | {d:.4f} | {g:.3g} |")
        if label.startswith("default ("):
            seam = np.bincount(r.wedge_vertex, minlength=len(r.vertices)) > 1
            X = _refit.refit(r.input_vertices, r.input_faces, r.vertices, r.faces, 1, 0.0, None, r.source_faces,
                             fixed=seam)
            forced = dataclasses.replace(r, vertices=X)
            d = metrics.attribute_deviation(path, forced, n_samples=3000)["uv_dev_rms"]
            g = metrics.surface_distance(m, forced)["rms_rel"]
            lines.append(f"| default with the re-fit forced (seams held, UVs unchanged) | 1 | {d:.4f} | {g:.3g} |")
    text = "# python experiments/figures/refit_uv.py\n\n" + "\n".join(lines) + "\n"
    print(text)
    (ROOT / "experiments" / "results" / "refit_uv.md").write_text(text)


if __name__ == "__main__":
    main()
