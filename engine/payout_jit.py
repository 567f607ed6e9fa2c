"""Compiled steps of the payout's interval propagation (issue 16): :class:`engine.payout._Tube`'s map g,
its forward closure and its Newton sweeps, bit for bit the numpy code's answers.

The narrowest-band and max-min searches of the min-range law (:func:`engine.payout._fast_lp13`, ``_fast_lp14``)
bisect on the pull-speed bounds; each trial is a forward closure of ~650 points: dozens of sweeps and
evaluations of g (~3 000 per layer, ~30 numpy operations each on small arrays), so the cost was numpy's
per-call overhead, not arithmetic.  These kernels do the same operations on every element, in the same
order (IEEE arithmetic, ``sqrt``, ``sin``, ``cos`` and ``hypot`` give the same bits as numpy's); the one
function whose bits differ between numpy and a compiled loop is ``arctan2`` (numpy's SIMD ``arctan2``
differs from the C library's in the last bit for ~7 % of arguments on AVX-512 machines), so g runs as
two kernels around numpy's own ``arctan2``: :func:`tube_pre` (the free length l(μ) and the arguments of
arctan2), then ``numpy.arctan2``, then :func:`tube_post` (the rest).  Where the kernels do not run (not
built, switched off) the numpy code runs: the same answers, slower.

The kernels run compiled ahead of time (:mod:`engine.aot`; this module is one of its sources) or not at
all: importing numba for them would cost more than they save in a one-shot run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

G_ROWS = ("ra", "b2", "r2", "ds", "af", "rf", "cf", "vf", "vt", "rt", "at", "ct", "theta_t")
"""Rows of the geometry table the g kernels read (one column per interval of the grid)."""


def _build_tube() -> tuple[Any, Any, Any, Any]:
    """numba's kernels ``(pre, post, step, newton)`` of :class:`engine.payout._Tube` (see the functions of the
    same names below for their arguments)."""
    import math

    import numba

    opts = dict(cache=True, nogil=True, error_model="numpy")

    @numba.njit(inline="always")
    def _mx(a, b):  # pragma: no cover - compiled; numpy.maximum: a if a >= b or a is NaN, else b
        return a if (a >= b or a != a) else b

    @numba.njit(inline="always")
    def _mn(a, b):  # pragma: no cover - compiled; numpy.minimum
        return a if (a <= b or a != a) else b

    @numba.njit(**opts)
    def _pre(G, mu, idx, full, k, l_out, y_out, x_out):  # pragma: no cover - compiled
        ra, b2, r2, af, rf, cf = G[0], G[1], G[2], G[4], G[5], G[6]
        for j in range(mu.shape[0]):
            i = j if full else idx[j]
            m = mu[j]
            if k:
                B = m + ra[i]
                m2 = m * m
                m2 = m2 - r2[i]
                disc = B * B
                disc = disc - b2[i] * m2
                disc = math.sqrt(_mx(disc, 0.0))
                if B <= 0:
                    lv = m2 / (B - disc)
                else:
                    lv = (B + disc) / b2[i]
            else:
                lv = m
            l_out[j] = lv
            y_out[j] = cf[i] * lv
            xv = af[i] * lv
            x_out[j] = xv + rf[i]
        return 0

    @numba.njit(**opts)
    def _post(G, l, atan, idx, full, k, out):  # pragma: no cover - compiled
        ds, vf, vt, rt, at, ct, th = G[3], G[7], G[8], G[9], G[10], G[11], G[12]
        inf = np.inf
        for j in range(l.shape[0]):
            i = j if full else idx[j]
            l_sag = l[j] - ds[i]
            phi = vf[i] + atan[j]
            phi = phi - vt[i]
            sp = math.sin(phi)
            cp = math.cos(phi)
            den = ct[i] * cp
            den = den - at[i] * sp
            if phi < th[i] and den > 0:
                l_rot = rt[i] * sp / den
            else:
                l_rot = inf
            if phi <= 0:
                l_rot = 0.0
            need = _mx(_mx(l_sag, l_rot), 0.0)
            if not k:
                out[j] = need
            elif need == inf:
                out[j] = inf
            else:
                h = at[i] * need
                h = h + rt[i]
                out[j] = need - math.hypot(h, ct[i] * need)
        return 0

    @numba.njit(inline="always")
    def _sweep(x, A, cap, C, out):  # pragma: no cover - compiled
        # C = [0, cumsum(A)]; out = minimum(C + maximum.accumulate(x - C), cap), element by element
        n = x.shape[0]
        s = 0.0
        for i in range(n - 1):
            s = s + A[i] if i else A[0]
            C[i + 1] = s
        run = x[0] - C[0]
        out[0] = _mn(C[0] + run, cap[0])
        for i in range(1, n):
            run = _mx(run, x[i] - C[i])
            out[i] = _mn(C[i] + run, cap[i])

    @numba.njit(**opts)
    def _step(x, A, y, gv, h, cap, C, tol, big, inc, y_new, yd, dy, info):  # pragma: no cover - compiled
        n = y.shape[0]
        exact = n
        worst = 0.0
        first_res = 0.0
        for i in range(n - 1):
            res = _mx(_mx(x[i + 1], y[i] + A[i]), gv[i]) - y[i + 1]
            a = abs(res)
            if a > tol and exact == n:
                exact = i + 1
                first_res = res
            worst = _mx(worst, a) if i else a
        for i in range(exact):
            if y[i] > h[i] + tol:
                return 0  # above mu_hi: infeasible
        if exact == n:
            return 1  # the recursion holds everywhere: y is the answer
        if y[exact] + first_res > h[exact] + tol:
            return 0
        info[0] = worst
        for i in range(n - 1):
            g = gv[i] if math.isfinite(gv[i]) else y[i] + big
            inc[i] = _mx(A[i], g - y[i])  # the frozen increments
            d = 1e-7 * _mx(1.0, abs(y[i]))  # the Newton step's difference quotient, should it be taken
            dy[i] = d
            yd[i] = y[i] + d
        _sweep(x, inc, cap, C, y_new)
        return 2

    @numba.njit(**opts)
    def _newton(x, y, z, A, cap, C, gv, g2, dy, tol, big, inc, out):  # pragma: no cover - compiled
        n = y.shape[0]
        s1 = np.empty(n - 1)
        base = np.empty(n - 1)
        for i in range(n - 1):
            slope = (g2[i] - gv[i]) / dy[i]
            gfin = math.isfinite(gv[i])
            if not (gfin and math.isfinite(slope)):
                slope = 1.0
            base[i] = (gv[i] if gfin else y[i] + big) - y[i]
            s1[i] = slope - 1.0
        cur = z.copy()
        nxt = np.empty(n)
        for _it in range(60):
            for i in range(n - 1):
                inc[i] = _mx(A[i], base[i] + s1[i] * (cur[i] - y[i]))
            _sweep(x, inc, cap, C, nxt)
            for i in range(n):
                if not math.isfinite(nxt[i]):
                    out[:] = cur
                    return 0
            d = 0.0
            for i in range(n):
                d = _mx(d, abs(nxt[i] - cur[i])) if i else abs(nxt[i] - cur[i])
            cur, nxt = nxt, cur
            if d <= tol:
                break
        out[:] = cur
        return 0

    return _pre, _post, _step, _newton


def kernels() -> tuple[Any, Any, Any, Any] | None:
    """The ahead-of-time kernels ``(pre, post, step, newton)`` without their argument checks (the callers in
    :class:`engine.payout._Tube` pass arrays they made: C-contiguous float64, int64 indices), or None where
    they do not run (not built, stale, switched off): the numpy code runs."""
    if _KERNELS:
        return _KERNELS[0]
    from engine import aot

    got = aot.load()
    names = ("tube_pre", "tube_post", "tube_step", "tube_newton")
    out = tuple(got[n].fn for n in names) if all(n in got for n in names) else None
    _KERNELS.append(out)
    return out


_KERNELS: list[Any] = []
