"""Coverage map of a winding line: where the band (of its true width) covers the mandrel, where it
leaves gaps and where bands overlap.

The surface is unwrapped to (m, v): ``m`` the meridian arc length from the left end of the mandrel
(mm; ``z`` when no mandrel is given) and ``v`` the angle about the axis (0…360°).  Each pass of the
line (``WindingLine.pass_id``) lays a band of width ``b`` centred on its path: a point of the surface
is under the band when its distance from the path, measured in the surface, is at most ``b/2``.  The
map is rasterised row by row: each sample of the path covers, in the rows within ``b/2`` of it, the
``v`` interval of half-width ``sqrt((b/2)² − Δm²) / r`` (a disc of radius ``b/2`` in the unwrapped
metric ``ds² = dm² + r² dv²``); the union over a pass's samples (spaced at most ``b/4`` apart) is
its band.  ``count`` is the number of passes covering each cell, split by direction of travel:
a helical layer covers each point once per direction when its pattern closes without gaps.

Checked against the closed form of :func:`engine.winding._coverage` (band width along a parallel
``b / cos β`` against the pitch ``2πr / p``) on a cylinder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CoverageMap:
    """Bands over the unwrapped surface.

    ``z_edges`` (nz+1) bin edges along the meridian arc length m (mm) — or z without a mandrel —,
    ``v_edges`` (nv+1) in degrees; ``forward``/``backward`` (nz, nv) passes of each direction
    covering each cell; ``count`` their sum; ``band_width_mm``.
    """

    z_edges: FloatArray
    v_edges: FloatArray
    forward: NDArray[np.int32]
    backward: NDArray[np.int32]
    band_width_mm: float
    meridian: bool
    z_samples: FloatArray | None = None
    m_samples: FloatArray | None = None
    """m(z) sampled (mm), to place z-based drawings (the centre lines) on the map's horizontal axis."""

    def to_map(self, z: FloatArray) -> FloatArray:
        """The map's horizontal coordinate (meridian length, or z) of axial positions ``z`` (mm)."""
        if not self.meridian or self.z_samples is None or self.m_samples is None:
            return np.asarray(z, dtype=float)
        return np.interp(z, self.z_samples, self.m_samples)

    @property
    def count(self) -> NDArray[np.int32]:
        return self.forward + self.backward

    @property
    def covered_fraction(self) -> float:
        """Share of the surface under at least one band."""
        return float(np.mean(self.count > 0))

    @property
    def gap_fraction(self) -> float:
        """Share of the surface under no band."""
        return 1.0 - self.covered_fraction

    @property
    def direction_fraction(self) -> tuple[float, float]:
        """Share covered by the forward and by the backward passes (each is one ply of the layer)."""
        return float(np.mean(self.forward > 0)), float(np.mean(self.backward > 0))

    @property
    def overlap_fraction(self) -> float:
        """Share where bands of one direction lie on each other (more than one ply per direction)."""
        return float(np.mean((self.forward > 1) | (self.backward > 1)))


def meridian_length(mandrel: Any, z: FloatArray) -> FloatArray:
    """Meridian arc length m(z) = ∫ sqrt(1 + r'(z)²) dz from the mandrel's left end (mm)."""
    zz = np.linspace(mandrel.z_min, mandrel.z_max, 4001)
    dr = np.gradient(mandrel.r(zz), zz)
    ds = np.sqrt(1.0 + dr**2)
    m = np.concatenate([[0.0], np.cumsum(0.5 * (ds[1:] + ds[:-1]) * np.diff(zz))])
    return np.interp(z, zz, m)


def coverage_map(line: Any, mandrel: Any = None, nz: int = 240, nv: int = 360,
                 band_width_mm: float | None = None) -> CoverageMap:
    """The coverage map of winding ``line`` (see the module docstring); ``mandrel`` for the meridian
    arc length (else z); ``band_width_mm`` defaults to the line's band width."""
    b = float(band_width_mm if band_width_mm is not None else line.band_width_mm)
    z = np.asarray(line.z, dtype=float)
    r = np.asarray(line.r, dtype=float)
    v = np.asarray(line.v, dtype=float)
    m = meridian_length(mandrel, z) if mandrel is not None else z
    lo, hi = float(m.min()), float(m.max())
    z_edges = np.linspace(lo, hi, nz + 1)
    v_edges = np.linspace(0.0, 360.0, nv + 1)
    rows_c = 0.5 * (z_edges[1:] + z_edges[:-1])
    dz = z_edges[1] - z_edges[0]
    fwd = np.zeros((nz, nv), dtype=np.int32)
    bwd = np.zeros((nz, nv), dtype=np.int32)
    pass_id = np.asarray(line.pass_id)
    direction = np.asarray(line.direction)
    half = 0.5 * b
    reach = int(math.ceil(half / dz)) + 1
    bounds = np.flatnonzero(np.diff(pass_id)) + 1
    starts = np.concatenate([[0], bounds])
    ends = np.concatenate([bounds, [pass_id.size]])
    for a, e in zip(starts, ends, strict=True):
        if e - a < 2:
            continue
        pm, pr, pv = m[a:e], r[a:e], v[a:e]
        # resample so that consecutive samples are at most b/4 apart in the surface
        seg = np.hypot(np.diff(pm), pr[:-1] * np.diff(pv))
        k = np.maximum(1, np.ceil(seg / (0.25 * b)).astype(int))
        t = np.concatenate([np.arange(kk) / kk + i for i, kk in enumerate(k)] + [[len(seg)]])
        idx = np.arange(pm.size, dtype=float)
        sm, sr, sv = np.interp(t, idx, pm), np.interp(t, idx, pr), np.interp(t, idx, pv)
        row0 = np.floor((sm - lo) / dz).astype(int)
        cover = np.zeros((nz, nv + 1), dtype=np.int32)
        for d in range(-reach, reach + 1):
            rows = row0 + d
            ok = (rows >= 0) & (rows < nz)
            if not ok.any():
                continue
            rr = rows[ok]
            dm = rows_c[rr] - sm[ok]
            inside = np.abs(dm) <= half
            if not inside.any():
                continue
            rr = rr[inside]
            w = np.sqrt(half**2 - dm[inside] ** 2) / np.maximum(sr[ok][inside], 1e-9)  # rad
            w = np.minimum(w, math.pi)
            c = np.degrees(np.mod(sv[ok][inside], 2.0 * math.pi))
            wd = np.degrees(w)
            _mark(cover, rr, c - wd, c + wd, nv)
        covered = np.cumsum(cover[:, :nv], axis=1) > 0
        tgt = fwd if int(np.median(direction[a:e])) >= 0 else bwd
        tgt += covered.astype(np.int32)
    zs = np.linspace(float(z.min()), float(z.max()), 2001)
    ms = meridian_length(mandrel, zs) if mandrel is not None else zs
    return CoverageMap(z_edges, v_edges, fwd, bwd, b, mandrel is not None, zs, ms)


def _mark(diff: NDArray[np.int32], rows: NDArray, v0: FloatArray, v1: FloatArray, nv: int) -> None:
    """Add the v intervals [v0, v1] (deg, possibly past 0 or 360) of ``rows`` to the difference array
    ``diff`` (+1 at the first cell, −1 after the last), splitting those that wrap."""
    # a cell is covered when its centre is: cells [s, e) with centres (j + ½)·Δ in [v0, v1]
    full = (v1 - v0) >= 360.0 - 360.0 / nv
    cells = 360.0 / nv
    a = np.ceil(v0 / cells - 0.5).astype(int)
    b = np.floor(v1 / cells - 0.5).astype(int) + 1
    empty = (b <= a) & ~full
    s = np.mod(a, nv)
    e = s + (b - a)
    s = np.where(full, 0, s)
    e = np.where(full, nv, e)
    rows, s, e = rows[~empty], s[~empty], e[~empty]
    wrap = e > nv
    e = np.where(wrap, e - nv, e)
    plain = ~wrap
    np.add.at(diff, (rows[plain], s[plain]), 1)
    np.add.at(diff, (rows[plain], np.minimum(e[plain], nv)), -1)
    # wrapped: [s, nv) and [0, e)
    np.add.at(diff, (rows[wrap], s[wrap]), 1)
    np.add.at(diff, (rows[wrap], np.full(wrap.sum(), nv)), -1)
    np.add.at(diff, (rows[wrap], np.zeros(wrap.sum(), dtype=int)), 1)
    np.add.at(diff, (rows[wrap], e[wrap]), -1)
