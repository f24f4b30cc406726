"""The multiresolution record of a run: every level between the input and the result, without re-running.

Garland and Heckbert's contractions form a sequence M_n ... M_g; the record keeps enough of it to rebuild
any M_i: the contractions in order (`Contractions`: pairs, positions, costs, rounds) and, per input face,
the contraction that removed it (degenerate, or in non-manifold mode coincident with another face). A
level is then a prefix of the record: union-find over the prefix's pairs re-links the input faces, the
faces removed by the prefix go, and each vertex sits where its last contraction put it.

Levels and face counts (`Record.replay`): the level for k faces is the shortest prefix with at most k
faces, or the one before it when that prefix jumps past k (a contraction removes two faces where one was
wanted). The greedy scheduler stops at the same place, so a greedy record replays `simplify(target_faces=k)`
exactly whenever a prefix has exactly k faces (always on a closed manifold for even k; an odd k stops one
face above, as `simplify` does); when the prefix jumps past k, `simplify` would go on to a later contraction
that removes one face, which the record does not hold, and the replay has one face more. The parallel
scheduler contracts in rounds; its record is in round order and, within a round, in the order of
selection's keys (the cost, or with ``quality_threshold``, as the default has, the shaped key), so a replay
is the run's own mesh at every round boundary, and in between it takes the round's first-ranked
contractions first. A parallel run with another face target chooses differently from the
first round on (selection gates on the faces still to remove), so it is not a replay of this one.

ESQEM's edge splits (``split_factor``) come after all contractions and are not in the record: a replay covers
the contraction phase only, down to the face count the contractions reached (`Record.faces_out`). Likewise
``refit`` (`qemjax._pipeline.refit`) moves the output's vertices after the contractions: a replay gives the
positions the contractions chose, so its last level is the result before the re-fit.

Progressive form: `Record.save` writes an ``.npz`` (byte-identical for the same record), `load_record`
reads it back; a notebook or another tool can replay from it without qemjax's run.
"""
from __future__ import annotations

import dataclasses
import io
import zipfile

import numpy as np

from .._mesh import topology as topo
from .._mesh.arrays import face_normals
from .result import Contractions
from .._mesh.units import Frame

FORMAT = "qemjax-record-1"  # written into every .npz; `load_record` refuses others
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # fixed time stamps: the same record gives the same bytes


@dataclasses.dataclass(eq=False)  # arrays: `==` is identity (an elementwise == has no one truth value)
class Level:
    """One level of a record: the mesh after its first ``contractions`` contractions.

    vertices (k,3) float64 and faces (j,3) int64 in the input's units, exactly as `simplify` builds its
    output; source_vertices (k,) / source_faces (j,) int64: the input vertex each vertex grew from and the
    input face each face continues; vertex_map (n,) int64: each input vertex's vertex here (-1: its part
    vanished); max_error: the largest cost among the contractions used (the cost model's measure, e.g. the quadric error, mesh units²; 0
    for none); round: the round of the last contraction used (-1 for none). Compares and hashes by
    identity (``a == b`` is ``a is b``); compare the arrays with ``np.array_equal``."""

    vertices: np.ndarray
    faces: np.ndarray
    source_vertices: np.ndarray
    source_faces: np.ndarray
    vertex_map: np.ndarray
    contractions: int
    max_error: float
    round: int

    def __repr__(self):  # counts, not arrays
        return (f"Level({len(self.faces)} faces, {len(self.vertices)} vertices, {self.contractions} contractions, "
                f"max_error {self.max_error:.3g}, round {self.round})")

    def to_trimesh(self):
        """The level as a `trimesh.Trimesh` (no processing)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


@dataclasses.dataclass(eq=False)  # arrays: `==` is identity, as for `Level`
class Record:
    """What one run did, enough to rebuild every level (see the module docstring).

    input_vertices (n,3) float64 / input_faces (m,3) int64: the cleaned input (ids as in the result);
    history: the `Contractions` (pairs (kept, removed), positions, costs, parts, rounds);
    removed_at (m,) int64: for each input face, the index in ``history`` of the contraction that removed it
    (-1: it survives the whole run); coincident (m,) bool: removed because it coincided with another face
    after that contraction (non-manifold mode; `_topology.coincident_removals`, lower face index first)
    rather than collapsing; frame: the internal unit frame (`_units.Frame`), used where `simplify` keeps
    rounded positions (faces of exactly zero area); scheduler: the scheduler that ran; target_faces: the
    face target the contractions ran to (0: none). Compares and hashes by identity (``a == b`` is
    ``a is b``)."""

    input_vertices: np.ndarray
    input_faces: np.ndarray
    history: Contractions
    removed_at: np.ndarray
    coincident: np.ndarray
    frame: Frame
    scheduler: str = "parallel"
    target_faces: int = 0
    locked: np.ndarray | None = None  # (n,) bool: locked input vertices (None: none), kept exactly

    def __repr__(self):  # counts, not arrays
        return (f"Record({len(self.input_faces)} -> {self.faces_out} faces, {len(self.history)} contractions, "
                f"scheduler {self.scheduler!r})")

    # -- what the record says ----------------------------------------------------------------------
    def faces_removed(self) -> np.ndarray:
        """(k,) int64: how many faces each contraction removed (coincident ones included)."""
        r = self.removed_at
        return np.bincount(r[r >= 0], minlength=len(self.history)).astype(np.int64)

    def face_counts(self) -> np.ndarray:
        """(k+1,) int64: the face count after each prefix of the record (entry 0: the input's)."""
        return len(self.input_faces) - np.concatenate([[0], np.cumsum(self.faces_removed())])

    @property
    def faces_out(self) -> int:
        """The face count the contractions reached (the smallest level)."""
        return int(self.face_counts()[-1])

    def steps_for(self, target_faces: int) -> int:
        """How many contractions the level for ``target_faces`` uses (the rule in the module docstring).
        A target the run was asked to reach but stopped above (the parity of a closed mesh, or no valid
        contraction left) gives the last level, as `simplify` does; ValueError below that."""
        counts = self.face_counts()
        if target_faces < counts[-1]:
            if 0 < self.target_faces <= target_faces:
                return len(self.history)
            raise ValueError(f"replay reaches the levels between the input ({counts[0]} faces) and this "
                             f"result ({counts[-1]} faces), not {target_faces}; for fewer faces, simplify "
                             f"further: qemjax.simplify(..., target_faces={target_faces}), or "
                             "qemjax.lod_chain(..., ratios=[...]) for every level from one run")
        j = int(np.argmax(counts <= target_faces))  # the first prefix at or below the target
        if j and counts[j] < target_faces:  # it jumped past the target: the level before
            j -= 1
        return j

    # -- levels ------------------------------------------------------------------------------------
    def replay(self, target_faces: int | None = None, *, ratio: float | None = None,
               contractions: int | None = None) -> Level:
        """The level at ``target_faces`` faces, or ``ratio`` × the input's faces (rounded as `simplify`
        rounds it), or after the first ``contractions`` contractions; exactly one of the three."""
        given = [x is not None for x in (target_faces, ratio, contractions)]
        if sum(given) != 1:
            raise ValueError("give exactly one of target_faces, ratio and contractions")
        for name, x in (("target_faces", target_faces), ("ratio", ratio), ("contractions", contractions)):
            if x is not None and (isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number))):
                raise ValueError(f"{name} must be a number, got {x!r}")
        if ratio is not None:
            if not 0 < ratio <= 1:
                raise ValueError(f"ratio must be in (0, 1] (the fraction of faces to keep), got {ratio}")
            target_faces = max(1, int(round(ratio * len(self.input_faces))))
        if target_faces is not None:
            if not _whole(target_faces) or target_faces < 1:
                raise ValueError(f"target_faces must be an integer >= 1, got {target_faces!r}")
            contractions = self.steps_for(int(target_faces))
        return self._level(self._contractions(contractions))

    def _contractions(self, j) -> int:
        """``j`` as a count of this record's contractions; ValueError unless a whole number in range."""
        if isinstance(j, (bool, np.bool_)) or not isinstance(j, (int, float, np.number)) or not _whole(j) \
                or not 0 <= j <= len(self.history):
            raise ValueError(f"contractions must be a whole number in [0, {len(self.history)}], got {j!r}")
        return int(j)

    def vertex_map(self, contractions: int | None = None) -> np.ndarray:
        """(n,) int64: each input vertex's vertex in the level after ``contractions`` (default: all),
        -1 for the vertices of parts that vanished."""
        j = len(self.history) if contractions is None else self._contractions(contractions)
        return self._level(j).vertex_map

    def _level(self, j: int) -> Level:
        V, F = self.input_vertices, self.input_faces
        n = len(V)
        pairs = self.history.pairs[:j]
        root = topo.contraction_roots(pairs, n)
        alive = (self.removed_at < 0) | (self.removed_at >= j)
        fids = np.flatnonzero(alive)
        G = root[F[fids]]
        used = np.zeros(n, bool)
        used[G.reshape(-1)] = True
        ids = np.flatnonzero(used)
        index = np.full(n, -1, np.int64)
        index[ids] = np.arange(len(ids))
        faces = index[G]
        # positions: where each vertex's last contraction put it; never contracted: the input's, exactly
        last = np.full(n, -1, np.int64)
        if j:
            np.maximum.at(last, pairs[:, 0], np.arange(j))
        src = last[ids]
        moved = src >= 0
        verts = V[ids].copy()
        verts[moved] = self.history.positions[src[moved]]
        flat = np.flatnonzero(~np.any(face_normals(verts, faces) != 0, axis=1))
        if flat.size:  # as `simplify`: an exactly flat face keeps the rounded internal positions
            w = np.unique(faces[flat])
            w = w[~moved[w]]
            if self.locked is not None:  # locked vertices keep the input's position at every level
                w = w[~self.locked[ids[w]]]
            verts[w] = self.frame.positions_to_mesh(_internal(V[ids[w]], ids[w], self.frame), ids[w])
        costs = self.history.costs[:j]
        rounds = self.history.rounds  # empty from a scheduler that gives no rounds (the contract lets it)
        return Level(vertices=verts, faces=faces, source_vertices=ids.astype(np.int64),
                     source_faces=fids.astype(np.int64), vertex_map=index[root],
                     contractions=j, max_error=float(costs.max()) if j else 0.0,
                     round=int(rounds[j - 1]) if j and rounds is not None and len(rounds) >= j else -1)

    # -- progressive form --------------------------------------------------------------------------
    def arrays(self) -> dict:
        """The record as named numpy arrays (what `save` writes)."""
        h, fr = self.history, self.frame
        out = {"format": np.array(FORMAT), "scheduler": np.array(self.scheduler),
               "target_faces": np.array(self.target_faces, np.int64),
               "input_vertices": self.input_vertices, "input_faces": self.input_faces,
               "pairs": h.pairs, "positions": h.positions, "costs": h.costs, "rounds": h.rounds,
               "removed_at": self.removed_at, "coincident": self.coincident,
               "frame_centers": fr.centers, "frame_scale": np.array(fr.scale, np.float64),
               "frame_part": fr.part if fr.part is not None else np.zeros(0, np.int64),
               "frame_sizes": fr.sizes if fr.sizes is not None else np.zeros(0)}
        for name, col in h.parts.items():
            out[f"parts/{name}"] = col
        if self.locked is not None:  # only then: a record without locks keeps its bytes
            out["locked"] = self.locked
        return out

    def save(self, path) -> None:
        """Write the record to ``path`` (.npz, uncompressed; readable with `numpy.load` or `load_record`).
        The same record gives the same bytes (fixed time stamps and member order)."""
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
            for name, a in self.arrays().items():
                buf = io.BytesIO()
                a = np.asarray(a)
                np.lib.format.write_array(buf, a if a.flags.c_contiguous else a.copy(), allow_pickle=False)
                z.writestr(zipfile.ZipInfo(name + ".npy", date_time=_ZIP_TIME), buf.getvalue())


def load_record(path) -> Record:
    """Read a record that `Record.save` (or ``res.record.save``) wrote. FileNotFoundError for no file,
    ValueError (in words) for a file that is not a whole record."""
    import os

    from .._io.mesh import MissingFileError

    if not os.path.exists(path):
        raise MissingFileError(2, "no such record file", os.fspath(path))
    if not zipfile.is_zipfile(path):  # numpy would take it for a pickle and ask for allow_pickle
        raise ValueError(f"{path} is not a qemjax record ({FORMAT}): not an .npz archive")
    try:
        with np.load(path, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise ValueError(f"{path}: the record is damaged ({' '.join(str(exc).split())})") from None
    if str(a.get("format", "")) != FORMAT:
        raise ValueError(f"{path} is not a qemjax record ({FORMAT})")
    try:
        parts = {k.split("/", 1)[1]: v for k, v in a.items() if k.startswith("parts/")}
        many = a["frame_part"].size > 0
        frame = Frame(a["frame_centers"], float(a["frame_scale"]), a["frame_part"] if many else None,
                      a["frame_sizes"] if many else None)
        history = Contractions(a["pairs"], a["positions"], a["costs"], parts, a["rounds"])
        return Record(a["input_vertices"], a["input_faces"], history, a["removed_at"], a["coincident"], frame,
                      str(a["scheduler"]), int(a["target_faces"]), a.get("locked"))
    except KeyError as exc:
        raise ValueError(f"{path}: the record is incomplete (no {exc.args[0]!r} in it)") from None


def removals(F: np.ndarray, pairs: np.ndarray, alive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(removed_at (m,) int64, coincident (m,) bool) of the faces F (m,3) under the contractions ``pairs``
    (k,2) (kept, removed), for a scheduler whose outcome does not give them (the contract lets it leave them
    None), so that its record replays its own output. A face goes at the first contraction after which two
    of its corners are one vertex; of the faces the run dropped (``alive`` False) that never collapse, as
    coincident by `topology.coincident_removals`, the rule the built-in schedulers apply, at the first
    contraction after which it drops them; any left, at the last contraction. One pass over the
    contractions, each looking at the faces around the vertex it keeps."""
    F = np.asarray(F, np.int64)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    m = len(F)
    n = int(max(F.max(initial=-1), pairs.max(initial=-1))) + 1
    removed_at, coincident = np.full(m, -1, np.int64), np.zeros(m, bool)
    root = np.arange(n, dtype=np.int64)
    members: dict = {}
    around: list = [[] for _ in range(n)]  # the faces around each vertex's class, those removed pruned lazily
    for f, corners in enumerate(F.tolist()):
        for v in set(corners):
            around[v].append(f)
    for k, (a, b) in enumerate(pairs.tolist()):
        ra, rb = int(root[a]), int(root[b])
        if ra == rb:
            continue
        moved = members.pop(rb, [rb])
        root[moved] = ra
        members.setdefault(ra, [ra]).extend(moved)
        faces = np.array(sorted({f for f in around[ra] + around[rb] if removed_at[f] < 0}), np.int64)
        around[rb] = []
        G = root[F[faces]]
        flat = (G[:, 0] == G[:, 1]) | (G[:, 1] == G[:, 2]) | (G[:, 0] == G[:, 2])
        removed_at[faces[flat]] = k
        rest = faces[~flat]
        drop = rest[topo.coincident_removals(G[~flat]) & ~alive[rest]]
        removed_at[drop], coincident[drop] = k, True
        around[ra] = [f for f in rest.tolist() if removed_at[f] < 0]
    removed_at[(removed_at < 0) & ~alive] = len(pairs) - 1
    return removed_at, coincident


def _whole(x) -> bool:
    """Whether the number x is a whole number (int() of an infinity or a NaN raises in Python's words)."""
    return isinstance(x, (int, np.integer)) or (bool(np.isfinite(x)) and int(x) == x)


def _internal(V: np.ndarray, verts: np.ndarray, frame: Frame) -> np.ndarray:
    """(k,3) float32: vertices ``verts`` at positions V in the internal frame, as `_units.normalize`
    rounds them."""
    center = frame.centers[0] if frame.part is None else frame.centers[frame.part[verts]]
    return ((V - center) / frame.scale).astype(np.float32)
