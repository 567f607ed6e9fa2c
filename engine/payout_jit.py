"""Compiled steps of the payout (issue 16), bit for bit the numpy code's answers: :class:`engine.payout._Tube`'s
map g, its forward closure, its Newton sweeps and its edge searches; and the Newton steps of the (15)
interior point (:func:`engine.payout._ipm_compiled`).

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


def _build_edge() -> tuple[Any, Any]:
    """numba's kernels ``(mid, upd)`` of :meth:`engine.payout._Tube._edge`'s Illinois steps: ``mid`` the next
    trial points (1 where every bracket is already narrow enough), ``upd`` the brackets after g there; numpy's
    operations element by element (its ``clip``, ``where``, NaN-propagating ``max``)."""
    import math

    import numba

    opts = dict(cache=True, nogil=True, error_model="numpy")

    @numba.njit(**opts)
    def _mid(a, b, fa, fb, it, tol, m):  # pragma: no cover - compiled
        n = a.shape[0]
        wmax = -np.inf
        for i in range(n):
            w = b[i] - a[i]
            if w != w or wmax != wmax:
                wmax = np.nan
            elif w > wmax:
                wmax = w
        if wmax <= tol:
            return 1
        side = it % 3 != 2
        for i in range(n):
            w = b[i] - a[i]
            v = a[i] - fa[i] * w / (fb[i] - fa[i])
            if math.isfinite(v) and side:
                lo = a[i] + 0.25 * tol
                hi = b[i] - 0.25 * tol
                v = v if (v != v or v > lo) else lo      # numpy.clip's min(max(v, lo), hi), NaN kept
                v = v if (v != v or v < hi) else hi
                m[i] = v
            else:
                m[i] = 0.5 * (a[i] + b[i])
        return 0

    @numba.njit(**opts)
    def _upd(a, b, fa, fb, last, m, gm, B):  # pragma: no cover - compiled
        for i in range(a.shape[0]):
            fm = (gm[i] - m[i]) - B[i]
            bad = fm > 0
            if bad:
                fa[i] = 0.5 * fa[i] if last[i] > 0 else fa[i]
                fb[i] = fm
                b[i] = m[i]
                last[i] = 1.0
            else:
                fa[i] = fm
                fb[i] = 0.5 * fb[i] if last[i] < 0 else fb[i]
                a[i] = m[i]
                last[i] = -1.0
        return 0

    return _mid, _upd


def _build_ipm() -> tuple[Any, Any, Any, Any, Any]:
    """numba's kernels ``(res, fac, rhs, aff, fin)`` of :func:`engine.payout._ipm_qp`'s Newton step on the cyclic
    (15) problem (see :func:`engine.payout._ipm_compiled` for the order they run in).  Sparse products as
    SciPy's ``csr_matvec``/``csc_matvec`` make them (row by row from 0.0 / column by column), dot products
    as numpy's pairwise ``add.reduce``, ``bincount`` index by index, maxima and minima propagating NaN as
    numpy's and Python's ``min`` as Python's: the numpy code's bits."""
    import math

    import numba

    opts = dict(cache=True, nogil=True, error_model="numpy")

    @numba.njit(inline="always")
    def _block(a, lo, n):  # pragma: no cover - compiled; numpy's pairwise_sum for n <= 128
        if n < 8:
            res = 0.0
            for i in range(n):
                res += a[lo + i]
            return res
        r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
        r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
        i = 8
        top = n - (n % 8)
        while i < top:
            r0 += a[lo + i]
            r1 += a[lo + i + 1]
            r2 += a[lo + i + 2]
            r3 += a[lo + i + 3]
            r4 += a[lo + i + 4]
            r5 += a[lo + i + 5]
            r6 += a[lo + i + 6]
            r7 += a[lo + i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[lo + i]
            i += 1
        return res

    @numba.njit
    def _sum(a):  # pragma: no cover - compiled; numpy.add.reduce(a) for 1-D float64
        # numpy's pairwise_sum: above 128 entries, the sum of the halves split at n/2 rounded down to a
        # multiple of 8; its recursion walked with an explicit stack (ahead-of-time code cannot recurse)
        n = a.shape[0]
        if n <= 128:
            return 0.0 + _block(a, 0, n)   # (numpy adds the sum to its identity, +0.0: -0.0 sums to +0.0)
        los = np.empty(64, np.int64)
        ns = np.empty(64, np.int64)
        stage = np.empty(64, np.int64)
        left = np.empty(64)
        sp = 0
        los[0], ns[0], stage[0] = 0, n, 0
        ret = 0.0
        have = False
        while True:
            if have:
                if sp < 0:
                    return 0.0 + ret
                if stage[sp] == 1:       # its first half summed: keep it, sum the second
                    left[sp] = ret
                    stage[sp] = 2
                    h = ns[sp] // 2
                    h -= h % 8
                    los[sp + 1], ns[sp + 1], stage[sp + 1] = los[sp] + h, ns[sp] - h, 0
                    sp += 1
                    have = False
                else:                    # both halves summed
                    ret = left[sp] + ret
                    sp -= 1
                continue
            k = ns[sp]
            if k <= 128:
                ret = _block(a, los[sp], k)
                sp -= 1
                have = True
            else:
                h = k // 2
                h -= h % 8
                stage[sp] = 1
                los[sp + 1], ns[sp + 1], stage[sp + 1] = los[sp], h, 0
                sp += 1

    @numba.njit(inline="always")
    def _csr(p, ix, d, v, out):  # pragma: no cover - compiled; scipy's csr_matvec into zeros
        for i in range(p.shape[0] - 1):
            acc = 0.0
            for jj in range(p[i], p[i + 1]):
                acc += d[jj] * v[ix[jj]]
            out[i] = acc

    @numba.njit(inline="always")
    def _csc(p, ix, d, v, out):  # pragma: no cover - compiled; scipy's csc_matvec into zeros
        out[:] = 0.0
        for j in range(p.shape[0] - 1):
            for ii in range(p[j], p[j + 1]):
                out[ix[ii]] += d[ii] * v[j]

    @numba.njit(inline="always")
    def _absmax(a):  # pragma: no cover - compiled; numpy.abs(a).max() (NaN if any)
        m = abs(a[0])
        for i in range(1, a.shape[0]):
            v = abs(a[i])
            if v != v or m != m:
                m = np.nan
            elif v > m:
                m = v
        return m

    @numba.njit(inline="always")
    def _step(v, dv):  # pragma: no cover - compiled; min(1.0, float(np.where(dv < 0, -v/dv, inf).min()))
        r = np.inf
        for i in range(v.shape[0]):
            q = -v[i] / dv[i] if dv[i] < 0 else np.inf
            if q != q or r != r:
                r = np.nan
            elif q < r:
                r = q
        return r if r < 1.0 else 1.0   # Python's min(1.0, r): 1.0 unless r < 1.0 (NaN too)

    @numba.njit(inline="always")
    def _pymin(a, b):  # pragma: no cover - compiled; Python's min(a, b)
        return b if b < a else a

    @numba.njit(**opts)
    def _res(Qp, Qi, Qd, qcsc, Ap, Ai, Ad, Tp, Ti, Td, x, s, z, c, b, Qx, Atz, rd, rp, w, info):
        # pragma: no cover - compiled
        if qcsc:
            _csc(Qp, Qi, Qd, x, Qx)
        else:
            _csr(Qp, Qi, Qd, x, Qx)
        _csr(Tp, Ti, Td, z, Atz)
        for i in range(x.shape[0]):
            rd[i] = (Qx[i] + c[i]) - Atz[i]
        _csr(Ap, Ai, Ad, x, rp)
        for i in range(s.shape[0]):
            rp[i] = (rp[i] - s[i]) - b[i]
        for i in range(s.shape[0]):
            w[i] = s[i] * z[i]
        info[0] = _sum(w)
        for i in range(x.shape[0]):
            w[i] = x[i] * Qx[i]
        info[1] = _sum(w[:x.shape[0]])
        for i in range(x.shape[0]):
            w[i] = c[i] * x[i]
        info[2] = _sum(w[:x.shape[0]])
        info[3] = _absmax(Qx)
        info[4] = _absmax(Atz)
        info[5] = _absmax(rp)
        info[6] = _absmax(rd)
        return 0

    @numba.njit(**opts)
    def _fac(s, z, j1, j2, iv, pair, w1, w2, qd, qo, dg, off):  # pragma: no cover - compiled
        m = qd.shape[0]
        b1 = np.zeros(m)
        b2 = np.zeros(m)
        b3 = np.zeros(m)
        for k in range(s.shape[0]):
            d = z[k] / s[k]
            b1[j1[k]] += (d * w1[k]) * w1[k]
            b2[j2[k]] += (d * w2[k]) * w2[k]
            b3[iv[k]] += (d * w1[k]) * w2[k] if pair[k] else 0.0
        for i in range(m):
            dg[i] = (qd[i] + b1[i]) + b2[i]
            off[i] = qo[i] + b3[i]
        return 0

    @numba.njit(**opts)
    def _rhs(Tp, Ti, Td, s, z, rp, rd, dsl, dz, second, kconst, rc, t, rhs):  # pragma: no cover - compiled
        for i in range(s.shape[0]):
            v = -s[i] * z[i]
            rc[i] = (v - dsl[i] * dz[i]) + kconst if second else v
            t[i] = (rc[i] - z[i] * rp[i]) / s[i]
        _csr(Tp, Ti, Td, t, rhs)
        for i in range(rhs.shape[0]):
            rhs[i] = -rd[i] + rhs[i]
        return 0

    @numba.njit(inline="always")
    def _newton_dir(x1, zu, g, c, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz):  # pragma: no cover - compiled
        fac = ((g * x1[0] + c * x1[x1.shape[0] - 1]) / g) / denom
        for i in range(x1.shape[0]):
            dx[i] = x1[i] - zu[i] * fac
        _csr(Ap, Ai, Ad, dx, dsl)
        for i in range(s.shape[0]):
            dsl[i] = dsl[i] + rp[i]
            dz[i] = (rc[i] - z[i] * dsl[i]) / s[i]

    @numba.njit(**opts)
    def _aff(x1, zu, g, c, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz, w, info):  # pragma: no cover - compiled
        _newton_dir(x1, zu, g, c, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz)
        a = _pymin(_step(s, dsl), _step(z, dz))
        for i in range(s.shape[0]):
            w[i] = (s[i] + a * dsl[i]) * (z[i] + a * dz[i])
        info[0] = a
        info[1] = _sum(w)
        return 0

    @numba.njit(**opts)
    def _fin(x1, zu, g, c, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz, x):  # pragma: no cover - compiled
        _newton_dir(x1, zu, g, c, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz)
        a = 0.995 * _pymin(_step(s, dsl), _step(z, dz))
        a = a if a < 1.0 else 1.0   # Python's min(1.0, a)
        ok = True
        for i in range(x.shape[0]):
            x[i] = x[i] + a * dx[i]
            ok = ok and math.isfinite(x[i])
        for i in range(s.shape[0]):
            s[i] = s[i] + a * dsl[i]
            z[i] = z[i] + a * dz[i]
            ok = ok and math.isfinite(z[i])
        return 1 if ok else 0

    return _res, _fac, _rhs, _aff, _fin


def kernels() -> tuple[Any, ...] | None:
    """The kernels ``(pre, post, step, newton, edge_mid, edge_upd)`` of :class:`engine.payout._Tube` (its callers
    pass arrays they made: C-contiguous float64, int64 indices), or None: the numpy code runs."""
    from engine import aot

    return aot.raw_kernels(("tube_pre", "tube_post", "tube_step", "tube_newton", "tube_edge_mid", "tube_edge_upd"),
                           _KERNELS)


_KERNELS: list[Any] = []


def ipm_kernels() -> tuple[Any, ...] | None:
    """The kernels ``(res, fac, rhs, aff, fin)`` of the (15) interior point (:func:`engine.payout._ipm_compiled`
    passes arrays it made), or None: the numpy code runs."""
    from engine import aot

    return aot.raw_kernels(("ipm_res", "ipm_fac", "ipm_rhs", "ipm_aff", "ipm_fin"), _IPM)


_IPM: list[Any] = []
