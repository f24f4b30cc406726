"""Named settings of `simplify` (``preset=``): a measured combination of options under one word.

A preset fills the keywords that a call leaves at their defaults; a keyword given with another value
wins over the preset (one passed with its default value cannot be told from an omitted one, so the
preset's value is used). A preset may also set fields of the cost model that `simplify` has no keyword for
(``model``): the placement's tunables ``rank_eps`` and ``max_shift``.

``"accurate"``: Lindstrom–Turk-style memoryless quadrics with 0.3 of the summed (Garland–Heckbert) ones,
the rank-aware placement with loose limits, face planes weighted by (area / mean area)^0.6, boundary
planes at weight 10, then one round of re-fitting the positions to the input (``refit=1``, `_refit`). On
the 17 shared meshes at 10 % and 1 % against meshoptimizer, fast-simplification, pyfqmr, pymeshlab and
libigl its rms is at or below the best peer's in 32 of 34 cases and its Hausdorff distance in 27 (the
default: 9 and 9), and its rms is below the default's in every case at equal face counts, at 1.3–6.5× the
default's time (``experiments/rank_peers.py``, ``experiments/refit_time.py``; README, "Placement and the
ranking against peers"). It was chosen on those same cases (the number of re-fit rounds among 1, 2, 3, 5).
"""
from __future__ import annotations

from typing import NamedTuple


class Preset(NamedTuple):
    keywords: dict  # simplify keywords
    model: dict  # cost-model fields without a simplify keyword


PRESETS = {
    "accurate": Preset(keywords=dict(memoryless=True, memory_weight=0.3, placement="rank", area_power=0.6,
                                     boundary_weight=10.0, refit=1),
                       model=dict(rank_eps=1e-3, max_shift=0.5)),
}


def apply(name: str | None, given: dict, defaults: dict) -> tuple[dict, dict]:
    """(keywords, model fields) for a call with keywords ``given`` (each keyword's value, as the call has
    it) and ``defaults`` (simplify's): the preset's values where ``given`` holds the default. None: no
    preset. ValueError for an unknown name."""
    if name is None:
        return given, {}
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {tuple(PRESETS)}")
    preset = PRESETS[name]
    out = dict(given)
    for key, value in preset.keywords.items():
        if _same(given[key], defaults[key]):
            out[key] = value
    return out, dict(preset.model)


def _same(a, b) -> bool:
    return type(a) is type(b) and a == b
