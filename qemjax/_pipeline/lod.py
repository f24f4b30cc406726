"""Level-of-detail chains: every level from one simplification run (`lod_chain`), exported as one glTF
scene or as separate files."""
from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from . import flat as _flat
from .api import CALLER, simplify
from .._record.history import Level
from .._record.result import SimplifyResult

RATIOS = (0.5, 0.25, 0.1, 0.01)
REFUSED = ("target_faces", "ratio", "max_error", "max_distance", "max_distance_rel")  # targets: ratios= sets them


@dataclasses.dataclass(eq=False)  # levels of arrays: `==` is identity, as for `Level`
class LodChain:
    """Levels of one mesh from one run: ``levels[i]`` (a `qemjax.Level`) keeps ``ratios[i]`` of the
    faces; ``result`` is the run itself (`SimplifyResult`, at the smallest ratio), whose record the
    levels are replayed from. Compares and hashes by identity (``a == b`` is ``a is b``)."""

    levels: list[Level]
    ratios: tuple[float, ...]
    result: SimplifyResult

    def __len__(self):
        return len(self.levels)

    def __repr__(self):
        """One line for the run, one per level (counts, not arrays)."""
        r = self.result
        lines = [f"LodChain: {len(self.levels)} levels of {len(r.input_faces)} faces from one run "
                 f"(method {r.stats.get('method')!r}, stop_reason {r.stop_reason!r})"]
        lines += [f"  [{i}] ratio {ratio:g}: {len(lv.faces)} faces, {len(lv.vertices)} vertices, max_error "
                  f"{lv.max_error:.3g}" for i, (ratio, lv) in enumerate(zip(self.ratios, self.levels))]
        return "\n".join(lines)

    def __getitem__(self, i) -> Level:
        return self.levels[i]

    def to_scene(self, name: str = "lod", spacing: float | None = None):
        """A `trimesh.Scene` with one node per level, named ``{name}0``, ``{name}1``, … (finest first), side
        by side along x: node i is translated by i × ``spacing`` (level 0 at the origin; the geometry
        itself is the level's, unmoved). ``spacing`` None: 1.2 × the largest x-extent of the levels'
        bounding boxes (so they do not overlap; of a mesh flat in x, its largest extent); 0: every level at
        the same place, as an engine picking a level would place them."""
        import trimesh

        if spacing is None:
            boxes = [np.ptp(lv.vertices, axis=0) for lv in self.levels if len(lv.vertices)]
            width = max((b[0] for b in boxes), default=0.0)
            spacing = 1.2 * (width if width > 0 else max((b.max() for b in boxes), default=0.0))
        scene = trimesh.Scene()
        for i, level in enumerate(self.levels):
            move = np.eye(4)
            move[0, 3] = i * spacing
            scene.add_geometry(level.to_trimesh(), node_name=f"{name}{i}", geom_name=f"{name}{i}", transform=move)
        return scene

    def export(self, path: str, name: str = "lod", spacing: float | None = None) -> None:
        """Write the chain as one glTF binary (.glb) with one node per level, side by side along x
        (`to_scene`: 1.2 × the x-extent apart, level 0 at the origin; ``spacing=0`` stacks them)."""
        data = self.to_scene(name, spacing).export(file_type="glb")
        with open(path, "wb") as f:
            f.write(data)


def _splits(options: dict) -> bool:
    """Whether the run that ``options`` describe splits edges after its contractions (ESQEM's ``split_factor``): the
    method as `simplify` resolves it (by name, a registered subclass's too, or as an object), then a
    ``split_factor`` given flat or dotted. False for a method without the field (simplify names the mistake)."""
    from .. import _costs

    try:
        method = _costs.resolve(options.get("method", options.get("preset") or _costs.DEFAULT))
    except ValueError:  # simplify reports the bad method
        return False
    if not hasattr(method, "split_factor"):
        return False
    split = method.split_factor
    for key in ("split_factor", "method.split_factor"):
        if key in options:
            split = options[key]
    return split is not None


def lod_chain(mesh: Any, ratios=RATIOS, **options) -> LodChain:
    """One simplification run down to the smallest of ``ratios`` (each in (0, 1], the fraction of faces to
    keep; any order, levels come back in the order given), and every level replayed from its record
    (`qemjax._record.history`): one run's cost instead of one per level. ``options`` are `simplify`'s keywords
    (not its targets, nor ``max_distance``: it bounds one result, not a chain). With the greedy scheduler each level equals a separate ``simplify(ratio=r)`` run
    whenever the run passes through exactly that face count; with the parallel scheduler (default) the
    levels are the run's own intermediate meshes, not those of separate runs. With ``late_memoryless=K`` the
    run turns memoryless at K × the smallest level's target: the levels above that are the summed phase's.

    ESQEM's edge splitting happens after all contractions and is not part of the record: with
    ``method="esqem"`` give ``split_factor=None``. When the run stops above a level's target (no valid
    contraction left: `simplify` warns, `SimplifyResult.stop_reason` says why), that level is the run's
    last mesh.

    The levels are the contractions' own meshes, so the run skips the default's re-fit (``refit=0``; pass
    ``refit=N`` to re-fit the result, whose last level then differs from ``chain.result``).

    Levels carry positions and faces only: the record replays contractions, not the wedges of appearance
    attributes, so ``attributes`` defaults to None here (what the input carries is named in a warning)
    and ``texture`` is refused. An unknown keyword is a TypeError whose hint names only what lod_chain takes
    (``ratioss`` suggests ``ratios``, never the refused ``ratio``).
    """
    table = _flat.options()
    for key in options:  # a dotted name: simplify's check, whose hints are dotted names lod_chain takes too
        if "." not in key and not key.startswith("_") and key not in _flat.KEYWORDS and key not in table \
                and key not in _flat.RUN_TYPES:  # (``schedule=``: simplify's too)
            raise TypeError(_flat.unknown_setting(key, table, ("ratios", *_flat.KEYWORDS), (*REFUSED, "texture"),
                                                  who="lod_chain"))
    given = options.get("attributes")
    if any(t is not None for t in (options.get("texture"), options.get("attributes.texture"),
                                   getattr(given, "texture", None))):  # as a texture may be given
        raise ValueError("lod_chain keeps positions only: its levels are replayed from contractions; use "
                         "simplify(texture=...) for a textured result")
    options.setdefault("attributes", None)
    if "refit" not in options and "method.refit" not in options:  # as a setting may be named: flat or dotted
        options["refit"] = 0  # levels are replays of the contractions, which a re-fit would not reach
    if isinstance(ratios, (int, float, np.number)):
        raise ValueError(f"ratios takes a list of ratios, one per level, got {ratios!r} (ratios=[{ratios!r}])")
    try:
        ratios = tuple(float(r) for r in ratios)
    except (TypeError, ValueError):
        raise ValueError(f"ratios takes a list of ratios in (0, 1], one per level, got {ratios!r}") from None
    if not ratios:
        raise ValueError("give at least one ratio")
    for r in ratios:
        if not 0 < r <= 1:
            raise ValueError(f"ratios must be in (0, 1] (the fraction of faces to keep), got {r}")
    for key in REFUSED:
        if key in options:
            raise ValueError(f"lod_chain takes its targets from ratios=, not {key}=")
    if options.get("partition"):
        raise ValueError("lod_chain cannot run partitioned: a partitioned run keeps no record to replay the "
                         "levels from")
    if _splits(options):
        raise ValueError("lod_chain with ESQEM needs split_factor=None (CLI: --split-factor none): edge splits "
                         "come after all contractions, and the levels are replayed from the contractions")
    if options.get("partition") is None:  # the size check, with its advice for a chain
        from . import fits

        fits.check(mesh, what="lod_chain (qemjax lod)")
        options["partition"] = False
    res = simplify(mesh, ratio=min(ratios), **options, **{CALLER: 1})  # warnings: at our caller
    m, last = len(res.input_faces), res.record.faces_out
    unreplayed = res._unreplayed()
    if unreplayed:  # attributes asked for: the levels would pass for textured or coloured meshes
        warnings.warn(f"lod_chain's levels have positions and faces only: {unreplayed}; chain.result keeps them",
                      stacklevel=2)
    # the record's own replay (res.replay would warn again for each level)
    return LodChain([res.record.replay(max(max(1, int(round(r * m))), last)) for r in ratios], ratios, res)
