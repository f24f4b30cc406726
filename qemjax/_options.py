"""Settings as frozen data: what a run was asked to do, resolved once by `simplify`.

`Schedule` holds the parallel scheduler's tunables (how much a round takes), `Partition` how a partitioned
run cuts and runs its parts; `Options` holds the
model-independent rules every scheduler applies (validity, limits). A cost model is itself a frozen
object whose fields are its settings (`qemjax._costs`); its numbers reach the kernels as 0-d arrays (a
pytree, `CostModel.kernel_params`), so a new value never recompiles. Nothing here is a module global:
tests and sweeps pass these objects.
"""
from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import numpy as np

from ._mesh.wedges import KINDS, check_kinds, check_texture, check_weights


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How much the parallel scheduler takes per round (results depend on these; the defaults are the
    measured trade-off between quality and rounds, see docs/schedulers.md).

    gate: a round's candidates are the pairs costing at most gate × the cost of the k-th cheapest, where
        k = min(contractions still needed / (2·tail), gate_fraction × live pairs).
    tail: near the target a round takes at most about 1/(2·tail) of what is still needed.
    free_cost: costs below this (squared distance, with the extent of the pair's connected part as unit)
        always pass the gate (flat regions).
    max_passes: selection passes per round; pass_yield: stop a round's passes once one accepts under this
        fraction of what the round took.

    ``Schedule(gate=1.0, gate_fraction=1e-12, free_cost=0.0)`` takes one pair per round, or the pairs tied
    with it at the cheapest cost: with a method the greedy queue runs alike (no shape term: the greedy queue
    has none, see docs/methods.md) and no ties, the parallel scheduler then reproduces the greedy queue
    contraction for contraction.
    """

    gate: float = 1.2
    gate_fraction: float = 0.05
    tail: int = 10
    free_cost: float = 1e-10
    max_passes: int = 8
    pass_yield: float = 0.1

    def __post_init__(self):
        for name in ("gate", "gate_fraction", "free_cost", "pass_yield"):
            v = _number("Schedule", name, getattr(self, name))
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Schedule.{name} must be finite and >= 0, got {v}")
        if self.gate < 1:
            raise ValueError(f"Schedule.gate must be >= 1 (a multiple of the k-th cheapest cost), got {self.gate}")
        for name in ("tail", "max_passes"):
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not np.isfinite(v) or int(v) != v or v < 1:
                raise ValueError(f"Schedule.{name} must be a positive integer, got {v!r}")


def _number(owner: str, name: str, x) -> float:
    """x as a float; ValueError naming ``owner.name`` unless x is a real number (bools are refused)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ValueError(f"{owner}.{name} must be a number, got {x!r}")
    return float(x)


def _bool(owner: str, name: str, x) -> None:
    if not isinstance(x, (bool, np.bool_)):
        raise ValueError(f"{owner}.{name} must be True or False, got {x!r}")


@dataclasses.dataclass(frozen=True)
class Topology:
    """What a run may do to the mesh's topology, and how the input is cleaned (``simplify(topology=...)``).

    preserve_topology: forbid contractions that break the link condition or make faces coincide (keeps a
        manifold's genus and boundary loops). None (default): True when pair_threshold is 0, else False.
        With False, contractions may create non-manifold edges, and coincident faces are dropped
        (opposite ones cancel, so small parts can vanish), as in Garland & Heckbert's paper.
    prune: with preserve_topology, let small separate open parts vanish (their last faces may contract away;
        a closed part stops at four faces, a tetrahedron, whose edges the link condition never contracts:
        preserve_topology=False lets it go); False (default): every part keeps at least one face.
    pair_threshold: t in mesh units; besides edges, any two vertices within distance t may contract
        (Garland–Heckbert's aggregation: separate parts can join). 0 = edge contraction only.
    flip_angle: forbid a contraction that turns any surviving face's normal by this many degrees or more
        (90: any sign flip or collapse to zero area); None allows flips.
    min_angle: a triangle-quality guard, in degrees (None, the default: off). A contraction (and the
        re-fit's move) is refused when a face it moves ends with 2·area / longest edge² below
        sin(min_angle) and lower than before the move. A face that passes has its smallest angle at least
        min_angle (2·area / longest² never exceeds the sine of the smallest angle), so faces made from
        well-shaped ones are never slivers under min_angle; the guard may refuse some faces whose smallest
        angle is up to about twice min_angle, and faces the input had worse may stay as they are.
    weld: merge vertices with identical coordinates first (G&H need shared corners).
    """

    preserve_topology: bool | None = None
    prune: bool = False
    pair_threshold: float = 0.0
    flip_angle: float | None = 90.0
    weld: bool = True
    min_angle: float | None = None

    def __post_init__(self):
        _bool("Topology", "prune", self.prune)
        _bool("Topology", "weld", self.weld)
        if self.preserve_topology is not None:
            _bool("Topology", "preserve_topology", self.preserve_topology)
        t = _number("Topology", "pair_threshold", self.pair_threshold)
        if not (t >= 0 and np.isfinite(t)):
            raise ValueError(f"pair_threshold must be a finite distance >= 0, got {self.pair_threshold}")
        if self.preserve_topology and t > 0:
            raise ValueError("pair_threshold > 0 joins separate parts, which changes topology: "
                             "use preserve_topology=False (the default when pair_threshold > 0)")
        if self.flip_angle is not None:
            a = _number("Topology", "flip_angle", self.flip_angle)
            if not 0 < a <= 180:
                raise ValueError(f"flip_angle must be in (0, 180] degrees or None, got {self.flip_angle}")
        if self.min_angle is not None:
            a = _number("Topology", "min_angle", self.min_angle)
            if not 0 < a < 60:
                raise ValueError(f"min_angle must be in (0, 60) degrees or None (a triangle's smallest angle is "
                                 f"at most 60), got {self.min_angle}")

    @property
    def manifold(self) -> bool:
        """preserve_topology as the run applies it (None resolved)."""
        return self.pair_threshold == 0 if self.preserve_topology is None else bool(self.preserve_topology)

    @property
    def cos_max(self) -> float:
        """The cosine of the flip angle (-2: flips allowed)."""
        return -2.0 if self.flip_angle is None else math.cos(math.radians(self.flip_angle))

    @property
    def min_quality(self) -> float:
        """The quality guard's bound on 2·area / longest edge² (0: off)."""
        return 0.0 if self.min_angle is None else math.sin(math.radians(self.min_angle))


class _Weights(dict):
    """A read-only {kind: weight}: `Attributes` keeps its own copy of a mapping given, so that it stays what
    was checked and can be hashed."""

    def _refuse(self, *args, **kwargs):
        raise TypeError("Attributes.attribute_weights cannot be changed: dataclasses.replace(attributes, "
                        "attribute_weights={...}) makes another")

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _refuse

    def __hash__(self):
        return hash(frozenset(self.items()))

    def __reduce__(self):  # pickles (a sweep's workers) without the refused __setitem__
        return (type(self), (dict(self),))


@dataclasses.dataclass(frozen=True, eq=False)
class Attributes:
    """Which appearance attributes a run carries through, and how they weigh (``simplify(attributes=...)``;
    docs/attributes.md).

    ``attributes``: ``'auto'`` (each kind the input carries without seams, and UVs with seams when the material names a
        texture image or ``texture`` is given; another seamed kind only when named),
        ``'uv'``, ``'color'``, ``'normal'``, a tuple of these (a list or set is kept as a tuple), or None
        (positions only).
    ``attribute_weights``: w ≥ 0, one number for every kind or {kind: w} (kept as a read-only copy); None:
        the measured defaults (``qemjax._mesh.wedges.DEFAULT_WEIGHTS``).
    ``texture``: a path or PIL image: the texture of the UVs (for a file that names no material).

    Frozen data, checked when made (ValueError naming the field): equal settings compare equal and hash
    alike; a texture given as an image compares by identity (a path, by its text).
    """

    attributes: object = "auto"
    attribute_weights: object = None
    texture: object = None

    def __post_init__(self):
        a = self.attributes
        check_kinds(a)
        if isinstance(a, (list, tuple, set, frozenset)):
            # a set has no order of its own: the kinds' order; a list or tuple as given
            a = tuple(k for k in KINDS if k in a) if isinstance(a, (set, frozenset)) else tuple(a)
            object.__setattr__(self, "attributes", a)
        w = self.attribute_weights
        if w is not None:
            if not isinstance(w, dict) and hasattr(w, "keys"):  # another mapping: read as a dict
                w = dict(w)
            if not isinstance(w, (dict, int, float, np.integer, np.floating)) or isinstance(w, (bool, np.bool_)):
                raise ValueError(f"attribute_weights takes one number w >= 0 for every kind or {{kind: w}}, "
                                 f"got {type(w).__name__} {w!r}")
            check_weights(w)  # ValueError naming the kind or the weight
            if isinstance(w, dict):
                object.__setattr__(self, "attribute_weights", _Weights(w))
        check_texture(self.texture)

    def _key(self) -> tuple:
        t = self.texture  # an image compares by identity (PIL's == compares pixels, and it has no hash)
        return (self.attributes, self.attribute_weights,
                t if t is None else os.fspath(t) if isinstance(t, (str, os.PathLike)) else ("image", id(t)))

    def __eq__(self, other):
        if other.__class__ is not self.__class__:
            return NotImplemented
        return self is other or self._key() == other._key()

    def __hash__(self):
        return hash(self._key())


@dataclasses.dataclass(frozen=True)
class Options:
    """Resolved options of one run, in internal units (coordinates normalised to unit extent).

    cos_max: cosine of the flip angle (-2: flips allowed).
    min_quality: the quality guard's bound on 2·area / longest edge² of a moved face (0: off).
    preserve_topology: link condition and no coincident faces (manifold mode).
    keep_parts: (manifold mode) forbid the contraction that would remove the last face of a part, so
        separate parts survive; False lets small parts vanish (``simplify(prune=True)``).
    max_cost: largest contraction cost allowed (squared distance at unit extent; inf = no limit).
    schedule: the parallel scheduler's `Schedule`.
    quality_threshold: the shape term of the parallel scheduler's ranking (a method's ``quality_threshold``;
        0: none; `_schedulers.shape`).
    """

    cos_max: float
    preserve_topology: bool
    max_cost: float
    keep_parts: bool = True
    schedule: Schedule = Schedule()
    min_quality: float = 0.0
    quality_threshold: float = 0.0


@dataclasses.dataclass(frozen=True)
class Partition:
    """Settings of a partitioned run (``simplify(path, ratio=..., partition=Partition(...))``, the command
    line's ``--partition``): the input is read in chunks and cut into parts of at most ``part_faces`` faces
    along the Hilbert order of the face centroids; each level simplifies groups of neighbouring parts in
    parallel with the vertices they share with other groups locked, then regroups so that those borders
    lie inside the next level's groups; the last level is one group, unlocked, run to the exact target.

    part_faces: the most faces one task reads (level 1: a part; later: a group of parts' outputs).
    budget: the faces kept before the last level, as a multiple of the target: a small budget leaves the
        locked borders most of the faces the interiors need, and the last level cannot win that back.
    reduction: each level but the last keeps about 1/reduction of its faces (at least ``budget`` × target).
    final_faces: the most faces the last level's single group may read; above it the run ends with its
        groups' borders still locked (``stats["partition"]["locked_share"]``, a warning).
    refit_input_faces: the largest input (faces) that the last level's re-fit, polish and sliver moves fit
        the output to, rather than to the faces the levels before left (a method that re-fits: the default).
        The worker of that level then reads every part (its memory: docs/large-meshes.md, "Tuning"). Above
        it, or 0, they fit to the last level's own input; ``stats["partition"]["refit_to"]`` says which.
    workers: local worker processes (None: every core; 1: in this process) when no ``client`` is given.
    client: a ``dask.distributed.Client``: the tasks run on its workers (a `LocalCluster`, dask-jobqueue,
        Kubernetes: any cluster whose workers see ``scratch``).
    scratch: the folder for the parts (a shared file system on a cluster; a `pathlib.Path` is kept as its str,
        so the same folder given either way is the same settings). None: a temporary folder, removed when the
        run ends. A folder given is kept, and a run of the same input and settings resumes from the parts
        already in it; it must be new, empty or one a partitioned run wrote (one holding other files is
        refused: a run with other inputs or settings clears it).
    retries: how often a task whose worker died is run again.
    measure: measure the distance of the output from every input vertex and face centroid: in the last
        level's task where it fitted to the input (``refit_input_faces``), else part by part.
    refit: which levels re-fit their output to their input, for a method that re-fits (the default):
        ``"last"``, or ``"all"``. The levels before the last leave a mesh that the next level simplifies
        again, and the last level fits the output to the input itself (``refit_input_faces``): their own
        re-fits, polish and sliver moves took most of a level's work and did not bring the output closer
        (docs/benchmarks.md, "Partitioned runs").
    share: how a level before the last splits its faces among its groups: ``"faces"``, in proportion to the
        faces each reads; or ``"cost"``, a common contraction cost: a few groups spread over the mesh run
        first in proportion, the median of the largest cost they reached becomes every group's
        ``max_error``, so that detailed groups keep more faces and flat ones fewer (the level's total is
        then near, not at, its goal; the last level meets the target exactly either way).
    """

    part_faces: int = 100_000
    budget: float = 4.0
    reduction: float = 4.0
    final_faces: int = 4_000_000
    refit_input_faces: int = 6_000_000
    workers: int | None = None
    client: Any = dataclasses.field(default=None, compare=False, repr=False)
    scratch: str | os.PathLike | None = None
    retries: int = 2
    measure: bool = True
    refit: str = "last"
    share: str = "faces"

    def __post_init__(self):
        if self.refit not in ("all", "last"):
            raise ValueError(f"Partition: refit must be 'all' or 'last', got {self.refit!r}")
        if self.share not in ("faces", "cost"):
            raise ValueError(f"Partition: share must be 'faces' or 'cost', got {self.share!r}")
        def positive(name, value, kind=int, least=1):
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value) or value < least or (kind is int and value != int(value)):
                raise ValueError(f"Partition: {name} must be {'an integer' if kind is int else 'a finite number'} "
                                 f">= {least}, got {value!r}")
        for name in ("part_faces", "budget", "reduction", "final_faces", "refit_input_faces", "workers", "retries"):
            value = getattr(self, name)  # numpy numbers stored as Python's (the settings go into JSON)
            if isinstance(value, (np.integer, np.floating)) and not isinstance(value, np.bool_):
                object.__setattr__(self, name, value.item())
        positive("part_faces", self.part_faces, least=1000)
        positive("budget", self.budget, float, 1)
        positive("reduction", self.reduction, float, 1.5)
        positive("final_faces", self.final_faces)
        positive("refit_input_faces", self.refit_input_faces, least=0)
        positive("retries", self.retries, least=0)
        if self.workers is not None:
            positive("workers", self.workers)
        if not isinstance(self.measure, (bool, np.bool_)):
            raise ValueError(f"Partition: measure must be True or False, got {self.measure!r}")
        # what the run calls on a client (`_partition.execute.DaskRunner`), looked for without importing dask:
        # anything else failed only once the input was cut, in the library's words
        if self.client is not None and not all(callable(getattr(self.client, m, None))
                                               for m in ("submit", "scheduler_info", "cancel")):
            raise ValueError(f"Partition: client must be a dask.distributed Client, or None for local processes; "
                             f"got {type(self.client).__name__}")
        if not (self.scratch is None or isinstance(self.scratch, (str, os.PathLike))):
            raise ValueError(f"Partition: scratch must be a folder's path or None, got {type(self.scratch).__name__}")
        if self.scratch is not None:  # stored as a str: the same folder given as a str or a Path is equal settings
            folder = os.fspath(self.scratch)
            if not isinstance(folder, str):
                raise ValueError(f"Partition: scratch must be a folder's path as text, got {type(folder).__name__}")
            object.__setattr__(self, "scratch", folder)

    @property
    def n_workers(self) -> int:
        """The local processes a run without a client uses."""
        if self.workers is not None:
            return int(self.workers)
        try:
            return len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            return os.cpu_count() or 1


# `simplify`'s keywords besides the settings (tests/test_first_use.py checks them against its signature): a
# method's field of one of these names could be given neither flat nor on the command line (`_costs.register`)
KEYWORDS = ("target_faces", "ratio", "max_error", "max_distance", "max_distance_rel", "method", "scheduler",
            "topology", "attributes", "feature_edges", "progress", "measure", "partition", "locked", "vertex_weights",
            "preset")


def run_setting_group(name: str) -> str | None:
    """"topology" or "attributes" when ``name`` is a field of `Topology` or `Attributes` (a run setting, which
    a method's field of that name would shadow where settings are given flat: `_pipeline.flat`), else None."""
    for group, cls in (("topology", Topology), ("attributes", Attributes)):
        if name in {f.name for f in dataclasses.fields(cls) if f.init}:
            return group
    return None
