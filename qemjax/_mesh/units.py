"""The one place where mesh units meet the internal unit-extent frame.

`simplify` computes in coordinates divided by the bounding box's largest side (the *extent*), so every
kernel sees numbers of order one, and centred on the bounding box *of each connected part*: float32 then
keeps a part's positions to about 1e-7 of that part's own size, however far away the other parts are (one
triangle 1e6 away no longer costs a unit sphere its precision). Positions come back as
``x * scale + center[part]``; squared distances (quadric errors, ``max_error``) as ``e * scale²``. Within one
connected part the float32 limit stays: detail below about 1e-7 of the part's extent is rounded.

Those squared distances are reported in float64, so the extent must keep ``scale²`` (and errors of a few
hundred times it: boundary penalties) a normal float64: about 1e-150 ≤ extent ≤ 1e150. Outside that range,
and for coordinates so large that positions just outside the box would overflow, `normalize` refuses the
mesh with a ValueError that names the extent, rather than dividing by zero or returning NaN.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .arrays import column_bounds

MIN_EXTENT = 1e-150  # scale² ≥ 1e-300: a normal float64 (smallest 2.2e-308) with room for small errors
MAX_EXTENT = 1e150  # scale² ≤ 1e300: room for errors up to 1e8 × scale² below float64's 1.8e308
MAX_COORD = 1e300  # positions a few extents outside the box stay finite


class Frame(NamedTuple):
    """Maps between mesh units and the internal frame: centers (k,3) float64, the bounding-box centre of
    each part (mesh units); scale float (mesh units per internal unit, the whole mesh's largest side);
    part (n,) int64, each vertex's part (None: one part); sizes (k,) float64, each part's largest side
    over the whole mesh's (None: one part)."""

    centers: np.ndarray
    scale: float
    part: np.ndarray | None = None
    sizes: np.ndarray | None = None

    def part_scale2(self) -> np.ndarray | None:
        """(n,) float64 (size of each vertex's part)², to express a squared distance given at the whole
        mesh's extent at the extent of each part instead (None for one part)."""
        return None if self.part is None else np.square(self.sizes)[self.part]

    def positions_to_mesh(self, x: np.ndarray, verts: np.ndarray | None = None) -> np.ndarray:
        """(k,3) internal positions (any float dtype) of the vertices ``verts`` (k,) (their input ids;
        needed when the mesh has several parts) -> (k,3) float64 in mesh units."""
        if self.part is None:
            center = self.centers[0]
        else:
            if verts is None:
                raise ValueError("a frame of several parts needs the vertices the positions belong to")
            center = self.centers[self.part[verts]]
        return np.asarray(x, np.float64) * self.scale + center

    def errors_to_mesh(self, e):
        """Squared distances, internal -> mesh units² (float64; array or scalar)."""
        return np.asarray(e, np.float64) * (self.scale * self.scale)

    def error_to_internal(self, e: float) -> float:
        """One squared distance, mesh units² -> internal (inf stays inf; large values may become inf,
        which means no limit)."""
        return float(e) / (self.scale * self.scale)


def normalize(V: np.ndarray, dtype=np.float32, parts: tuple[int, np.ndarray] | None = None
              ) -> tuple[np.ndarray, Frame]:
    """(n,3) finite float64 vertices in mesh units -> ((n,3) ``dtype`` coordinates divided by the bounding
    box's largest side and centred on the box of each part, `Frame`). ``parts``: (count, (n,) labels) as
    `_topology.parts` gives (None: one part). Raises ValueError when the extent or the coordinates cannot
    be represented (see the module docstring)."""
    lo, hi = column_bounds(V)
    big = float(max(np.max(np.abs(lo)), np.max(np.abs(hi))))
    if big > MAX_COORD:
        raise ValueError(f"vertex coordinates reach {big:.3g}: too large to compute in float64 "
                         f"(limit {MAX_COORD:.0e}); rescale or translate the mesh")
    extent = float(np.max(hi - lo))  # ≤ 2·MAX_COORD: no overflow
    if extent == 0:
        raise ValueError("the mesh's extent is 0: all its vertices coincide")
    if extent < MIN_EXTENT:
        raise ValueError(f"the mesh's extent {extent:.3g} is too small to represent squared errors in "
                         f"float64 (minimum {MIN_EXTENT:.0e}); rescale the mesh")
    if extent > MAX_EXTENT:
        raise ValueError(f"the mesh's extent {extent:.3g} is too large to represent squared errors in "
                         f"float64 (maximum {MAX_EXTENT:.0e}); rescale the mesh")
    if parts is None or parts[0] <= 1:
        center = 0.5 * lo + 0.5 * hi  # (lo + hi) / 2 could overflow
        return ((V - center) / extent).astype(dtype), Frame(center[None], extent)
    count, label = parts
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], np.arange(count))
    Vs = V[order]
    plo, phi = np.minimum.reduceat(Vs, starts, axis=0), np.maximum.reduceat(Vs, starts, axis=0)
    centers = 0.5 * plo + 0.5 * phi
    sizes = np.max(phi - plo, axis=1) / extent
    return ((V - centers[label]) / extent).astype(dtype), Frame(centers, extent, label, sizes)
