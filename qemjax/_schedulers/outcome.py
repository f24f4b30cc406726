"""Why contractions are refused and why a run stopped: the codes both schedulers report.

A pair found invalid carries the first rule it broke (``REJECT``); a run ends with one of ``STOPS``:

- ``"target"``: the face target is met, or only the documented parity case is left (a closed manifold
  loses faces in pairs, so with one face to go every contraction would overshoot);
- ``"max_error"``: the cheapest remaining contraction costs more than ``max_error``;
- ``"blocked"``: no valid contraction is left (`blocked_by` says which rules hold the rest back);
- ``"unchanged"``: nothing was asked to be removed (the target is not below the input's faces).
"""
from __future__ import annotations

import numpy as np

BUDGET = 0  # not a rule broken: a pair held back only because it would remove more faces than are still needed
TOPOLOGY, COINCIDENT, FLIP, PART, SEAM = 1, 2, 3, 4, 5
REJECT = {TOPOLOGY: "topology", COINCIDENT: "coincident", FLIP: "flip", PART: "vanishing_part",
          SEAM: "seam"}  # seam: would move a seam vertex off its seam or merge wedges (`_wedges`)
STOPS = ("target", "max_error", "blocked", "unchanged")


def count_reasons(codes: np.ndarray) -> dict:
    """{reason name: number of pairs} for reason codes (0 = none, not counted)."""
    c = np.bincount(np.asarray(codes, np.int64), minlength=len(REJECT) + 1)
    return {name: int(c[code]) for code, name in REJECT.items()}


def classify(faces_left: int, target: int, bad: np.ndarray, removes: np.ndarray, over_cost: np.ndarray,
             manifold_ok: np.ndarray) -> tuple[str, dict]:
    """The stop reason and what blocked the run, from the pairs left when no contraction was taken.

    bad (P,) int8 rejection codes; removes (P,) faces each pair would remove; over_cost (P,) bool: costs
    more than max_error; manifold_ok (P,) bool: a pair the mode may contract at all (in manifold mode,
    edges with one or two faces). Returns (stop reason, blocked_by counts)."""
    need = faces_left - target
    if need <= 0:
        return "target", {}
    live = manifold_ok & (bad == 0)
    blocked = count_reasons(bad[manifold_ok])
    blocked["face_budget"] = int(np.sum(live & (removes > need)))
    blocked["max_error"] = int(np.sum(live & (removes <= need) & over_cost))
    blocked["non_manifold"] = int(np.sum(~manifold_ok))
    if blocked["max_error"]:
        return "max_error", blocked
    return "blocked", blocked


def parity_only(faces_left: int, target: int, closed: bool) -> bool:
    """True for the documented case: a closed mesh one face above the target (every edge contraction
    there removes two faces, so none fits)."""
    return closed and faces_left == target + 1
