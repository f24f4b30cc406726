"""What the rounds of one run share: the run's settings and mesh (`Run`), what a round knows of its candidate
pairs (`RoundState`), and the fixed shapes of the device calls."""
from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._kernels.batching import CHUNKS, DTYPE, bucket, pad_rows
from ..._mesh.arrays import face_normals
from ..._mesh.incidence import FaceLists
from ..._options import Options
from .. import outcome
from ..device import on_device, start_price
from ..runtime import Timer
from ..select import submit

MERGE_CHUNK = 4096  # the piece shape of a round's merge and device row update (one compilation) ...
SMALL_CHUNK = CHUNKS[0]  # ... or, for a mesh of at most SMALL_MESH faces, this one: such a mesh's rounds
SMALL_MESH = 1 << 14  # contract about 100 pairs, and a 4096-row scatter costs far more than a 256-row one. Chosen per run,
# from the mesh's size, so that meshes of similar size compile the same shapes whatever their rounds

# the shapes of the stale pairs priced in a round's one device call (`device.start_step`), by merge piece:
# the smallest that holds a round's stale pairs, else the largest and more calls: two shapes per size class,
# so a run compiles at most two such calls
STEP_PRICE = {SMALL_CHUNK: (1024, 4096), MERGE_CHUNK: (4096, 16384)}


def holding(sizes: tuple, k: int) -> int:
    """The smallest of ``sizes`` (ascending) that holds k rows, else the largest."""
    return next((s for s in sizes if s >= k), sizes[-1])


def merge_size(m: int) -> int:
    """The fixed piece shape of the merges and device row updates of a run on m faces."""
    return SMALL_CHUNK if m <= SMALL_MESH else MERGE_CHUNK


@dataclasses.dataclass
class RoundState:
    """What a round knows of its candidate pairs; every per-pair array is aligned with ``E``.

    E (P,2) pairs (mesh edges, plus close pairs with aggregation), ecount (P,) faces at each, deg (n,)
    edges at each vertex, bvert (n,) boundary vertices, keys (P,) sorted pair keys when E was rebuilt
    (None when it was updated in place); x (P,3), cost (P,), branch (P,) int8: the current prices;
    parts (P,p) float32: the model's cost parts (p may be 0); key (P,): what selection ranks (the cost,
    or for a model with `rank_weights` the cost plus its weighted parts);
    bad (P,) int8: the rule a pair broke when last validated (0: not known invalid); changed (n,) bool:
    vertices whose pairs need a new price next round; edges_next: `contraction.contract_edges`' result when
    the pairs were updated through the contractions (manifold mode)."""

    E: np.ndarray
    ecount: np.ndarray
    deg: np.ndarray
    bvert: np.ndarray = None
    keys: np.ndarray | None = None
    x: np.ndarray = None
    cost: np.ndarray = None
    branch: np.ndarray = None
    parts: np.ndarray = None
    key: np.ndarray = None
    bad: np.ndarray = None
    changed: np.ndarray = None
    edges_next: tuple | None = None
    # (the stale rows of edges_next, a function giving their price started with the last round's merge) when it
    # is known: a `Priced` (`Round.cost`), or for the compiled glue the kernel's raw (5 + p, ≥ K) output
    next_price: tuple | None = None


class Tally:
    """What a run has done so far, for its `outcome.Outcome`: per round the contractions in record order
    (``history``: (round, (kept, removed, positions, costs)); ``history_parts``: their cost parts and keys),
    the faces they removed (``dead``) and the coincident faces dropped (``dropped``: (round, faces)), the face
    count after each (``faces_per_round``); the rounds, rejections (in all and by rule), price branches and
    the largest cost taken; the ranking weights (`Round.rank`: ``rank_w``, the face count they were taken
    at, and every change in ``reweights``)."""

    def __init__(self, model):
        self.history, self.history_parts = [], []
        self.dead, self.dropped = [], []
        self.faces_per_round = []
        self.branches = np.zeros(len(model.branches), np.int64)
        self.rounds = self.rejected = 0
        self.rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
        self.max_cost_used = 0.0
        self.rank_w, self.weighed_at, self.reweights = None, 0, []


class Run:
    """One simplification's state that lives across rounds, whichever round implementation runs them: the
    settings, the vertex rows on the host (VQ) and the device (VQd), the face lists, the locks and seams, and
    the `Tally`. The implementation's own working arrays are its own (`Round`)."""

    def __init__(self, V, S, F, extra_pairs, target_faces, model, options: Options, progress=None, edges=None,
                 part_scale=None, params=None, wedges=None, normals=None, locks=None):
        self.n = len(V)
        self.m = m = len(F)
        self.merge_chunk = merge_size(m)
        self.price_sizes = STEP_PRICE[self.merge_chunk]
        self.wedges = wedges  # a `_wedges.Tracker` when attributes are kept (else None)
        self.locks = locks  # a `_locks.RunLocks` (else None); the weights are carried in a copy
        self.weights = None if locks is None or locks.weights is None else np.array(locks.weights, np.float64)
        self.part_scale = part_scale
        self.model, self.options, self.progress = model, options, progress
        self.params = model.kernel_params() if params is None else params
        if isinstance(self.params, dict):  # the settings cross to the device once, not with every kernel call
            self.params = on_device(self.params)
        self.cos_max = jnp.asarray(np.asarray(options.cos_max, DTYPE))  # the flip threshold, likewise
        # the quality guard's bound, likewise (None: off, and the device's flip test leaves it out)
        self.min_quality = jnp.asarray(np.asarray(options.min_quality, DTYPE)) if options.min_quality else None
        self.target = target_faces
        self.manifold = options.preserve_topology
        self.extra_pairs = np.asarray(extra_pairs, np.int32).reshape(-1, 2)
        # manifold mode: the pairs are updated through each round's contractions instead of rebuilt
        self.incremental = self.manifold and len(self.extra_pairs) == 0
        self.pad = self.n  # a zero row past the last vertex: padding for ring gathers
        self.VQ = np.zeros((bucket(self.n + 1), 3 + model.width), DTYPE)  # rows [position, model state]
        self.VQ[: self.n, :3], self.VQ[: self.n, 3:] = V, S
        self.VQd = jnp.asarray(self.VQ)  # device copy, updated row by row
        # the first costing of the given edges runs while the host sets up the faces (unless the model
        # needs the faces for it)
        self.first = None
        if edges is not None and len(self.extra_pairs) == 0 and not model.uses_ring:
            self.first = start_price(model, self.VQd, edges[0], self.params)
        self.edges = edges
        # int32 rows (n < 2**31) keep their index: face i continues input face i; built on the worker
        # while this thread computes the input normals
        lists = submit(FaceLists, F, self.n, size=m)
        # the input normals; on the host until the round implementation has taken what it needs (`adopted`)
        self.normals = face_normals(np.asarray(V, DTYPE), F) if normals is None else normals
        self.N0d = jnp.asarray(pad_rows(self.normals, bucket(m)))  # padded: one compilation per size class
        self.merged = None  # (kept vertices, their merged states) not yet in VQ: `Round.settle`
        if self.incremental:
            self.label = np.full(self.n, -1, np.int32)  # scratch of `contraction.contract_edges`
        self.faces = lists.result()
        self.timer = Timer()
        self.tally = Tally(model)

    @property
    def rounds(self) -> int:
        return self.tally.rounds

    def adopted(self) -> None:
        """The round implementation has what it needs of the host-side input normals: let them go."""
        self.normals = None
