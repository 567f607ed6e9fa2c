"""Compiled Chebyshev sums for the isotensoid dome (issue 16): :func:`chebval` is
``numpy.polynomial.chebyshev.chebval`` for a 1-D series on a 1-D array, bit for bit.

The isotensoid's evaluation (:class:`engine.mandrel.IsotensoidSegment`) inverts ζ(t) by Newton's method
on series of ~80 Chebyshev terms: numpy's Clenshaw recurrence makes ~3 array operations per term, and the
dome's evaluation was ~0.15 s of the serial start of the example vessel's run (before any layer could
go to its own process).  This kernel runs the same recurrence (the same operations on every element, in
the same order: IEEE arithmetic gives the same bits) in one compiled loop.  It runs compiled ahead of time
(:mod:`engine.aot`; this module is one of its sources) or not at all: importing numba for it would cost more
than it saves.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _build_chebval() -> Any:
    """numba's kernel ``(x, c, c0, c1, out) -> 0``: ``out = chebval(x, c)`` for ``len(c) >= 3`` (``c0``, ``c1``:
    work arrays of ``x``'s size), numpy's recurrence element by element."""
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _chebval(x, c, c0, c1, out):  # pragma: no cover - compiled
        n = x.shape[0]
        m = c.shape[0]
        a = c[m - 2]
        b = c[m - 1]
        for k in range(n):
            c0[k] = a
            c1[k] = b
        for i in range(3, m + 1):
            ci = c[m - i]
            for k in range(n):
                tmp = c0[k]
                c0[k] = ci - c1[k]
                c1[k] = tmp + c1[k] * (2.0 * x[k])        # numpy: x2 = 2 * x, then c1 * x2 (2x is exact)
        for k in range(n):
            out[k] = c0[k] + c1[k] * x[k]
        return 0

    return _chebval


def chebval(x: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """``numpy.polynomial.chebyshev.chebval(x, c)`` (float64 ``x`` of any shape, 1-D float64 ``c`` of at least
    3 terms) by the compiled kernel, bit for bit; None where it does not run (not built, switched off, no
    points, too few terms): the caller uses numpy's."""
    if x.size == 0 or c.ndim != 1 or c.shape[0] < 3:
        return None
    from engine import aot

    k = aot.load().get("chebval")
    if k is None:
        return None
    flat = np.ascontiguousarray(x, dtype=float).reshape(-1)
    n = flat.shape[0]
    out = np.empty(n)
    k(flat, np.ascontiguousarray(c, dtype=float), np.empty(n), np.empty(n), out)
    return out.reshape(x.shape)
