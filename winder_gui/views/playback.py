"""Playback of a winding program in machine time, and the band laid on the mandrel (no widgets, no VTK).

The 3D view plays the program by machine seconds, not by frames: :func:`point_times` gives the
program time at every winding-line point from the NC blocks (each block's time spread over its
points by arc length), :class:`Timeline` maps a time to an animation frame and a circuit to its first
frame, and :func:`band_strip` builds the band as a strip of true width on the mandrel (the line's
points offset by ±w/2 along the surface, across the fibre), whose first ``k`` quads are the band
laid up to a time (:meth:`BandStrip.quads_until`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

SPEEDS = (1, 10, 100, 1000)
"""Playback speeds: machine seconds per wall-clock second."""
BAND_POINTS = 20_000
"""Most points of the winding line used for the band drawn in 3D (the band's quads follow them)."""


def point_times(n_points: int, block_index: NDArray, block_time: NDArray, s: NDArray | None = None) -> FloatArray:
    """Program time (s) at each of ``n_points`` winding-line points.

    ``block_index`` (n+1) are the path-point indices of the block boundaries and ``block_time`` (n)
    the blocks' times, as in :class:`engine.blocks.Blocks`; inside a block the time grows with the
    arc length ``s`` (mm) of the line (evenly per point without ``s``).  Points outside the blocks
    keep the time of the nearest boundary.
    """
    idx = np.asarray(block_index, dtype=float)
    t_b = np.concatenate([[0.0], np.cumsum(np.asarray(block_time, dtype=float))])
    if idx.size < 2:
        return np.zeros(n_points)
    if s is None:
        return np.interp(np.arange(n_points, dtype=float), idx, t_b)
    s = np.asarray(s, dtype=float)
    s_b = np.interp(idx, np.arange(s.size, dtype=float), s)
    # strictly increasing s at the boundaries for interp (blocks of zero length keep their time)
    return np.interp(s, s_b, t_b) if np.all(np.diff(s_b) > 0) else np.interp(np.arange(n_points, dtype=float), idx, t_b)


@dataclass(frozen=True)
class Timeline:
    """Animation frames in machine time.

    ``times`` (s, non-decreasing) and ``circuits`` of each frame (the winding-line point each frame
    shows).
    """

    times: FloatArray
    circuits: NDArray[np.int64]

    @property
    def total_s(self) -> float:
        return float(self.times[-1]) if self.times.size else 0.0

    def frame_at(self, t: float) -> int:
        """The last frame at or before time ``t`` (s)."""
        if self.times.size == 0:
            return 0
        return int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, self.times.size - 1))

    def circuit_start(self, circuit: int) -> int:
        """The first frame of ``circuit`` (the nearest circuit that has frames)."""
        if self.circuits.size == 0:
            return 0
        hits = np.flatnonzero(self.circuits == circuit)
        if hits.size:
            return int(hits[0])
        return int(np.argmin(np.abs(self.circuits - circuit)))


@dataclass(frozen=True)
class BandStrip:
    """The band as quads between its two edges (view frame, mm).

    ``points`` (2m, 3): left edge then right edge, ``times`` (m) the program time of each of the
    ``m`` centre points, ``scalars`` per point pair (colour), ``width_mm`` the band width.
    Quad ``i`` joins centre points ``i`` and ``i + 1``.
    """

    points: FloatArray
    times: FloatArray
    width_mm: float

    @property
    def m(self) -> int:
        return self.times.size

    def quads(self) -> NDArray[np.int64]:
        """VTK cell connectivity of all quads: (4, a, b, c, d) per quad, flat."""
        m = self.m
        i = np.arange(max(m - 1, 0), dtype=np.int64)
        return np.column_stack([np.full_like(i, 4), i, i + 1, m + i + 1, m + i]).ravel()

    def quads_until(self, t: float) -> int:
        """How many quads are laid at time ``t`` (s): those whose both ends were wound by then."""
        if self.m < 2:
            return 0
        return int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, self.m - 1))


def band_strip(xyz: FloatArray, normal: FloatArray, times: FloatArray, width_mm: float,
               lift_mm: float = 0.0) -> BandStrip:
    """The band of ``width_mm`` centred on the polyline ``xyz`` (n, 3) lying on a surface with unit
    outward ``normal`` (n, 3): its edges are ``xyz ± w/2 · b`` with ``b = normal × tangent`` (across
    the fibre, in the surface), lifted by ``lift_mm`` along the normal; ``times`` (s) per point."""
    xyz = np.asarray(xyz, dtype=float)
    nrm = np.asarray(normal, dtype=float)
    tan = np.gradient(xyz, axis=0) if xyz.shape[0] > 1 else np.zeros_like(xyz)
    across = np.cross(nrm, tan)
    norm = np.linalg.norm(across, axis=1)
    ok = norm > 1e-12
    across[ok] /= norm[ok, None]
    # a point where the tangent vanishes (a repeated point) takes its neighbour's direction
    if not ok.all() and ok.any():
        good = np.flatnonzero(ok)
        nearest = good[np.clip(np.searchsorted(good, np.flatnonzero(~ok)), 0, good.size - 1)]
        across[~ok] = across[nearest]
    centre = xyz + lift_mm * nrm
    half = 0.5 * float(width_mm)
    pts = np.vstack([centre + half * across, centre - half * across])
    return BandStrip(pts, np.asarray(times, dtype=float), float(width_mm))
