"""Cubic interpolating splines without importing ``scipy.interpolate`` (issue 16, start-up).

``scipy.interpolate`` costs about 0.25 s of CPU to import (it pulls in ``scipy.optimize``): a quarter
of a small example's whole ``winder run``.  The engine uses two things from it on every run: the
spline re-fit of a grown laminate surface (:class:`engine.mandrel.SplineSegment`) and X'(s), X''(s)
of the axis path at its knots for the time law.  :class:`CubicSpline` here builds the same banded
system as :class:`scipy.interpolate.CubicSpline` for the boundary conditions the engine uses
(not-a-knot, first or second derivative given), solves it with the same LAPACK routine
(``dgtsv``, as ``scipy.linalg.solve_banded`` calls it, without importing ``scipy.linalg``) and evaluates the
pieces with the same floating-point operations as SciPy's ``PPoly``.  The results are SciPy's bit
for bit (tests/test_knot_spline.py checks that on random data, inside and outside the knots).
Fewer than four knots fall back to SciPy itself (its special cases: a line or a parabola).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
# a boundary condition as CubicSpline's bc_type takes it: "not-a-knot" or (order 1 or 2, value)
BC = Any


def _slopes(x: FloatArray, y: FloatArray, bc: tuple[BC, BC]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(dx, secant slopes, derivatives s at the knots) of CubicSpline.__init__, row for row."""
    n = x.shape[0]
    dx = np.diff(x)
    dxr = dx.reshape((dx.shape[0],) + (1,) * (y.ndim - 1))
    slope = np.diff(y, axis=0) / dxr
    A = np.zeros((3, n))
    b = np.empty((n,) + y.shape[1:], dtype=float)
    A[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
    A[0, 2:] = dx[:-1]
    A[-1, :-2] = dx[1:]
    b[1:-1] = 3 * (dxr[1:] * slope[:-1] + dxr[:-1] * slope[1:])
    bc_start, bc_end = bc
    if bc_start == "not-a-knot":
        A[1, 0] = dx[1]
        A[0, 1] = x[2] - x[0]
        d = x[2] - x[0]
        b[0] = ((dxr[0] + 2 * d) * dxr[1] * slope[0] + dxr[0] ** 2 * slope[1]) / d
    elif bc_start[0] == 1:
        A[1, 0] = 1
        A[0, 1] = 0
        b[0] = bc_start[1]
    else:
        A[1, 0] = 2 * dx[0]
        A[0, 1] = dx[0]
        b[0] = -0.5 * bc_start[1] * dx[0] ** 2 + 3 * (y[1] - y[0])
    if bc_end == "not-a-knot":
        A[1, -1] = dx[-2]
        A[-1, -2] = x[-1] - x[-3]
        d = x[-1] - x[-3]
        b[-1] = (dxr[-1] ** 2 * slope[-2] + (2 * d + dxr[-1]) * dxr[-2] * slope[-1]) / d
    elif bc_end[0] == 1:
        A[1, -1] = 1
        A[-1, -2] = 0
        b[-1] = bc_end[1]
    else:
        A[1, -1] = 2 * dx[-1]
        A[-1, -2] = dx[-1]
        b[-1] = 0.5 * bc_end[1] * dx[-1] ** 2 + 3 * (y[-1] - y[-2])
    s = _solve_tridiagonal(A, b.reshape(n, -1)).reshape(b.shape)
    return dxr, slope, s


def _solve_tridiagonal(A: FloatArray, b: FloatArray) -> FloatArray:
    """``scipy.linalg.solve_banded((1, 1), A, b, overwrite_ab=True, overwrite_b=True, check_finite=False)``
    for float64 ``A`` (3, n >= 2) and ``b`` (n, k): the LAPACK call it makes (``dgtsv`` on A's three rows,
    overwritten), without importing ``scipy.linalg`` (engine._lightimport.flapack)."""
    from engine._lightimport import flapack

    if A.dtype != np.float64 or b.dtype != np.float64 or A.shape[1] < 2:
        from scipy.linalg import solve_banded

        return solve_banded((1, 1), A, b, overwrite_ab=True, overwrite_b=True, check_finite=False)
    _du2, _d, _du, x, info = flapack().dgtsv(A[2, :-1], A[1, :], A[0, 1:], b, True, True, True, True)
    if info > 0:
        raise np.linalg.LinAlgError("singular matrix")
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal gbsv/gtsv")
    return x


def _bc(bc_type: BC) -> tuple[BC, BC]:
    if isinstance(bc_type, str):
        return bc_type, bc_type
    a, b = bc_type
    return a, b


def _supported(bc: tuple[BC, BC]) -> bool:
    return all(c == "not-a-knot" if isinstance(c, str) else (len(c) == 2 and c[0] in (1, 2)) for c in bc)


class CubicSpline:
    """C2 cubic spline y(x) through the knots, SciPy's ``CubicSpline(x, y, axis=0, bc_type)`` bit for bit.

    ``x``: (n,) strictly increasing; ``y``: (n,) or (n, k); ``bc_type``: ``"not-a-knot"`` or a pair
    of ``"not-a-knot"`` / ``(1, dy/dx)`` / ``(2, d²y/dx²)``.  Calling ``spline(xq, nu)`` gives the
    ``nu``-th derivative (0, 1 or 2) at ``xq``, extrapolating the end pieces outside the knots.
    """

    def __init__(self, x: Any, y: Any, bc_type: BC = "not-a-knot") -> None:
        self.x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        bc = _bc(bc_type)
        self._scipy: Any = None
        if self.x.shape[0] < 4 or not _supported(bc):
            from scipy.interpolate import CubicSpline as _SciPy

            self._scipy = _SciPy(self.x, y, axis=0, bc_type=bc_type)
            return
        dxr, slope, s = _slopes(self.x, y, bc)
        t = (s[:-1] + s[1:] - 2 * slope) / dxr
        # CubicHermiteSpline's pieces: c0 (dx)^3 + c1 (dx)^2 + c2 dx + c3
        self.c = np.stack((t / dxr, (slope - s[:-1]) / dxr - t, s[:-1], y[:-1]))

    def __call__(self, xq: Any, nu: int = 0) -> FloatArray:
        """The ``nu``-th derivative at ``xq`` (shape ``xq.shape + y.shape[1:]``)."""
        if self._scipy is not None:
            return np.asarray(self._scipy(xq, nu))
        xq = np.asarray(xq, dtype=float)
        xf = xq.ravel()
        c, x = self.c, self.x
        i = np.clip(np.searchsorted(x, xf, side="right") - 1, 0, x.shape[0] - 2)
        dx = xf - x[i]
        tail = (1,) * (c.ndim - 2)
        dx = dx.reshape(dx.shape + tail)
        # PPoly's evaluate_poly1: res += c[k] * z * prefactor, z the running power of dx
        res = np.zeros((xf.shape[0],) + c.shape[2:])
        z: Any = 1.0
        for kp in range(4):
            if kp < nu:
                continue
            pre = 1.0
            for k in range(kp, kp - nu, -1):
                pre *= k
            res = res + c[3 - kp][i] * z * pre
            if kp < 3:
                z = z * dx
        res[np.isnan(xf)] = np.nan
        return res.reshape(xq.shape + c.shape[2:])


def knot_derivatives(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """dy/dx and d²y/dx² at the knots of the not-a-knot spline through ``(x, y)`` (y: (n,) or (n, k)),
    bit for bit ``scipy.interpolate.CubicSpline(x, y, axis=0)(x, 1)`` and ``(x, 2)``."""
    cs = CubicSpline(x, y)
    return cs(x, 1), cs(x, 2)
