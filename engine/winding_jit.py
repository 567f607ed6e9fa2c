"""The Clairaut pass's RK4 integration compiled (issue 16): :func:`rk4` is
:func:`engine.winding_clairaut.integrate`'s loop, bit for bit.

A pass of a non-geodesic (or geodesic, by Clairaut's relation) winding line is shot by Newton's method on
λ, each trial an RK4 integration of ODE (3) over ~2 000 steps in Python floats: the vessel's polar layer
spends ~0.08 s there before its first layer can go to its own process, its helical layer ~0.1 s closing
the pattern by angle.  The kernel runs the same IEEE operations in the same order on the same float64
values (a Python float is one), so it gives the same numbers.  It runs compiled ahead of time
(:mod:`engine.aot`; this module is one of its sources) or not at all (the Python loop runs).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _build_rk4() -> Any:
    """numba's kernel ``(h, AL, AM, AR, BL, BM, BR, i0, i1, c0, lam, sens, lo, hi, has_lo, has_hi, cs, ss) -> 0``:
    :func:`engine.winding_clairaut.integrate` into ``cs`` (and ``ss`` with ``sens``), |i1 − i0| + 1 values."""
    import math

    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _rk4(hs, AL, AM, AR, BL, BM, BR, i0, i1, c0, lam, sens, lo, hi, has_lo, has_hi, cs, ss):
        # pragma: no cover - compiled
        step = 1 if i1 >= i0 else -1
        c = c0
        s = 0.0
        cs[0] = c
        if sens:
            ss[0] = s
        j = i0
        n = 1
        while j != i1:
            if step > 0:
                k = j
                h = hs[k]
                a1, b1, a2, b2, a3, b3 = AL[k], BL[k], AM[k], BM[k], AR[k], BR[k]
            else:
                k = j - 1
                h = -hs[k]
                a1, b1, a2, b2, a3, b3 = AR[k], BR[k], AM[k], BM[k], AL[k], BL[k]
            hh = 0.5 * h
            g1 = a1 * c * c + b1
            k1 = lam * g1
            c2 = c + hh * k1
            g2 = a2 * c2 * c2 + b2
            k2 = lam * g2
            c3 = c + hh * k2
            g3 = a2 * c3 * c3 + b2
            k3 = lam * g3
            c4 = c + h * k3
            g4 = a3 * c4 * c4 + b3
            k4 = lam * g4
            if sens:
                m1 = g1 + 2.0 * lam * a1 * c * s
                s2 = s + hh * m1
                m2 = g2 + 2.0 * lam * a2 * c2 * s2
                s3 = s + hh * m2
                m3 = g3 + 2.0 * lam * a2 * c3 * s3
                s4 = s + h * m3
                m4 = g4 + 2.0 * lam * a3 * c4 * s4
                s = s + h * (m1 + 2.0 * m2 + 2.0 * m3 + m4) / 6.0
                ss[n] = s
            c = c + h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
            j += step
            if has_lo and c < lo[j]:
                c = lo[j]
            if has_hi and c > hi[j]:
                c = hi[j]
            if not math.isfinite(c) or abs(c) > 1e12:
                c = math.copysign(1e12, c) if math.isfinite(c) else 1e12
            cs[n] = c
            n += 1
        return 0

    return _rk4


_KERNEL: list[Any] = []
_EMPTY = np.zeros(0)


def _kernel() -> Any:
    from engine import aot

    got = aot.raw_kernels(("clairaut_rk4",), _KERNEL)
    return None if got is None else got[0]


def rk4(grid: Any, i0: int, i1: int, c0: float, lam: float, sens: bool, lo: Any, hi: Any
        ) -> tuple[list[float], list[float] | None] | None:
    """:func:`engine.winding_clairaut.integrate` by the compiled kernel (the same lists of floats), or None
    where it does not run (not built, switched off, node indices outside the grid)."""
    kern = _kernel()
    if kern is None:
        return None
    arrs = getattr(grid, "_rk4_arrays", None)
    if arrs is None:
        AL, AM, AR = grid.A
        BL, BM, BR = grid.B
        arrs = tuple(np.ascontiguousarray(np.array(v, dtype=np.float64)) for v in (grid.h, AL, AM, AR, BL, BM, BR))
        grid._rk4_arrays = arrs
    nodes = arrs[0].shape[0] + 1
    i0, i1 = int(i0), int(i1)
    if not (0 <= i0 < nodes and 0 <= i1 < nodes and all(a.shape[0] == nodes - 1 for a in arrs)):
        return None
    lo_a = _EMPTY if lo is None else np.ascontiguousarray(lo, dtype=np.float64)
    hi_a = _EMPTY if hi is None else np.ascontiguousarray(hi, dtype=np.float64)
    if (lo is not None and lo_a.shape != (nodes,)) or (hi is not None and hi_a.shape != (nodes,)):
        return None
    m = abs(i1 - i0) + 1
    cs = np.empty(m)
    ss = np.empty(m if sens else 0)
    kern(*arrs, i0, i1, float(c0), float(lam), bool(sens), lo_a, hi_a, lo is not None, hi is not None, cs, ss)
    return cs.tolist(), (ss.tolist() if sens else None)
