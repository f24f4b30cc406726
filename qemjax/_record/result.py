"""The object `simplify` returns."""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(eq=False)  # arrays: `==` is identity (an elementwise == has no one truth value)
class Contractions:
    """Record of the contractions in the order they happened, in the cleaned input's vertex ids.

    pairs (k,2) int64: (kept, removed) vertex; positions (k,3) float64: where the kept vertex went
    (input units); costs (k,) float64: quadric cost (squared distance, input units); parts: for a method
    with cost parts, each part by name (k,) float64 in input units (``method="esqem"``: ``"quadric"``,
    a squared distance, equal to costs; ``"curvature"``, K(e) in 1/units²), and ``"rank"``, what selection
    ranked the pair by (esqem: Q + w·K, a squared distance); empty otherwise; rounds (k,) int64: the round
    each contraction happened in, counted from 0 (the greedy scheduler: one contraction per round). Within
    a round, contractions are in the order selection ranked them (cost order; with ``quality_threshold``, the
    shaped keys' order). The faces each removed are
    in the result's `record` (``record.removed_at``).

    Compares and hashes by identity (``a == b`` is ``a is b``); compare the arrays with ``np.array_equal``.
    """

    pairs: np.ndarray
    positions: np.ndarray
    costs: np.ndarray
    parts: dict = dataclasses.field(default_factory=dict)
    rounds: np.ndarray | None = None

    def __len__(self):
        return len(self.pairs)

    def __repr__(self):  # counts, not arrays
        rounds = "" if self.rounds is None or not len(self.rounds) else f", {int(self.rounds.max()) + 1} rounds"
        parts = f", parts {', '.join(self.parts)}" if self.parts else ""
        return f"Contractions({len(self)} contractions{rounds}{parts})"


@dataclasses.dataclass(eq=False)  # arrays: `==` is identity, as for `Contractions`
class SimplifyResult:
    """A simplified mesh and what it cost.

    vertices (k,3) float64 and faces (j,3) int64 in the input's units and orientation;
    vertex_error (k,) float64: each output vertex's quadric error Q(v), a squared distance in input units;
    max_error: the largest contraction cost used (the cost model's measure, ``stats["error_unit"]``: for the
    quadric methods a quadric error, a sum of squared distances to planes in input units², which can be
    many times the squared distance the output lies from the input; that distance is measured in
    ``stats["distance_max"]`` / ``["distance_rms"]``);
    source_vertices (k,) int64: for each output vertex, the id (in the cleaned input) of the vertex it
    grew from; source_faces (j,) int64: for each output face, the input face it continues (contraction
    only re-links faces, it never creates them); input_vertices / input_faces: the cleaned input (after
    welding and face clean-up);
    history: the `Contractions`; stop_reason: why the run stopped, one of ``"target"`` (met, or one face
    above an odd target on a closed mesh), ``"max_error"``, ``"max_distance"`` (a level with more faces
    than the run reached was returned: fewer would lie farther from the input than ``simplify(max_distance=)``
    allows), ``"blocked"`` (no valid contraction left:
    ``stats["blocked_by"]`` counts the pairs each rule held back), ``"locked"`` (the vertices given as
    ``locked`` held back the pairs left: ``stats["blocked_by"]["locked"]``) or ``"unchanged"`` (nothing to
    remove);
    stats: counts and timings (``rounds``: the scheduler's rounds run, those that contracted nothing
    included, the greedy queue's being its contractions; ``rounds_contracting``: those that contracted
    something, one entry each in ``faces_per_round``; ``compile_s`` is every compilation inside this call: JAX's tracing and
    compiling, and numba's compiling of a host loop its cache did not have; ``run_s`` the rest, ``total_s`` both; the parallel scheduler adds its stage
    times ``topology_s``, ``kernels_s``, ``select_s`` (which includes ``validity_s`` where a round validates in its numpy stages), ``contract_s``
    and ``faces_per_round``), ``refit`` (re-fit rounds run) and ``refit_s`` (their seconds; a batch runs
    its cells' re-fits side by side on threads, each timed on its own), the targets (``target_faces``, 0 for
    none; ``max_error_limit``, a squared distance in input units, None for none) and ``dropped``: what
    the input carried that the result does not keep (any of "uv", "material", "vertex_colors",
    "face_colors"); ``error_unit``: what ``max_error`` and the history's costs measure (the cost model's
    `error_unit`); the measured distance from the input (``simplify(measure=...)``, `_pipeline.measure`):
    ``distance_max`` and ``distance_rms`` (mesh units), ``distance_p50`` / ``_p95`` / ``_p99`` (area-weighted
    percentiles of the samples' distances), each also as ``*_rel`` (over the
    input's bounding-box diagonal), ``distance_samples`` and ``distance_s``, all None when not measured;
    with ``max_distance`` (`_pipeline.bound`): ``max_distance`` (mesh units) and ``max_distance_rel``, the
    verified two-way distance ``distance_two_way_max`` (and ``_rel``; <= ``max_distance``),
    ``max_distance_checks`` (levels checked) and ``max_distance_s``; ``vertex_error`` is then NaN when the
    bound stopped the run (the record keeps no vertex states for earlier levels);
    with attributes kept,
    ``attributes`` (their kinds) and the input's seams: ``seams_in`` (connected pieces), ``seam_edges_in``
    and ``seam_vertices_in``.
    With ``locked=`` / ``vertex_weights=`` (`qemjax._pipeline.locks`): ``locked_in`` (the vertices given),
    ``locked`` (the cleaned vertices they are), ``locked_unreferenced`` (given ones no face uses: not
    kept) and ``vertex_weights`` (whether any weight differs from 1).
    Also: ``method``, ``scheduler`` and ``model`` (the cost model's settings, {field: value}); ``faces_in``,
    ``faces_out``, ``vertices_in``, ``vertices_out``; the clean-up's counts (``welded``,
    ``degenerate_removed``, ``zero_area_removed``, ``duplicate_removed``, ``unreferenced_removed``), the
    input's ``parts_in`` (connected parts) and ``non_manifold_edges_in``; ``close_pairs`` (the pairs
    ``pair_threshold`` adds); ``scale`` (the power of two the run's unit frame divides by);
    ``compilations`` (JAX's, in this call); ``contractions``, ``rejected`` and ``rejected_by`` (the
    refusals over the run, per rule), ``branches`` (contractions per placement branch); with a re-fit that
    moves, ``polish_moves`` and ``sliver_moves``; ESQEM's ``reweights`` (the face count and the ranking
    weights each time they were set) and ``split`` (its edge splits); a batched run's ``batch`` (its size,
    copies, ``same_run``, ``total_s``, ``compilations``); for a method that turns memoryless late (the
    default), ``memoryless_from_faces`` (the face count at the switch; None: it did not switch) and, where
    the run stayed on the summed quadrics throughout, ``late_memoryless_off`` (why: no face target,
    ``max_error`` alone; a scheduler registered from outside; ``regularize`` or ``area_weight`` set; kept
    attributes; feature edges given); ``quality_threshold_off`` (why the shape term did not apply: a scheduler other than the parallel one); a
    bounded run's ``refit_skipped`` (why its re-fitted positions were not returned).

    Appearance attributes (``simplify(attributes=...)``; None when the input carries none or they were not
    kept) are per wedge, a distinct attribute value at a vertex (a vertex on a UV seam has one per chart):
    uv (w,2), colors (w,4) RGBA in [0, 1], normals (w,3) unit; wedge_vertex (w,) int64: each wedge's
    vertex (index into ``vertices``); wedge_faces (j,3) int64: each face corner's wedge (faces[i, k] ==
    wedge_vertex[wedge_faces[i, k]]); material: the trimesh material of the UVs (with its texture image)
    or None; input_wedge_faces (m,3): the cleaned input's corner wedges (its own ids; for
    `qemjax.metrics.seam_report`). `to_trimesh` splits vertices by wedge, as OBJ, glTF and trimesh store them.

    Compares and hashes by identity (``a == b`` is ``a is b``); compare the arrays with ``np.array_equal``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_error: np.ndarray
    max_error: float
    source_vertices: np.ndarray
    source_faces: np.ndarray
    input_vertices: np.ndarray
    input_faces: np.ndarray
    history: Contractions
    stats: dict
    stop_reason: str = "target"
    record: object = None
    uv: np.ndarray | None = None
    colors: np.ndarray | None = None
    normals: np.ndarray | None = None
    wedge_faces: np.ndarray | None = None
    wedge_vertex: np.ndarray | None = None
    material: object = None
    input_wedge_faces: np.ndarray | None = None

    def __repr__(self):
        """A few lines (a notebook cell shows this): the counts, the method, why the run stopped and its
        key figures; the arrays are the fields (``res.vertices``, ...), every figure is in ``res.stats``."""
        s = self.stats
        # a partitioned result holds no input arrays: its counts are in the stats
        faces_in = len(self.input_faces) if len(self.input_faces) else s.get("faces_in", 0)
        vertices_in = len(self.input_vertices) if len(self.input_vertices) else s.get("vertices_in", 0)
        first = (f"SimplifyResult: {faces_in} -> {len(self.faces)} faces, {vertices_in} -> "
                 f"{len(self.vertices)} vertices, stop_reason {self.stop_reason!r}")
        if s.get("target_faces"):
            first += f" (target {s['target_faces']} faces)"
        lines = [first, f"  method {s.get('method')!r}, scheduler {s.get('scheduler')!r}, {s.get('rounds', 0)} rounds, "
                        f"{len(self.history)} contractions, {s.get('total_s', 0.0):.2f} s "
                        f"(compile {s.get('compile_s', 0.0):.2f} s)",
                 (f"  distance from the input: max {s['distance_max']:.3g}, rms {s['distance_rms']:.3g} mesh units"
                  if s.get("distance_max") is not None else "  distance from the input: not measured (measure=True)")
                 + f"; max_error {self.max_error:.3g} ({s.get('error_unit', 'quadric error, mesh units²')})"]
        kept = [k for k in ("uv", "colors", "normals") if getattr(self, k) is not None]
        extra = ([f"attributes kept: {', '.join(kept)} ({len(self.wedge_vertex)} wedges)"] if kept else []) + \
                ([f"dropped: {', '.join(s['dropped'])}"] if s.get("dropped") else [])
        if extra:
            lines.append("  " + "; ".join(extra))
        return "\n".join(lines)

    @property
    def vertex_map(self) -> np.ndarray:
        """(n,) int64: for each input vertex (the cleaned input, as ``input_vertices``), the output vertex it
        was contracted into; -1 for the vertices of parts that vanished. ``vertex_map[source_vertices]`` is
        ``arange(len(vertices))``. With ESQEM's splitting the indices are those of the contraction phase's
        vertices, which the split mesh keeps first."""
        return self._record().vertex_map()

    def replay(self, target_faces: int | None = None, *, ratio: float | None = None,
               contractions: int | None = None):
        """The mesh at ``target_faces`` faces (or ``ratio`` × the input's, or after the first
        ``contractions`` contractions) rebuilt from the record of this run, without simplifying again:
        a `qemjax.Level` (vertices, faces, source_vertices, source_faces, vertex_map, contractions, max_error,
    round). Greedy:
        equal to ``simplify(target_faces=k, scheduler="greedy")`` when a prefix of the run has k faces;
        parallel: the run's own mesh at round boundaries, the round's cheapest contractions first in
        between. Covers the contraction phase only (not ESQEM's edge splits). See `qemjax._record.history`.
        A level has positions and faces only: the record holds the contractions, not the wedges of the
        run's appearance attributes, so a run that kept UVs, colours or normals warns (once per call) that
        they are not replayed."""
        level = self._record().replay(target_faces, ratio=ratio, contractions=contractions)
        unreplayed = self._unreplayed()
        if unreplayed:  # a level without them would otherwise pass for the textured or coloured mesh
            import warnings

            warnings.warn(f"replay gives positions and faces only: {unreplayed}", stacklevel=2)
        return level

    def _unreplayed(self) -> str | None:
        """What a replay of this run leaves out, in words (``"the run's uv is not replayed (...)"``), or None
        where the run kept no appearance attributes."""
        kept = [name for name in ("uv", "colors", "normals") if getattr(self, name) is not None]
        if not kept:
            return None
        return (f"the run's {', '.join(kept)} {'is' if len(kept) == 1 else 'are'} not replayed (the record holds "
                "the contractions, not the attributes' wedges)")

    def _record(self):
        if self.record is None:
            raise ValueError("this result carries no record")
        return self.record

    def to_trimesh(self):
        """The simplified mesh as a `trimesh.Trimesh` (no processing: arrays are kept as they are). With
        appearance attributes, its vertices are the wedges (split at seams, faces = ``wedge_faces``) and its
        visual carries them: `TextureVisuals` (UVs and the material with its image) or `ColorVisuals`
        (vertex colours); stored normals become its vertex normals. UVs without a material get a bare
        `PBRMaterial` (no image), not trimesh's made-up grey placeholder texture."""
        import trimesh

        if self.wedge_faces is None:
            return trimesh.Trimesh(self.vertices, self.faces, process=False)
        kw = {}
        if self.normals is not None:
            kw["vertex_normals"] = self.normals
        if self.uv is not None:
            material = trimesh.visual.material.PBRMaterial() if self.material is None else self.material
            kw["visual"] = trimesh.visual.TextureVisuals(uv=self.uv, material=material)
        elif self.colors is not None:
            kw["visual"] = trimesh.visual.ColorVisuals(
                vertex_colors=np.clip(np.round(self.colors * 255), 0, 255).astype(np.uint8))
        return trimesh.Trimesh(self.vertices[self.wedge_vertex], self.wedge_faces, process=False, **kw)

    def summary(self) -> str:
        """One line: faces before -> after and the target, times, rounds, the measured distance from the
        input (``stats["distance_max"]`` and ``["distance_rms"]`` in mesh units, the largest also as a
        percentage of the input's bounding-box diagonal; `_pipeline.measure`), and the largest contraction
        cost named for what it is (``stats["error_unit"]``: a quadric error, a sum of squared distances to
        planes, for the quadric methods; a surface-area change for ``method="area"``). A re-fit the method
        asks for but that did not run (``stats["refit_skipped"]``: a bounded run's) is named beside the distance."""
        s = self.stats
        goals = []
        if s.get("target_faces"):
            goals.append(f"{s['target_faces']} faces")
        if s.get("max_error_limit") is not None:
            goals.append(f"max error {s['max_error_limit']:.3g}")
        if s.get("max_distance") is not None:
            goals.append(f"max distance {s['max_distance']:.3g}")
        if s.get("distance_max") is not None:
            rel = s.get("distance_max_rel")
            of = f" = {100 * rel:.3g} % of the diagonal" if rel is not None else ""
            dist = f"distance from the input: max {s['distance_max']:.3g}{of}, rms {s['distance_rms']:.3g} mesh units"
        else:
            dist = "distance from the input: not measured (measure=True measures it)"
        if s.get("distance_two_way_max") is not None:
            dist += f", both ways max {s['distance_two_way_max']:.3g} (checked against max_distance)"
        if s.get("refit_skipped"):  # the method's re-fit did not run: say so where the distance is read
            dist += f" (re-fit skipped: {s['refit_skipped']})"
        if s.get("partition"):  # no rounds or contraction costs of its own: its parts and levels
            p = s["partition"]
            return (f"{s['faces_in']} -> {s['faces_out']} faces (target {' or '.join(goals) or 'none'}) "
                    f"in {s['total_s']:.2f} s, partitioned: {p['parts']} parts, {p['levels']} levels on "
                    f"{p['where']} (largest worker {p['peak_rss_workers'] / 2**30:.2f} GiB); {dist}")
        return (f"{s['faces_in']} -> {s['faces_out']} faces (target {' or '.join(goals) or 'none'}) "
                f"in {s['total_s']:.2f} s (compile {s['compile_s']:.2f} s, run {s['run_s']:.2f} s), "
                f"{s['rounds']} rounds; {dist}; largest contraction cost {self.max_error:.3g} "
                f"({s.get('error_unit', 'quadric error, mesh units²')})")
