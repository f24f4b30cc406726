"""What a scheduler returns (`Outcome`, the contract every scheduler keeps), why contractions are refused and
why a run stopped: the codes every scheduler reports.

A pair found invalid carries the first rule it broke (``REJECT``); a run ends with one of ``STOPS``:

- ``"target"``: the face target is met, or only the documented parity case is left (a closed manifold
  loses faces in pairs, so with one face to go every contraction would overshoot);
- ``"max_error"``: the cheapest remaining contraction costs more than ``max_error``;
- ``"blocked"``: no valid contraction is left (`blocked_by` says which rules hold the rest back);
- ``"unchanged"``: nothing was asked to be removed (the target is not below the input's faces);
- ``"locked"``: blocked, and locked vertices hold back most of what is left (`hold_back`; given by
  `Outcome.stop_above` from ``blocked_by``).

The pipeline reads an `Outcome` through its fields and three methods: `Outcome.output` (the surviving
mesh, compacted), `Outcome.stop_above` (the stop reason of a run that ended above its face target) and
`Outcome.counts` (what the run reports in the result's stats).
"""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

BUDGET = 0  # not a rule broken: a pair held back only because it would remove more faces than are still needed
TOPOLOGY, COINCIDENT, FLIP, PART, SEAM, LOCKED = 1, 2, 3, 4, 5, 6
# seam: would move a seam vertex off its seam or merge wedges (`_wedges`); locked: both endpoints locked, or
# the contraction would leave a locked vertex in no face (`qemjax._schedulers.locks`)
REJECT = {TOPOLOGY: "topology", COINCIDENT: "coincident", FLIP: "flip", PART: "vanishing_part",
          SEAM: "seam", LOCKED: "locked"}
STOPS = ("target", "max_error", "blocked", "unchanged", "locked")


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
    # a valid pair that fits and costs little enough was held back by the budget too: in non-manifold mode the
    # faces it makes coincide go with it (a tetrahedron's edge takes all four), which ``removes`` leaves out
    blocked["face_budget"] = int(np.sum(live & ((removes > need) | ~over_cost)))
    blocked["max_error"] = int(np.sum(live & (removes <= need) & over_cost))
    blocked["non_manifold"] = int(np.sum(~manifold_ok))
    if blocked["max_error"]:
        return "max_error", blocked
    return "blocked", blocked


def parity_only(faces_left: int, target: int, closed: bool) -> bool:
    """True for the documented case: a closed mesh one face above the target (every edge contraction
    there removes two faces, so none fits)."""
    return closed and faces_left == target + 1


def hold_back(blocked_by: dict) -> bool:
    """Whether a blocked run stopped because of its locks: they hold back at least as many of the pairs
    left as every other rule together (the stop reason is then ``"locked"``)."""
    n = blocked_by.get("locked", 0)
    return n > 0 and n >= sum(v for k, v in blocked_by.items() if k != "locked")


def compact_output(V: np.ndarray, F: np.ndarray, alive_faces: np.ndarray):
    """Keep live faces and the vertices they use. Returns (V', F', kept vertex ids, kept face ids)."""
    fids = np.flatnonzero(alive_faces)
    F = F[fids]
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    ids = np.flatnonzero(used)
    newidx = np.cumsum(used) - 1
    return V[ids], newidx[F], ids, fids


class Output(NamedTuple):
    """The surviving mesh of a run (`Outcome.output`): positions (k,3) of the vertices live faces use
    (normalised units), faces (f,3) numbered into them, and the run's ids of those vertices (k,) and faces
    (f,)."""

    positions: np.ndarray
    faces: np.ndarray
    source_vertices: np.ndarray
    source_faces: np.ndarray


class History(NamedTuple):
    """The contractions in order: kept and removed vertex (k,2) int64, the kept vertex's new position
    (k,3) float64 (normalised units) and each contraction's cost (k,) float64."""

    pairs: np.ndarray
    positions: np.ndarray
    costs: np.ndarray

    @classmethod
    def empty(cls) -> "History":
        return cls(np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0))

    @classmethod
    def of(cls, steps: list) -> "History":
        """From one (kept, removed, position, cost) entry per contraction (the greedy schedulers')."""
        return cls(np.array([(a, b) for a, b, _, _ in steps], np.int64).reshape(-1, 2),
                   np.array([x for _, _, x, _ in steps], np.float64).reshape(-1, 3),
                   np.array([c for _, _, _, c in steps], np.float64))


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What every scheduler returns (the contract; `qemjax._schedulers`), in the run's normalised units.

    positions (n,3) float32 and states (n, width): every vertex's row at the end (removed ones keep
    their last); faces (m,3) int64: the input faces re-linked; alive (m,) bool: the survivors; history:
    the contractions (`History`); stop_reason: one of STOPS; blocked_by: what held back the pairs left
    (`classify`; empty when the target was met); rejected_by: pairs refused during the run, per rule
    (`count_reasons`); rejected: how many refusals; rounds: rounds run (parallel: those that contracted
    nothing too, `contracting_rounds`) or contractions (greedy);
    worst_cost: the largest cost of a contraction taken (the limit is ``Options.max_cost``); branches:
    contractions per placement branch (the model's ``branches``); stage_times: seconds per stage
    (``*_s``); faces_per_round, parts (k, p+1): the cost parts and the ranking key of each contraction
    (or None), reweights: (faces, weights) each time a model's rank weights were set; history_rounds
    (k,): each contraction's round; removed_at (m,): the contraction that removed each face (-1: none),
    coincident (m,) bool: faces dropped as coincident (`_record`); switched_at: the faces left when a
    two-phase run turned memoryless (`late`; None: it did not)."""

    positions: np.ndarray
    states: np.ndarray
    faces: np.ndarray
    alive: np.ndarray
    history: History
    stop_reason: str
    blocked_by: dict
    rejected_by: dict
    rejected: int = 0
    rounds: int = 0
    worst_cost: float = 0.0
    branches: np.ndarray = None
    stage_times: dict = dataclasses.field(default_factory=dict)
    faces_per_round: list | None = None
    parts: np.ndarray | None = None
    reweights: list = dataclasses.field(default_factory=list)
    history_rounds: np.ndarray | None = None
    removed_at: np.ndarray | None = None
    coincident: np.ndarray | None = None
    switched_at: int | None = None

    def __post_init__(self):
        if self.stop_reason not in STOPS:
            raise ValueError(f"a scheduler stopped with {self.stop_reason!r}, not one of {STOPS}")
        if len(self.alive) != len(self.faces) or len(self.positions) != len(self.states):
            raise ValueError("a scheduler's outcome is inconsistent: faces and alive, or positions and "
                             "states, differ in length")
        h = self.history
        if not len(h.pairs) == len(h.positions) == len(h.costs):
            raise ValueError("a scheduler's history columns differ in length")

    @property
    def contractions(self) -> int:
        return len(self.history.pairs)

    def output(self) -> Output:
        """The live faces and the vertices they use (`compact_output`)."""
        return Output(*compact_output(self.positions, self.faces, self.alive))

    def stop_above(self, faces_left: int, target: int, closed: bool) -> str:
        """The stop reason of a run whose output ends above its face target (``faces_left`` > ``target``;
        ``closed``: the output has no boundary): ``"target"`` for the documented parity case
        (`parity_only`), else ``"blocked"`` where the run reported its target met (splitting added faces
        back), and then ``"locked"`` where locks hold back most of the pairs left (`hold_back`)."""
        stop = self.stop_reason
        if parity_only(faces_left, target, closed) and stop in ("target", "blocked"):
            return "target"
        stop = "blocked" if stop == "target" else stop
        return "locked" if stop == "blocked" and hold_back(self.blocked_by) else stop

    def counts(self, branch_names) -> dict:
        """The run's counts for the result's stats: contractions, refusals, rounds (run) and those of them
        that contracted something (`contracting_rounds`), contractions per placement branch (by the
        model's ``branch_names``), refusals and blocked pairs per rule."""
        return dict(contractions=self.contractions, rejected=self.rejected, rounds=self.rounds,
                    rounds_contracting=contracting_rounds(self.history_rounds if self.contractions else ()),
                    branches={name: int(c) for name, c in zip(branch_names, self.branches)},
                    rejected_by=self.rejected_by, blocked_by=self.blocked_by)

    @classmethod
    def unchanged(cls, positions, states, faces, branches: int) -> "Outcome":
        """The outcome of a run with nothing to remove."""
        return cls(positions, states, faces, np.ones(len(faces), bool), History.empty(), "unchanged", {},
                   count_reasons(np.zeros(0, np.int8)), branches=np.zeros(branches, int))


def contracting_rounds(history_rounds) -> int | None:
    """How many rounds contracted something, from each contraction's round (None: a scheduler that does not
    give them). A round may contract nothing: one that only refused its picks selects again among the rest,
    and a run that stops blocked ends with one that found nothing to contract; ``rounds`` counts those too."""
    return None if history_rounds is None else int(len(np.unique(history_rounds)))


def stage_times(timer: dict) -> dict:
    """The ``*_s`` entries of a scheduler's timer."""
    return {k: v for k, v in timer.items() if k.endswith("_s")}
