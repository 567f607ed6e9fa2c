"""The nearest boundary vertex of points in the meridian plane, compiled (issue 16): the answers of
``scipy.spatial.cKDTree.query`` on the same vertices, bit for bit.

The payout's clearance envelope, its line check and its extension to the line ask for the distance from
hundreds of thousands of eye positions (z, r) to the mandrel's boundary polyline (a few thousand vertices);
the laminate's transitions ask the same of the free fibre's samples.  A k-d tree answers in ~0.5 µs a
point.  The boundary is a curve sorted along z (the generatrix, plus the end faces at constant z), so a
search outward along z over blocks of consecutive vertices, each block skipped by its bounding box, finds
the nearest vertex after a few dozen distance evaluations.

The same answer as the k-d tree:

- the squared distance of every vertex is ``dz*dz + dr*dr`` in that order (the tree's sum over the
  dimensions; no fused multiply-add), and the distance its correctly rounded square root;
- the vertex found has the least squared distance; a block is skipped or the search ends only where the
  bounding box's squared gap (a lower bound of every vertex's squared distance in it, rounding included:
  subtraction, squaring and addition are monotone) is *greater* than the best so far, so every vertex at
  the least distance is seen;
- where two vertices share the least distance the tree's choice depends on its traversal, so such points
  are flagged (``tie``) and the caller asks the tree for them (rare: a point exactly midway);
- ``ub2``: only vertices with a squared distance below it count (the tree's ``distance_upper_bound``,
  strict); none found gives +inf and the index ``n`` (the tree's answer);
- a query with a NaN or infinite coordinate is flagged too and goes to the tree, which refuses it
  (``ValueError``) as it always did.

:class:`NearestVertex` is the caller's side: it runs the kernel where it is built (:mod:`engine.aot`; this
module is one of its sources) and the k-d tree otherwise, built only when first needed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

BLOCK = 16
"""Vertices per block (consecutive in z) of the search."""

CHUNK = 2048
"""Query points per kernel call: an ahead-of-time kernel does not release the GIL, so a long call would
stall the GUI's thread (its heartbeat test allows 100 ms; one run with 8 192-point chunks came to 104 ms
under the CI's load); a chunk takes well under 2 ms."""


def _build_nearest() -> Any:
    """numba's kernel ``(vz, vr, order, bz0, bz1, br0, br1, block, qz, qr, ub2, d2, j, tie) -> 0`` (see
    :class:`NearestVertex`)."""
    import math

    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _nearest(vz, vr, order, bz0, bz1, br0, br1, block, qz, qr, ub2, d2_out, j_out, tie_out):
        # pragma: no cover - compiled
        n = vz.shape[0]
        nb = bz0.shape[0]
        for q in range(qz.shape[0]):
            z = qz[q]
            r = qr[q]
            if not (math.isfinite(z) and math.isfinite(r)):
                d2_out[q] = np.inf
                j_out[q] = n
                tie_out[q] = True
                continue
            # the last block starting at or below z (block 0 if none)
            lo, hi = 0, nb - 1
            while lo < hi:
                mid = (lo + hi + 1) // 2
                if bz0[mid] <= z:
                    lo = mid
                else:
                    hi = mid - 1
            kb = lo
            best = ub2
            bi = -1
            ties = 0
            for side in range(2):
                k = kb if side == 0 else kb + 1
                step = -1 if side == 0 else 1
                while 0 <= k < nb:
                    gz = 0.0
                    if bz0[k] - z > 0.0:
                        gz = bz0[k] - z
                    elif z - bz1[k] > 0.0:
                        gz = z - bz1[k]
                    gz2 = gz * gz
                    if gz2 > best:
                        break  # every block further this way is at least as far in z
                    gr = 0.0
                    if br0[k] - r > 0.0:
                        gr = br0[k] - r
                    elif r - br1[k] > 0.0:
                        gr = r - br1[k]
                    if gz2 + gr * gr <= best:
                        i1 = min((k + 1) * block, n)
                        for i in range(k * block, i1):
                            dz = z - vz[i]
                            dr = r - vr[i]
                            d2 = dz * dz
                            d2 = d2 + dr * dr
                            if d2 < best:
                                best = d2
                                bi = i
                                ties = 0
                            elif d2 == best and bi >= 0:
                                ties += 1
                    k += step
            if bi < 0:
                d2_out[q] = np.inf
                j_out[q] = n
                tie_out[q] = False
            else:
                d2_out[q] = best
                j_out[q] = order[bi]
                tie_out[q] = ties > 0
        return 0

    return _nearest


_KERNEL: list[Any] = []


def kernel() -> Any | None:
    """The ahead-of-time kernel ``nearest_vertex`` without its argument check, or None where it does not run."""
    from engine import aot

    got = aot.raw_kernels(("nearest_vertex",), _KERNEL)
    return None if got is None else got[0]


class NearestVertex:
    """The nearest of the vertices ``(z, r)`` (mm) to query points: :meth:`query` answers as
    ``scipy.spatial.cKDTree(np.column_stack([z, r])).query(P, distance_upper_bound=ub)`` does, bit for bit
    (distances and indices), by the compiled search where it is built."""

    def __init__(self, z: NDArray[np.float64], r: NDArray[np.float64]) -> None:
        z = np.ascontiguousarray(z, dtype=np.float64)
        r = np.ascontiguousarray(r, dtype=np.float64)
        self.points = np.column_stack([z, r])
        self.n = int(z.size)
        self._tree: Any = None
        self._kernel = kernel() if self.n > 0 and bool(np.isfinite(self.points).all()) else None
        if self._kernel is not None:
            order = np.argsort(z, kind="stable").astype(np.int64)
            self.order = np.ascontiguousarray(order)
            self.vz = np.ascontiguousarray(z[order])
            self.vr = np.ascontiguousarray(r[order])
            starts = np.arange(0, self.n, BLOCK)
            ends = np.minimum(starts + BLOCK, self.n) - 1
            self.bz0 = np.ascontiguousarray(self.vz[starts])
            self.bz1 = np.ascontiguousarray(self.vz[ends])
            self.br0 = np.ascontiguousarray(np.minimum.reduceat(self.vr, starts))
            self.br1 = np.ascontiguousarray(np.maximum.reduceat(self.vr, starts))

    @property
    def tree(self) -> Any:
        """The k-d tree of the vertices (``scipy.spatial.cKDTree``), built on first use."""
        if self._tree is None:
            from engine._lightimport import ckdtree

            self._tree = ckdtree()(self.points)
        return self._tree

    def query(self, P: NDArray[np.float64], distance_upper_bound: float = np.inf
              ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distances (mm) and indices of the nearest vertex to each row (z, r) of ``P``; +inf and ``n`` where none
        is nearer than ``distance_upper_bound`` (strictly)."""
        P = np.asarray(P, dtype=np.float64).reshape(-1, 2)
        ub = float(distance_upper_bound)
        if self._kernel is None or not ub > 0.0:
            return self.tree.query(P, distance_upper_bound=ub)
        qz = np.ascontiguousarray(P[:, 0])
        qr = np.ascontiguousarray(P[:, 1])
        m = qz.size
        d2 = np.empty(m)
        j = np.empty(m, dtype=np.int64)
        tie = np.empty(m, dtype=np.bool_)
        for a in range(0, m, CHUNK):  # the kernel holds the GIL: a GUI's thread gets it between chunks
            b = min(a + CHUNK, m)
            self._kernel(self.vz, self.vr, self.order, self.bz0, self.bz1, self.br0, self.br1, BLOCK, qz[a:b],
                         qr[a:b], ub * ub, d2[a:b], j[a:b], tie[a:b])
        d = np.sqrt(d2)
        if tie.any():
            d[tie], j[tie] = self.tree.query(P[tie], distance_upper_bound=ub)
        return d, j
