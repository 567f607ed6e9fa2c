"""Compiled (numba) forward pass of the time-law DP, :func:`engine.timeparam._dp` (issue 16).

The numpy pass in :mod:`engine.timeparam` is the tested reference; this kernel computes the same
candidates in the same floating-point order and the same integer minimum (the departure level rides
in the low 12 bits of the float cost), so every finite ``J`` and its argmin are bit for bit those of
the numpy pass; a state no law reaches is not finite in both, possibly with other bits
(``tests/test_timeparam_speed.py`` compares both).

Which compiled kernels run (:func:`kernel`, :func:`_compiled`), all giving the same bits:

* numba's just-in-time kernels where they are loaded in this process (:func:`warm`; the GUI loads them in
  the background: they release the GIL, so its worker threads leave the window responsive);
* else the same kernels compiled ahead of time (:mod:`engine.aot`, built at install time): no
  numba at run time, well under a millisecond to load, so a one-shot ``winder run`` and the frozen build
  (which leaves numba out, see installer/README.md) get them from their first law;
* else numba's, imported when it pays: not when numba is missing or cannot compile/cache here, nor when it
  is not loaded yet and the problem is too small to repay importing it (~0.5 s once per process;
  :data:`IMPORT_THRESHOLD`);
* else none: the callers run the numpy code.  ``WINDER_NUMBA=0`` switches every compiled kernel off,
  ``WINDER_AOT=0`` the ahead-of-time ones.

The same module has the compiled DP windows and the convex hulls of the node groups.
numba's compiled code is cached on disk (``cache=True``: ``__pycache__`` next to this file, or numba's
per-user cache directory when that is not writable).
"""

from __future__ import annotations

import math
import os
import sys
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

# Without the ahead-of-time kernels, problems with at least this many nodes import numba if it is not
# loaded yet (:func:`engine.timeparam.parametrize` calls :func:`kernel` with its node count): importing numba
# and loading the cached kernels costs ~0.5 s once per process; a numpy tube pass on 3 000 nodes
# (M = 100) costs ~50 ms, a compiled one ~10 ms, and a program's laws run 10-20 passes.  Smaller
# problems (every shipped example: 332..1750 nodes) use numba only when it is loaded already.  (The node
# count also chooses the hull method, engine.timeparam._compiled_hull_for, whichever kernels run.)
IMPORT_THRESHOLD = 3000

SCRATCH_MAX_ELEMENTS = 1 << 20
"""Work arrays up to this many elements (8 MB of float64) are kept per thread between calls."""

_SCRATCH = threading.local()


def scratch(name: str, shape: tuple[int, ...], dtype: Any = np.float64, zero: bool = False) -> np.ndarray:
    """A work array of ``shape`` kept per thread under ``name`` and handed out again by the next call
    (its contents are the caller's until then; ``zero`` clears it).  A fresh array from numpy costs its
    first touch page by page (~1.5 ms for the ~3 MB of work arrays of one solve at N = 893, M = 100,
    every solve: allocations above glibc's mmap threshold go back to the system when freed).  Above
    :data:`SCRATCH_MAX_ELEMENTS` elements an array of its own is made."""
    n = 1
    for d in shape:
        n *= int(d)
    dt = np.dtype(dtype)
    if n > SCRATCH_MAX_ELEMENTS:
        return np.zeros(shape, dt) if zero else np.empty(shape, dt)
    bufs = getattr(_SCRATCH, "bufs", None)
    if bufs is None:
        bufs = _SCRATCH.bufs = {}
    buf = bufs.get((name, dt))
    if buf is None or buf.size < n:
        buf = bufs[(name, dt)] = np.empty(max(n, 1), dt)
    out = buf[:n].reshape(shape)
    if zero:
        out.fill(0)
    return out


_KERNEL: list[Any] = []      # [kernel] once compiled, [None] when numba is unusable here


def _build_kernel() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")  # x/0 = inf, as in numpy
    def _forward(levf, klo, cnt, bad, two_h, kq, use_k, M, lomask, himask, Jraw):  # pragma: no cover - compiled
        n1 = klo.shape[0]
        fb = np.empty(1)
        ib = fb.view(np.int64)
        Jf = Jraw.view(np.float64)
        for i in range(n1):
            th = two_h[i]
            kqi = kq[i]
            base = i * M
            for j in range(M):
                vj = levf[base + M + j]
                best = np.int64(0x7FFFFFFFFFFFFFFF)
                k0 = klo[i, j]
                if bad[i, j]:
                    g = base
                    fb[0] = Jf[g] + np.inf
                    best = (ib[0] & himask) | (g & lomask)
                else:
                    for w in range(cnt[i, j]):
                        g = base + k0 + w
                        vk = levf[g]
                        ssum = vk + vj
                        cost = th / ssum
                        if use_k:
                            diff = vj - vk
                            diff *= ssum
                            diff *= diff
                            diff *= kqi
                            cost += diff
                        fb[0] = Jf[g] + cost
                        ci = (ib[0] & himask) | (g & lomask)
                        if ci < best:
                            best = ci
                Jraw[base + M + j] = best
        return 0

    return _forward


_WINDOWS: list[Any] = []


def _build_windows() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _windows(lev, xall, xn, rq, rk, lq, lk, L, xjb, xjt, degenerate, plo, sp_p, t_lo, t_hi, nb,
                 klo, cnt, bad):  # pragma: no cover - compiled
        n1, M = klo.shape
        total = 0
        for i in range(n1):
            s0 = i * L
            ar = s0
            al = s0
            off = 3.0 * i
            lo_p = plo[i]
            spi = sp_p[i]
            degp = degenerate[i]
            for j in range(M):
                xj = xall[i + 1, j]
                good = xj >= xjb[i] and xj <= xjt[i] and not (degenerate[i + 1] and j >= 1)
                if good:
                    q = xj / xn[i]
                    q += off
                    # np.interp on each chain (non-decreasing abscissae, xp[s0] <= q <= xp[e]): the same
                    # index (the last j with xp[j] <= q, walking up: the queries increase with j) and
                    # the same arithmetic as numpy's arr_interp.  Written out twice: a jitted helper
                    # would be a closure variable, which defeats numba's on-disk cache.
                    e = s0 + L - 1
                    if q >= rq[e]:
                        ub = rk[e]
                    else:
                        while rq[ar + 1] <= q:
                            ar += 1
                        if rq[ar] == q:
                            ub = rk[ar]
                        else:
                            slope = (rk[ar + 1] - rk[ar]) / (rq[ar + 1] - rq[ar])
                            ub = slope * (q - rq[ar]) + rk[ar]
                            if ub != ub:
                                ub = slope * (q - rq[ar + 1]) + rk[ar + 1]
                                if ub != ub and rk[ar] == rk[ar + 1]:
                                    ub = rk[ar]
                    if q >= lq[e]:
                        lb = lk[e]
                    else:
                        while lq[al + 1] <= q:
                            al += 1
                        if lq[al] == q:
                            lb = lk[al]
                        else:
                            slope = (lk[al + 1] - lk[al]) / (lq[al + 1] - lq[al])
                            lb = slope * (q - lq[al]) + lk[al]
                            if lb != lb:
                                lb = slope * (q - lq[al + 1]) + lk[al + 1]
                                if lb != lb and lk[al] == lk[al + 1]:
                                    lb = lk[al]
                    good = ub >= lb and ub >= 0
                if not good:
                    klo[i, j] = 0
                    cnt[i, j] = 1
                    bad[i, j] = True
                    total += 1
                    continue
                pk_lo = np.sqrt(lb if lb > 0.0 else 0.0)
                pk_hi = np.sqrt(ub if ub > 0.0 else 0.0)
                if degp:
                    kl = 0
                    kh = 0 if (lo_p >= pk_lo and lo_p <= pk_hi) else -1
                else:
                    y = pk_lo - lo_p
                    y /= spi
                    y *= nb
                    yi = 0 if y < 0 else (nb - 1 if y >= nb - 1 else int(y))
                    kl = t_lo[yi]
                    y = pk_hi - lo_p
                    y /= spi
                    y *= nb
                    yi = 0 if y < 0 else (nb - 1 if y >= nb - 1 else int(y))
                    kh = t_hi[yi]
                    kix = kl if kl < M - 1 else M - 1
                    if kl <= M - 1 and lev[i, kix] < pk_lo:
                        kl += 1
                    kix = kh if kh > 0 else 0
                    if kh >= 0 and lev[i, kix] > pk_hi:
                        kh -= 1
                c = kh - kl + 1
                if c <= 0:
                    klo[i, j] = 0
                    cnt[i, j] = 1
                    bad[i, j] = True
                    total += 1
                else:
                    klo[i, j] = kl
                    cnt[i, j] = c
                    bad[i, j] = False
                    total += c
        return total

    return _windows


def windows(lev: np.ndarray, xall: np.ndarray, xn: np.ndarray, ch: tuple[np.ndarray, ...], L: int,
            xjb: np.ndarray, xjt: np.ndarray, degenerate: np.ndarray, plo: np.ndarray, sp_p: np.ndarray,
            t_lo: np.ndarray, t_hi: np.ndarray, nb: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The DP windows ``(klo, cnt, bad)`` of :func:`engine.timeparam._dp` (levels uniform in ṡ), the
    same integers as its numpy code; ``None`` without numba."""
    kern = _compiled(_WINDOWS, "windows", _build_windows)
    if kern is None:
        return None
    n1, M = lev.shape[0] - 1, lev.shape[1]
    klo = np.empty((n1, M), np.int64)
    cnt = np.empty((n1, M), np.int64)
    bad = np.empty((n1, M), np.bool_)
    rq, rk, lq, lk = ch
    kern(lev, xall, xn, rq, rk, lq, lk, int(L), xjb, xjt, degenerate, plo, sp_p, t_lo, t_hi, int(nb),
         klo, cnt, bad)
    return klo, cnt, bad


_FUSED: list[Any] = []


def _build_fused() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _dp_pass(plo_, span, phi, frac, lev, xn, rq, rk, lq, lk, rs, ls, L, xjb, xjt, degenerate, plo,
                 sp_p, t_lo, t_hi, nb, two_h, kq_h, uniform_h, chunk, use_k, lomask, himask, Jraw, jidx,
                 sdot):  # pragma: no cover
        # One whole DP pass: per interval the windows (as _windows), the chunk bookkeeping of the numpy
        # pass (a uniform-spacing pass costs every interval of a chunk with its first interval's 2h and
        # K/4h², as the numpy pass does), the candidates (as _forward), then the reach checks and the
        # backward pass.  Returns (candidates, node that cannot be reached or -1, final level reached).
        n, M = lev.shape
        n1 = n - 1
        for i in range(n):                  # the levels, as numpy's minimum(plo + span·frac, phi)
            a = plo_[i]
            sp = span[i]
            ph = phi[i]
            for k in range(M):
                v = a + sp * frac[k]
                if ph < v:
                    v = ph
                lev[i, k] = v
        levf = lev.reshape(-1)
        Jf = Jraw.view(np.float64)
        for q0 in range(n * M):
            Jf[q0] = np.inf
        Jf[0] = 0.0
        fb = np.empty(1)
        ib = fb.view(np.int64)
        klo = np.empty(M, np.int64)
        cnt = np.empty(M, np.int64)
        bad = np.empty(M, np.bool_)
        qq = np.empty(M)
        xq = np.empty(M)                 # ṡ² of the levels at the arrival node
        okj = np.empty(M, np.bool_)
        lbv = np.empty(M)
        ubv = np.empty(M)
        pkl = np.empty(M)
        pkh = np.empty(M)
        yl = np.empty(M)
        yh = np.empty(M)
        pm = np.empty(M)                 # prefix minima of J at the departure node
        pmi = pm.view(np.int64)
        infbits = np.int64(0x7FF0000000000000)
        u1 = np.uint64(1)
        him = np.int64(-4096)            # the masks as constants (12 low bits; dp_pass checks the arguments)
        lom = np.int64(4095)
        total = 0
        acc = 0
        first = 0
        for i in range(n1):
            # --- windows of interval i (the same arithmetic as _windows) -------------------------
            s0 = i * L
            ar = np.uint64(s0)             # indices known >= 0: unsigned (no negative-index wraparound code)
            al = np.uint64(s0)
            off = 3.0 * i
            lo_p = plo[i]
            spi = sp_p[i]
            degp = degenerate[i]
            per = 0
            xni = xn[i]
            xlo = xjb[i]
            xhi = xjt[i]
            degn = degenerate[i + 1]
            for j in range(M):                      # vectorisable: abscissae of the chain queries
                v = lev[i + 1, j]
                xj = v * v
                xq[j] = xj
                qq[j] = xj / xni + off
            e = np.uint64(s0 + L - 1)
            for j in range(M):                      # the chain walks (np.interp's arithmetic)
                xj = xq[j]
                good = xj >= xlo and xj <= xhi and not (degn and j >= 1)
                ub = 0.0
                lb = 0.0
                if good:
                    q = qq[j]
                    if q >= rq[e]:
                        ub = rk[e]
                    else:
                        while rq[ar + u1] <= q:
                            ar += u1
                        if rq[ar] == q:
                            ub = rk[ar]
                        else:
                            slope = rs[ar]
                            ub = slope * (q - rq[ar]) + rk[ar]
                            if ub != ub:
                                ub = slope * (q - rq[ar + u1]) + rk[ar + u1]
                                if ub != ub and rk[ar] == rk[ar + u1]:
                                    ub = rk[ar]
                    if q >= lq[e]:
                        lb = lk[e]
                    else:
                        while lq[al + u1] <= q:
                            al += u1
                        if lq[al] == q:
                            lb = lk[al]
                        else:
                            slope = ls[al]
                            lb = slope * (q - lq[al]) + lk[al]
                            if lb != lb:
                                lb = slope * (q - lq[al + u1]) + lk[al + u1]
                                if lb != lb and lk[al] == lk[al + u1]:
                                    lb = lk[al]
                    good = ub >= lb and ub >= 0
                okj[j] = good
                lbv[j] = lb if lb > 0.0 else 0.0
                ubv[j] = ub if ub > 0.0 else 0.0
            for j in range(M):                      # vectorisable: square roots, fractions of the span
                pl = np.sqrt(lbv[j])
                ph = np.sqrt(ubv[j])
                pkl[j] = pl
                pkh[j] = ph
                y = pl - lo_p
                y /= spi
                y *= nb
                yl[j] = y
                y = ph - lo_p
                y /= spi
                y *= nb
                yh[j] = y
            for j in range(M):
                if not okj[j]:
                    klo[j] = 0
                    cnt[j] = 1
                    bad[j] = True
                    per += 1
                    continue
                pk_lo = pkl[j]
                pk_hi = pkh[j]
                if degp:
                    kl = 0
                    kh = 0 if (lo_p >= pk_lo and lo_p <= pk_hi) else -1
                else:
                    y = yl[j]
                    yi = 0 if y < 0 else (nb - 1 if y >= nb - 1 else int(y))
                    kl = t_lo[np.uint64(yi)]
                    y = yh[j]
                    yi = 0 if y < 0 else (nb - 1 if y >= nb - 1 else int(y))
                    kh = t_hi[np.uint64(yi)]
                    kix = kl if kl < M - 1 else M - 1          # the corrections without branches
                    kl += (kl <= M - 1) & (levf[np.uint64(i * M + kix)] < pk_lo)
                    kix = kh if kh > 0 else 0
                    kh -= (kh >= 0) & (levf[np.uint64(i * M + kix)] > pk_hi)
                c = kh - kl + 1
                if c <= 0:
                    klo[j] = 0
                    cnt[j] = 1
                    bad[j] = True
                    per += 1
                else:
                    klo[j] = kl
                    cnt[j] = c
                    bad[j] = False
                    per += c
            total += per
            # --- the numpy pass's chunks (whole intervals of <= chunk candidates) ----------------
            if acc and acc + per > chunk:
                first = i
                acc = 0
            acc += per
            if uniform_h:
                th = two_h[first]
                kqi = kq_h[first]
            else:
                th = two_h[i]
                kqi = kq_h[i]
            # --- candidates (the same arithmetic and integer minimum as _forward) ---------------
            # Each window is scanned from its fastest departure level down, and the scan stops
            # once no slower level can win: for k' <= k, J_k' + cost(k') >= min_{k'' <= k} J_k'' +
            # 2h/(v_k + v_j) (the levels do not decrease with k, the penalty term is >= 0, and
            # rounding is monotone), so when that bound's key exceeds the best key found (a finite
            # one) every remaining candidate's key does too: the same minimum, fewer candidates.
            base = i * M
            m = Jraw[base]
            kf = -1                          # the fastest departure level with a finite J
            for k in range(M):
                x = Jraw[base + k]
                if x < m:
                    m = x
                pmi[k] = m
                if x < infbits:
                    kf = k
            for j in range(M):
                vj = levf[base + M + j]
                best = np.int64(0x7FFFFFFFFFFFFFFF)
                if bad[j]:
                    g = base
                    fb[0] = Jf[g] + np.inf
                    best = (ib[0] & himask) | (g & lomask)
                else:
                    # Departures above kf have no finite J: their keys are above every finite key, so
                    # the scan starts at kf when the window reaches above it.  A window without a
                    # finite J keeps the largest key (not finite, as its minimum would be: a state no
                    # law reaches; only finite J are the numpy pass's bit for bit).
                    k0 = klo[j]
                    top = cnt[j] - 1
                    if kf - k0 < top:
                        top = kf - k0
                    for w in range(top, -1, -1):
                        k = np.uint64(k0 + w)
                        g = np.uint64(base) + k
                        vk = levf[g]
                        ssum = vk + vj
                        cost = th / ssum
                        if best < infbits:
                            fb[0] = pm[k] + cost
                            if (ib[0] & him) > best:
                                break
                        if use_k:
                            diff = vj - vk
                            diff *= ssum
                            diff *= diff
                            diff *= kqi
                            cost += diff
                        fb[0] = Jf[g] + cost
                        ci = (ib[0] & him) | (np.int64(g) & lom)
                        if ci < best:
                            best = ci
                Jraw[base + M + j] = best
        # --- reach checks on J without its low bits, then the backward pass ------------------------
        for i in range(1, n):
            any_fin = False
            for j in range(M):
                ib[0] = Jraw[i * M + j] & himask
                if np.isfinite(fb[0]):
                    any_fin = True
                    break
            if not any_fin:
                return total, i, False
        ib[0] = Jraw[n1 * M] & himask
        if not np.isfinite(fb[0]):
            return total, -1, False
        j = 0
        jidx[n1] = 0
        sdot[n1] = lev[n1, 0]
        for i in range(n1 - 1, -1, -1):
            k = Jraw[(i + 1) * M + j] & lomask
            k -= i * M
            k &= lomask
            j = k
            jidx[i] = j
            sdot[i] = lev[i, j]
        return total, -1, True

    return _dp_pass


def dp_pass(levels: tuple[np.ndarray, ...], xn: np.ndarray, ch: tuple[np.ndarray, ...], L: int,
            xjb: np.ndarray, xjt: np.ndarray, degenerate: np.ndarray, plo: np.ndarray, sp_p: np.ndarray,
            t_lo: np.ndarray, t_hi: np.ndarray, nb: int, two_h: np.ndarray, kq_h: np.ndarray, uniform_h: bool,
            chunk: int, use_k: bool, lomask: int, himask: int, work: list | None = None
            ) -> tuple[int, int, bool, np.ndarray, np.ndarray] | None:
    """One whole DP pass of :func:`engine.timeparam._dp` (levels uniform in ṡ) in one compiled call:
    the levels, the windows, the forward pass and the backward pass, bit for bit the numpy code's.
    ``levels`` = ``(plo, span, phi, frac)``: level ``k`` at node ``i`` is ``min(plo_i + span_i·frac_k,
    phi_i)`` (mm/s).  ``ch`` =
    ``(rq, rk, lq, lk, rs, ls)``: the chains and their segment slopes ``diff(rk)/diff(rq)``,
    ``diff(lk)/diff(lq)`` (numpy's ``interp`` computes the same quotients).

    The pass's (N, M) work arrays (levels, J; every element is written before it is read) are the
    thread's :func:`scratch` arrays, or, for bigger problems, kept in ``work`` (a list) for the next
    pass of the same problem.

    Returns ``(candidates, unreachable node or -1, final speed reached, jidx, sdot)`` (``jidx``, ``sdot``
    valid only when the pass succeeded: node -1 and final reached), or ``None`` without numba."""
    kern = _compiled(_FUSED, "dp_pass", _build_fused)
    if kern is None or lomask != 4095 or himask != -4096:    # (the kernel's constants: 12 low bits)
        return None
    plo_, span, phi, frac = levels
    n, M = plo_.size, frac.size
    if n * M <= SCRATCH_MAX_ELEMENTS:                  # kept per thread (written before read)
        lev = scratch("dp_lev", (n, M))
        Jraw = scratch("dp_J", (n * M,), np.int64)
    elif work and work[0].shape == (n, M):
        lev, Jraw = work
    else:
        lev = np.empty((n, M))
        Jraw = np.empty(n * M, np.int64)
        if work is not None:
            work[:] = [lev, Jraw]
    jidx = np.empty(n, np.int64)
    sdot = np.empty(n)
    rq, rk, lq, lk, rs, ls = ch
    total, bad_node, final_ok = kern(plo_, span, phi, frac, lev, xn, rq, rk, lq, lk, rs, ls, int(L),
                                     xjb, xjt, degenerate, plo, sp_p, t_lo, t_hi, int(nb), two_h, kq_h,
                                     bool(uniform_h), int(chunk), bool(use_k), np.int64(lomask),
                                     np.int64(himask), Jraw, jidx, sdot)
    return int(total), int(bad_node), bool(final_ok), jidx, sdot


_CHAINS: list[Any] = []


def _build_chains() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _chains_k(allr, order, m, V, h, xn_cur, rq, rk, lq, lk, xjb, xjt, uhi, ulo, xkt, rs, ls):  # pragma: no cover
        # The numpy code of engine.timeparam._chains, element by element (the same operations in the
        # same order).  Returns False (nothing usable) where that code would take another branch: a
        # non-positive vertex determinant (parallel normals) or a NaN vertex.
        B = order.shape[0]
        L = V + 1
        xk = np.empty(V)
        xj = np.empty(V)
        for b in range(B):
            mb = m[b]
            hb = h[b]
            bot = 0
            top = 0
            ub = -np.inf
            lb = np.inf
            kt = -np.inf
            for t in range(mb):
                ia = order[b, t]
                ib_ = order[b, (t + 1) % mb]
                na0 = allr[b, ia, 0]
                na1 = allr[b, ia, 1]
                nb0 = allr[b, ib_, 0]
                nb1 = allr[b, ib_, 1]
                det = na0 * nb1 - na1 * nb0
                if not det > 0:
                    return False
                zx = (nb1 - na1) / det
                zu = (na0 - nb0) / det
                x = zx + 2.0 * hb * zu
                if x != x or zu != zu:
                    return False
                xk[t] = zx
                xj[t] = x
                if x < xj[bot]:
                    bot = t
                if x > xj[top]:
                    top = t
                if zu > ub:
                    ub = zu
                if zu < lb:
                    lb = zu
                if zx > kt:
                    kt = zx
            c = (top - bot) % mb + 1
            nl = mb - c + 2
            sc = xn_cur[b]
            off = 3.0 * b
            for ll in range(L):
                ri = (bot + min(ll, c - 1)) % mb
                li = (bot - min(ll, nl - 1)) % mb
                rq[b * L + ll] = xj[ri] / sc + off
                rk[b * L + ll] = xk[ri]
                lq[b * L + ll] = xj[li] / sc + off
                lk[b * L + ll] = xk[li]
            xjb[b] = xj[bot]
            xjt[b] = xj[top]
            uhi[b] = ub
            ulo[b] = lb
            xkt[b] = kt
        # the chains' segment slopes, np.diff(rk) / np.diff(rq) (and the left chain's) over the flat arrays
        for a in range(rq.size - 1):
            rs[a] = (rk[a + 1] - rk[a]) / (rq[a + 1] - rq[a])
            ls[a] = (lk[a + 1] - lk[a]) / (lq[a + 1] - lq[a])
        return True

    return _chains_k


def chains(allr: np.ndarray, order: np.ndarray, m: np.ndarray, h: np.ndarray, xn_cur: np.ndarray,
           work: bool = False) -> dict[str, np.ndarray] | None:
    """The polygon chains of :func:`engine.timeparam._chains` from the hull vertex rows ``order``, ``m``
    (bit for bit its numpy code's) and their segment slopes ``rs``, ``ls`` (``np.diff(rk) / np.diff(rq)``,
    the same for the left chain: the quotients numpy's ``interp`` computes), or ``None`` (without numba,
    or where the numpy code handles parallel normals or NaN vertices).  ``work``: the chain arrays are the
    thread's :func:`scratch` arrays (valid until the next such call)."""
    kern = _compiled(_CHAINS, "chains", _build_chains)
    if kern is None:
        return None
    B = order.shape[0]
    V = int(m.max())
    L = V + 1
    if work:
        out = {k: scratch("chain_" + k, (B * L,)) for k in ("rq", "rk", "lq", "lk")}
        out.update({k: scratch("chain_" + k, (max(B * L - 1, 0),)) for k in ("rs", "ls")})
    else:
        out = {k: np.empty(B * L) for k in ("rq", "rk", "lq", "lk")}
        out.update({k: np.empty(max(B * L - 1, 0)) for k in ("rs", "ls")})
    out.update({k: np.empty(B) for k in ("xjb", "xjt", "uhi", "ulo", "xkt")})
    ok = kern(np.ascontiguousarray(allr, float), np.ascontiguousarray(order, np.int64),
              np.ascontiguousarray(m, np.int64), V, np.ascontiguousarray(h, float),
              np.ascontiguousarray(xn_cur, float), out["rq"], out["rk"], out["lq"], out["lk"], out["xjb"],
              out["xjt"], out["uhi"], out["ulo"], out["xkt"], out["rs"], out["ls"])
    return out if ok else None


_LIMITS: list[Any] = []


def _build_limits() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _limit_ratios_k(d1, d2, h, x0, u, tau, A, V):  # pragma: no cover - compiled
        # engine.timeparam._limit_ratios' numpy code element by element: x = max(x0 + ((2u)·h)·τ, 0),
        # X', X'' by Horner from 0 (out = out·τ + c_n), |X''·x + X'·u|/A and |X'|·√x/V; the maxima
        # are exact in any order (a NaN wins, as in numpy's max).
        n1, p, n_1 = d1.shape
        n_2 = d2.shape[2]
        # max_k fl(a_k/A) = fl(max_k a_k / A): a correctly rounded division by A > 0 is monotone, so
        # each axis' maximum is divided once
        am = np.full(p, -np.inf)
        vm = np.full(p, -np.inf)
        T = tau.size
        xs = np.empty(T)
        sx = np.empty(T)
        q1 = np.empty(T)
        q2 = np.empty(T)
        nan_a = False
        nan_v = False
        for i in range(n1):
            w = 2.0 * u[i] * h[i]
            ui = u[i]
            for t in range(T):
                x = x0[i] + w * tau[t]
                if x < 0.0:                      # np.maximum(x, 0.0): NaN stays, -0.0 stays
                    x = 0.0
                xs[t] = x
                sx[t] = np.sqrt(x)
            for c in range(p):
                for t in range(T):
                    q1[t] = 0.0
                    q2[t] = 0.0
                for k in range(n_1 - 1, -1, -1):
                    ck = d1[i, c, k]
                    for t in range(T):
                        q1[t] = q1[t] * tau[t] + ck
                for k in range(n_2 - 1, -1, -1):
                    ck = d2[i, c, k]
                    for t in range(T):
                        q2[t] = q2[t] * tau[t] + ck
                ma = am[c]
                mv = vm[c]
                for t in range(T):
                    a = abs(q2[t] * xs[t] + q1[t] * ui)
                    v = abs(q1[t]) * sx[t]
                    if a > ma:
                        ma = a
                    if v > mv:
                        mv = v
                    nan_a |= a != a
                    nan_v |= v != v
                am[c] = ma
                vm[c] = mv
        acc = -np.inf
        spd = -np.inf
        for c in range(p):
            acc = max(acc, am[c] / A[c])
            spd = max(spd, vm[c] / V[c])
        if nan_a:
            acc = np.nan
        if nan_v:
            spd = np.nan
        return acc, spd

    return _limit_ratios_k


def limit_ratios(d1: np.ndarray, d2: np.ndarray, h: np.ndarray, x0: np.ndarray, u: np.ndarray, tau: np.ndarray,
                 A: np.ndarray, V: np.ndarray) -> tuple[float, float] | None:
    """The worst acceleration and speed ratios of :func:`engine.timeparam._limit_ratios` (bit for bit its
    numpy code's), or ``None`` without numba (loaded)."""
    kern = _compiled(_LIMITS, "limits", _build_limits)
    if kern is None or d1.shape[0] == 0:
        return None
    c = np.ascontiguousarray
    acc, spd = kern(c(d1, float), c(d2, float), c(h, float), c(x0, float), c(u, float), c(tau, float),
                    c(A, float), c(V, float))
    return float(acc), float(spd)


_ROWS: list[Any] = []


def _build_rows() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _rows_k(P, Q, A, inv_sdd, rows, hull_rows):  # pragma: no cover - compiled
        # engine.timeparam._prepare's numpy code element by element: g = P/A, c = Q/A as the rows
        # (g, c) then (-g, -c) then (0, ±1/s̈_T); the hull rows are the rows times 1.0 or, for an inner
        # Bernstein point inside the triangle (origin, first, last) of its own axis, times 0.0.
        n1, p, nb = P.shape
        G = p * nb
        R = rows.shape[1]
        prune = nb == 5
        g = np.empty(nb)
        c = np.empty(nb)
        for i in range(n1):
            for a in range(p):
                for k in range(nb):
                    g[k] = P[i, a, k] / A[a]
                    c[k] = Q[i, a, k] / A[a]
                    r = a * nb + k
                    rows[i, r, 0] = g[k]
                    rows[i, r, 1] = c[k]
                    rows[i, G + r, 0] = -g[k]
                    rows[i, G + r, 1] = -c[k]
                    hull_rows[i, r, 0] = g[k] * 1.0
                    hull_rows[i, r, 1] = c[k] * 1.0
                    hull_rows[i, G + r, 0] = -g[k] * 1.0
                    hull_rows[i, G + r, 1] = -c[k] * 1.0
                if prune:
                    det = g[0] * c[4] - c[0] * g[4]
                    sd = det if abs(det) > 0 else 1.0
                    for k in range(1, 4):
                        al = (g[k] * c[4] - c[k] * g[4]) / sd
                        be = (g[0] * c[k] - c[0] * g[k]) / sd
                        if abs(det) > 0 and al >= 0 and be >= 0 and al + be <= 1.0 - 1e-12:
                            r = a * nb + k
                            hull_rows[i, r, 0] = g[k] * 0.0
                            hull_rows[i, r, 1] = c[k] * 0.0
                            hull_rows[i, G + r, 0] = -g[k] * 0.0
                            hull_rows[i, G + r, 1] = -c[k] * 0.0
            if R > 2 * G:
                rows[i, 2 * G, 0] = 0.0
                rows[i, 2 * G, 1] = inv_sdd
                rows[i, 2 * G + 1, 0] = 0.0
                rows[i, 2 * G + 1, 1] = -inv_sdd
                for r in range(2 * G, R):
                    hull_rows[i, r, 0] = rows[i, r, 0] * 1.0
                    hull_rows[i, r, 1] = rows[i, r, 1] * 1.0
        return 0

    return _rows_k


def constraint_rows(P: np.ndarray, Q: np.ndarray, A: np.ndarray, inv_sdd: float | None, rows: np.ndarray,
                    hull_rows: np.ndarray) -> bool:
    """Fill ``rows`` and ``hull_rows`` (N-1, R, 2) as :func:`engine.timeparam._prepare`'s numpy code does
    (bit for bit) from the Bernstein coefficients ``P``, ``Q`` (N-1, p, 5 or 1) of the acceleration
    constraints, the limits ``A`` (p,) and ``1/s̈_T`` (``None``: no s̈_T rows).  False (nothing written)
    without numba (loaded)."""
    kern = _compiled(_ROWS, "rows", _build_rows)
    if kern is None:
        return False
    c = np.ascontiguousarray
    kern(c(P, float), c(Q, float), c(A, float), 0.0 if inv_sdd is None else float(inv_sdd), rows, hull_rows)
    return True


_GROUPS: list[Any] = []


def _build_groups() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _group_rows_k(allr, order, keep, at_start, fi, off, valid, crow, rows):  # pragma: no cover - compiled
        # engine.timeparam._coarse_problem's numpy code element by element: the vertex rows of every
        # interval of a group (times 1.0 / 0.0 for kept / dropped vertices, for a later slot also for a
        # row at τ = 0), (g, c + 2·off·g) times 1.0 / 0.0 for valid / padded slots, then the same
        # negated, then the cap rows and their negatives.
        B, mx = fi.shape
        R = order.shape[1]
        half = mx * R
        for b in range(B):
            for t in range(mx):
                i = fi[b, t]
                o2 = 2.0 * off[b, t]
                vm = 1.0 if valid[b, t] else 0.0
                for r in range(R):
                    kp = 1.0 if keep[i, r] else 0.0
                    o = order[i, r]
                    g = allr[i, o, 0] * kp
                    c = allr[i, o, 1] * kp
                    if t >= 1:
                        la = 0.0 if at_start[i, r] else 1.0
                        g = g * la
                        c = c * la
                    c = c + o2 * g
                    g = g * vm
                    c = c * vm
                    q = t * R + r
                    rows[b, q, 0] = g
                    rows[b, q, 1] = c
                    rows[b, half + q, 0] = -g
                    rows[b, half + q, 1] = -c
                rows[b, 2 * half + t, 0] = crow[b, t, 0]
                rows[b, 2 * half + t, 1] = crow[b, t, 1]
                rows[b, 2 * half + mx + t, 0] = -crow[b, t, 0]
                rows[b, 2 * half + mx + t, 1] = -crow[b, t, 1]
        return 0

    return _group_rows_k


def group_rows(allr: np.ndarray, order: np.ndarray, keep: np.ndarray, at_start: np.ndarray, fi: np.ndarray,
               off: np.ndarray, valid: np.ndarray, crow: np.ndarray) -> np.ndarray | None:
    """The node groups' constraint rows of :func:`engine.timeparam._coarse_problem` (bit for bit its numpy
    code's): ``rows`` (B, 2·mx·R + 2·mx, 2) from the intervals' rows ``allr``, their hull vertex ids
    ``order`` (N-1, R), ``keep`` and ``at_start`` masks, the groups' intervals ``fi`` (B, mx), offsets
    ``off`` (mm), ``valid`` slots and cap rows ``crow`` (B, mx, 2); ``None`` without numba (loaded)."""
    kern = _compiled(_GROUPS, "groups", _build_groups)
    if kern is None:
        return None
    B, mx = fi.shape
    R = order.shape[1]
    rows = np.empty((B, 2 * mx * R + 2 * mx, 2))
    c = np.ascontiguousarray
    kern(c(allr, float), c(order, np.int64), c(keep, np.bool_), c(at_start, np.bool_), c(fi, np.int64),
         c(off, float), c(valid, np.bool_), c(crow, float), rows)
    return rows


_SWEEP: list[Any] = []


def _sweep_back(rq: Any, rk: Any, lq: Any, lk: Any, L: int, xn: Any, xjb: Any, xjt: Any, capx: Any,
                xend: float, clo: Any, chi: Any) -> int:
    """The backward pass of :func:`engine.timeparam._sweep` on flat sequences (numpy arrays when compiled by
    numba, Python lists otherwise: the same IEEE operations in the same order, so the same bits).

    ``[clo_i, chi_i]`` is the ṡ² at node i from which the end can be reached: the projection of interval
    i's polygon (its chains ``rq, rk, lq, lk`` of ``L`` points each, abscissa ``x_j/xn + 3i``) restricted
    to ``[clo_{i+1}, chi_{i+1}]`` onto its start axis, at most ``capx_i``, kept inside by a margin that
    covers the chains' round-off (1e-9 relative plus 8 ulps of the abscissa).  Writes ``clo``, ``chi``;
    returns -1, or the interval where no speed is left.
    """
    n = len(capx)
    clo[n - 1] = xend
    chi[n - 1] = xend
    for i in range(n - 2, -1, -1):
        a = max(clo[i + 1], xjb[i])
        b = min(chi[i + 1], xjt[i])
        if a > b:
            return i
        off = 3.0 * i
        qa = a / xn[i] + off
        qb = b / xn[i] + off
        i0 = i * L
        i1 = i0 + L - 1
        rmax = -math.inf
        lmin = math.inf
        for side in range(2):                  # the right chain (max x_k), the left chain (min x_k)
            qs = rq if side == 0 else lq
            ks = rk if side == 0 else lk
            # the chain at qa and qb (linear between its points, constant beyond them) and its points between
            lo_v = ks[i0]
            hi_v = ks[i1]
            best = -math.inf if side == 0 else math.inf
            t = i0
            while t < i1 and qs[t + 1] < qa:
                t += 1
            if qa > qs[i0] and t < i1:
                d = qs[t + 1] - qs[t]
                lo_v = ks[t + 1] if d <= 0.0 else ks[t] + (ks[t + 1] - ks[t]) * (qa - qs[t]) / d
            while t < i1 and qs[t + 1] < qb:
                t += 1
                v = ks[t]
                if qs[t] > qa:
                    best = max(best, v) if side == 0 else min(best, v)
            if qb <= qs[i0]:
                hi_v = ks[i0]
            elif t < i1:
                d = qs[t + 1] - qs[t]
                hi_v = ks[t + 1] if d <= 0.0 else ks[t] + (ks[t + 1] - ks[t]) * (qb - qs[t]) / d
            if side == 0:
                rmax = max(best, lo_v, hi_v)
            else:
                lmin = min(best, lo_v, hi_v)
        eq = 8.0 * xn[i] * (off + 3.0) * 2.220446049250313e-16
        chi[i] = min(rmax - (1e-9 * abs(rmax) + eq), capx[i])
        clo[i] = max(lmin + (1e-9 * abs(lmin) + eq), 0.0)
        if clo[i] > chi[i]:
            return i
    return -1


def _build_sweep() -> tuple[Any, Any]:
    """numba's :func:`_sweep_back` and :func:`engine.timeparam._sweep_fwd` (see :func:`sweep_kernels`)."""
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _fwd(rows, two_h, capx, chi, x0, xend, one, x):  # pragma: no cover - compiled
        # engine.timeparam._sweep_fwd element by element (the same products, sums and extrema),
        # then every row <= 1 at the chosen speeds (engine.timeparam._sweep's check, in place)
        n = capx.size
        R = rows.shape[1]
        x[0] = x0
        for i in range(n - 1):
            xk = x[i]
            th = two_h[i]
            up = np.inf
            lo = -np.inf
            for r in range(R):
                g = rows[i, r, 0]
                c = rows[i, r, 1]
                if c == 0.0:
                    if g * xk > one:
                        return i
                    continue
                q = th / c
                v = (1.0 - q * g) * xk + q * one
                if c > 0.0:
                    if v < up:
                        up = v
                elif v > lo:
                    lo = v
            lo = max(0.0, lo)
            if i + 1 == n - 1:
                xj = xend
            else:
                xj = min(up, chi[i + 1], capx[i + 1])
                if xj < lo:
                    xj = lo
            if xj > up or xj < lo:
                return i
            u = (xj - xk) / th
            for r in range(R):
                if rows[i, r, 0] * xk + rows[i, r, 1] * u > 1.0:
                    return i
            x[i + 1] = xj
        return -1

    return numba.njit(cache=True, nogil=True, error_model="numpy")(_sweep_back), _fwd


def sweep_kernels() -> tuple[Any, Any] | None:
    """:func:`engine.timeparam._sweep_back` and :func:`engine.timeparam._sweep_fwd` compiled (the same
    bits), or ``None`` without compiled kernels."""
    return _compiled(_SWEEP, ("sweep_back", "sweep_fwd"), _build_sweep)


_HULL_SYM: list[Any] = []


def _build_hull_sym() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _graham(px, py, ang, r2, idx, cd, sd, up, kk):  # pragma: no cover - compiled
        B, R = px.shape[0], px.shape[1]
        o = np.empty(R, np.int64)
        o2 = np.empty(R, np.int64)
        bk = np.empty(R, np.int64)
        hist = np.empty(65, np.int64)
        bscale = 63.0 / np.pi
        ka = np.empty(R)
        kq = np.empty(R)
        X = np.empty(R)
        Y = np.empty(R)
        A = np.empty(R)
        I = np.empty(R, np.int64)
        alive = np.empty(R, np.bool_)
        bad = np.empty(R, np.bool_)
        mark = np.empty(R, np.bool_)
        nr = np.empty(R, np.bool_)
        L = np.empty(R, np.int64)
        D = cd.shape[0]
        vx = np.empty(2 * D)
        vy = np.empty(2 * D)
        for b in range(B):
            # 1. np.lexsort((-r2, ang)): by angle, then the farther first, then the row number (stable)
            for j in range(R):
                ka[j] = ang[b, j]
                kq[j] = -r2[b, j]
            # (a stable counting pass into 64 buckets of the angle, a monotone map, first: the insertion
            # sort below, with the same comparisons, then has few moves left; the same order)
            for q in range(65):
                hist[q] = 0
            for j in range(R):
                v = ka[j] * bscale
                q = 63 if not v < 63.0 else (0 if not v > 0.0 else int(v))
                bk[j] = q
                hist[q + 1] += 1
            for q in range(64):
                hist[q + 1] += hist[q]
            for j in range(R):
                q = bk[j]
                o2[hist[q]] = j
                hist[q] += 1
            for jj in range(R):
                j = o2[jj]
                va = ka[j]
                vq = kq[j]
                t = jj - 1
                while t >= 0:
                    u = o[t]
                    if ka[u] > va or (ka[u] == va and kq[u] > vq):
                        o[t + 1] = u
                        t -= 1
                    else:
                        break
                o[t + 1] = j
            for j in range(R):
                X[j] = px[b, o[j]]
                Y[j] = py[b, o[j]]
                A[j] = ang[b, o[j]]
                I[j] = idx[b, o[j]]
            for j in range(R):
                alive[j] = A[j] < 5.0 and (j == 0 or A[j] != A[j - 1])
            # 2. the extreme points in D directions and their mirror images
            for d in range(D):
                best = -1.0
                r = 0
                for j in range(R):
                    pr = abs(X[j] * cd[d] + Y[j] * sd[d])
                    if pr > best:
                        best = pr
                        r = j
                p = X[r] * cd[d] + Y[r] * sd[d]
                sg = 1.0 if p > 0 else (-1.0 if p < 0 else 0.0)
                vx[d] = sg * X[r]
                vy[d] = sg * Y[r]
                vx[D + d] = -vx[d]
                vy[D + d] = -vy[d]
            for j in range(R):
                if not alive[j]:
                    continue
                inside = True
                for d in range(2 * D):
                    ax_ = vx[d]
                    ay_ = vy[d]
                    ex = vx[(d + 1) % (2 * D)] - ax_
                    ey = vy[(d + 1) % (2 * D)] - ay_
                    crs = ex * (Y[j] - ay_) - ey * (X[j] - ax_)
                    if not ((crs > 1e-12 * (abs(ex) + abs(ey))) or (ex == 0 and ey == 0)):
                        inside = False
                        break
                if inside:
                    alive[j] = False
            # 3. rounds of simultaneous removal, on the alive points in order (their neighbours are the
            # alive ones before and after, across an end the mirror image of the other end's)
            n = 0
            for j in range(R):
                if alive[j]:
                    L[n] = j
                    n += 1
            while n > 0:
                any_bad = False
                for i in range(n):
                    j = L[i]
                    if i > 0:
                        pp = L[i - 1]
                        sp = 1.0
                    else:
                        pp = L[n - 1]
                        sp = -1.0
                    if i < n - 1:
                        pn = L[i + 1]
                        sn = 1.0
                    else:
                        pn = L[0]
                        sn = -1.0
                    e1x = X[j] - sp * X[pp]
                    e1y = Y[j] - sp * Y[pp]
                    e2x = sn * X[pn] - X[j]
                    e2y = sn * Y[pn] - Y[j]
                    cr = e1x * e2y - e1y * e2x
                    near = cr * cr <= 1e-24 * (e1x * e1x + e1y * e1y) * (e2x * e2x + e2y * e2y)
                    strict = cr < 0 and not near
                    mark[i] = strict or near
                    nr[i] = near
                    bad[i] = strict
                # collinear within round-off: removed unless its predecessor is marked too
                for i in range(n):
                    if nr[i] and not mark[i - 1 if i > 0 else n - 1]:
                        bad[i] = True
                    if bad[i]:
                        any_bad = True
                if not any_bad:
                    break
                c = 0
                for i in range(n):
                    if bad[i]:
                        alive[L[i]] = False
                    else:
                        L[c] = L[i]
                        c += 1
                n = c
            c = 0
            for j in range(R):
                if alive[j]:
                    up[b, c] = I[j]
                    c += 1
            kk[b] = c
        return 0

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _prep(pts, ipos, ineg, px, py, idx, r2):  # pragma: no cover - compiled
        B, R = px.shape[0], px.shape[1]
        for b in range(B):
            sx = 0.0
            sy = 0.0
            for j in range(R):
                px[b, j] = pts[b, ipos[j], 0]
                py[b, j] = pts[b, ipos[j], 1]
                sx = max(sx, abs(px[b, j]))
                sy = max(sy, abs(py[b, j]))
            sx = sx if sx > 0 else 1.0
            sy = sy if sy > 0 else 1.0
            for j in range(R):
                x = px[b, j] / sx
                y = py[b, j] / sy
                if y < 0 or (y == 0 and x < 0):
                    x = -x
                    y = -y
                    idx[b, j] = ineg[j]
                else:
                    idx[b, j] = ipos[j]
                px[b, j] = x
                py[b, j] = y
                r2[b, j] = x * x + y * y
        return 0

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _assemble(up, kk, partner, order, m):  # pragma: no cover - compiled
        # engine.timeparam._hull_sym_assemble: the half chain's row ids, then their mirror partners,
        # zeros past 2k
        B, W = order.shape
        for b in range(B):
            k = kk[b]
            for t in range(k):
                order[b, t] = up[b, t]
                order[b, k + t] = partner[up[b, t]]
            for t in range(2 * k, W):
                order[b, t] = 0
            m[b] = 2 * k
        return 0

    return _graham, _prep, _assemble


def hull_sym_prep(pts: np.ndarray, ipos: np.ndarray, ineg: np.ndarray, work: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The first lines of :func:`engine.timeparam._hull_sym` compiled: the half points of every row scaled
    by the row's largest |x| and |y|, turned into the upper half-plane, their row ids and squared radii
    ``(px, py, idx, r2)``, bit for bit; ``None`` when numba is not loaded.  ``work``: in the thread's
    :func:`scratch` arrays (valid until the next such call)."""
    k = _hull_sym_kernels()
    if k is None:
        return None
    B, R = pts.shape[0], ipos.shape[0]
    if work:
        px, py, r2 = scratch("hs_px", (B, R)), scratch("hs_py", (B, R)), scratch("hs_r2", (B, R))
        idx = scratch("hs_idx", (B, R), np.int64)
    else:
        px, py, r2 = np.empty((B, R)), np.empty((B, R)), np.empty((B, R))
        idx = np.empty((B, R), np.int64)
    k[1](np.ascontiguousarray(pts, float), np.ascontiguousarray(ipos, np.int64),
         np.ascontiguousarray(ineg, np.int64), px, py, idx, r2)
    return px, py, idx, r2


def _hull_sym_kernels() -> Any:
    return _compiled(_HULL_SYM, ("hull_graham", "hull_prep", "hull_assemble"), _build_hull_sym)


def hull_sym_rows(px: np.ndarray, py: np.ndarray, ang: np.ndarray, r2: np.ndarray, idx: np.ndarray,
                  cd: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Steps 1-3 of :func:`engine.timeparam._hull_sym` (sort, extreme-point pre-filter, rounds of the
    parallel Graham scan) compiled, row by row, with its arithmetic operation for operation: the
    half chain's row ids ``up`` (B, R) and their counts ``k``, bit for bit the numpy code's.  The
    angles come from numpy (``ang``: its ``arctan2``, whose bits a compiled ``atan2`` need not
    match).  ``None`` when numba is not loaded."""
    kern = _hull_sym_kernels()
    if kern is None:
        return None
    B, R = px.shape
    up = np.zeros((B, max(R, 1)), np.int64)
    k = np.zeros(B, np.int64)
    kern[0](px, py, ang, r2, np.ascontiguousarray(idx, np.int64), cd, sd, up, k)
    return up, k


def hull_sym_order(px: np.ndarray, py: np.ndarray, ang: np.ndarray, r2: np.ndarray, idx: np.ndarray,
                   cd: np.ndarray, sd: np.ndarray, partner: np.ndarray, work: bool = False
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`hull_sym_rows` followed by :func:`engine.timeparam._hull_sym_assemble` compiled: the hull
    ``(order, m)`` of :func:`engine.timeparam._hull_sym`, bit for bit; ``partner`` maps every row id to
    its mirror's.  ``work``: the arrays are the thread's :func:`scratch` arrays (valid until the next
    such call).  ``None`` when numba is not loaded."""
    kern = _hull_sym_kernels()
    if kern is None:
        return None
    B, R = px.shape
    up = scratch("hs_up", (B, max(R, 1)), np.int64) if work else np.empty((B, max(R, 1)), np.int64)
    k = np.zeros(B, np.int64)
    kern[0](px, py, ang, r2, np.ascontiguousarray(idx, np.int64), cd, sd, up, k)
    K = max(int(k.max()), 1) if B else 1
    order = scratch("hs_order", (B, 2 * K), np.int64) if work else np.empty((B, 2 * K), np.int64)
    m = np.empty(B, np.int64)
    kern[2](up, k, np.ascontiguousarray(partner, np.int64), order, m)
    return order, m


_HULL: list[Any] = []


def _build_hull() -> Any:
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _hulls(pts, order, m, posr, partner):  # pragma: no cover - compiled
        B, R = pts.shape[0], pts.shape[1]
        xs = np.empty(R)
        ys = np.empty(R)
        ids = np.empty(R, np.int64)
        st = np.empty(2 * R + 1, np.int64)
        srt = np.empty(R, np.int64)
        nbk = 64
        bcnt = np.empty(nbk + 1, np.int64)
        bid = np.empty(R, np.int64)
        # the merged (sorted) full point set of the symmetric path: coordinates and row ids
        mx_ = np.empty(R)
        my_ = np.empty(R)
        mid = np.empty(R, np.int64)
        npos = posr.shape[0]
        for b in range(B):
            # --- centrally symmetric rows (every row r in posr has its mirror partner[r], pts[partner]
            # == -pts[r] exactly, and the two sets cover the rows): the monotone chain below on half
            # the points.  Its result is the full chain's, vertex for vertex: the full sorted order is
            # the merge of the half's sorted order with its mirror image reversed, the lower pass runs
            # over it as before, and the upper pass of the full chain visits the mirror images of the
            # lower pass's points in the same order, with the same turn tests (the cross products and
            # tolerances are unchanged by a sign flip of every coordinate), so it is the mirror image
            # of the lower chain.  Exact duplicate points (whose order the full sort breaks by row
            # number) and fewer than 3 points go to the full chain.
            sym = npos > 0 and 2 * npos == R
            if sym:
                sx = 0.0
                sy = 0.0
                for t in range(npos):
                    r = posr[t]
                    q = partner[r]
                    if not (pts[b, q, 0] == -pts[b, r, 0] and pts[b, q, 1] == -pts[b, r, 1]):
                        sym = False
                        break
                    sx = max(sx, abs(pts[b, r, 0]))
                    sy = max(sy, abs(pts[b, r, 1]))
            if sym:
                sx = sx if sx > 0 else 1.0
                sy = sy if sy > 0 else 1.0
                c = 0
                for t in range(npos):
                    r = posr[t]
                    if pts[b, r, 0] != 0.0 or pts[b, r, 1] != 0.0:
                        xs[c] = pts[b, r, 0] / sx
                        ys[c] = pts[b, r, 1] / sy
                        ids[c] = r
                        c += 1
                if 2 * c < 3:
                    sym = False
            if sym:
                for q in range(nbk + 1):
                    bcnt[q] = 0
                for q in range(c):
                    v = (xs[q] + 1.0) * (0.4999 * nbk)
                    bk = 0 if not v > 0.0 else (nbk - 1 if v >= nbk - 1 else int(v))
                    bid[q] = bk
                    bcnt[bk + 1] += 1
                for q in range(nbk):
                    bcnt[q + 1] += bcnt[q]
                for q in range(c):
                    bk = bid[q]
                    srt[bcnt[bk]] = q
                    bcnt[bk] += 1
                for q in range(1, c):
                    v = srt[q]
                    vx = xs[v]
                    vy = ys[v]
                    r = q - 1
                    while r >= 0 and (xs[srt[r]] > vx or (xs[srt[r]] == vx and ys[srt[r]] > vy)):
                        srt[r + 1] = srt[r]
                        r -= 1
                    srt[r + 1] = v
                # merge the half (ascending) with its mirror image (the half descending, negated)
                a = 0
                d = c - 1
                for q in range(2 * c):
                    take_a = d < 0
                    if a < c and d >= 0:
                        pa = srt[a]
                        pd = srt[d]
                        ax = xs[pa]
                        ay = ys[pa]
                        dx = -xs[pd]
                        dy = -ys[pd]
                        if ax == dx and ay == dy:
                            sym = False                      # an exact duplicate: the full chain
                            break
                        take_a = ax < dx or (ax == dx and ay < dy)
                    if take_a:
                        pa = srt[a]
                        mx_[q] = xs[pa]
                        my_[q] = ys[pa]
                        mid[q] = ids[pa]
                        a += 1
                    else:
                        pd = srt[d]
                        mx_[q] = -xs[pd]
                        my_[q] = -ys[pd]
                        mid[q] = partner[ids[pd]]
                        d -= 1
                    if q > 0 and mx_[q] == mx_[q - 1] and my_[q] == my_[q - 1]:
                        sym = False
                        break
            if sym:
                k = 0
                for q in range(2 * c):
                    while k >= 2:
                        a = st[k - 2]
                        bb = st[k - 1]
                        ax = mx_[bb] - mx_[a]
                        ay = my_[bb] - my_[a]
                        bx = mx_[q] - mx_[a]
                        by = my_[q] - my_[a]
                        cr = ax * by - ay * bx
                        if cr > 1e-12 * (abs(ax) + abs(ay)) * (abs(bx) + abs(by)) + 1e-15:
                            break
                        k -= 1
                    st[k] = q
                    k += 1
                k -= 1
                for q in range(k):
                    order[b, q] = mid[st[q]]
                    order[b, k + q] = partner[mid[st[q]]]
                m[b] = 2 * k
                continue
            # --- the full monotone chain -----------------------------------------------------------
            sx = 0.0
            sy = 0.0
            for r in range(R):
                sx = max(sx, abs(pts[b, r, 0]))
                sy = max(sy, abs(pts[b, r, 1]))
            sx = sx if sx > 0 else 1.0
            sy = sy if sy > 0 else 1.0
            c = 0
            for r in range(R):                     # zero rows (0 <= 1) never bind
                if pts[b, r, 0] != 0.0 or pts[b, r, 1] != 0.0:
                    xs[c] = pts[b, r, 0] / sx      # hull membership is invariant under axis scaling
                    ys[c] = pts[b, r, 1] / sy
                    ids[c] = r
                    c += 1
            if c < 3:
                for q in range(c):
                    order[b, q] = ids[q]
                m[b] = c
                continue
            # sort by x, then y, equal points in input order (a stable insertion sort: few points).
            # The symmetric path above sorts the same way; the two stay written out because a compiled
            # function calling another one built in this closure misses numba's on-disk cache (every
            # process would compile the hull again; tests/test_timeparam_numba_cache.py)
            # (a stable counting pass into buckets of x first: the insertion sort then only fixes
            # the order inside a bucket; the order is the same)
            for q in range(nbk + 1):
                bcnt[q] = 0
            for q in range(c):
                v = (xs[q] + 1.0) * (0.4999 * nbk)
                bk = 0 if not v > 0.0 else (nbk - 1 if v >= nbk - 1 else int(v))
                bid[q] = bk
                bcnt[bk + 1] += 1
            for q in range(nbk):
                bcnt[q + 1] += bcnt[q]
            for q in range(c):
                bk = bid[q]
                srt[bcnt[bk]] = q
                bcnt[bk] += 1
            for q in range(1, c):
                v = srt[q]
                vx = xs[v]
                vy = ys[v]
                r = q - 1
                while r >= 0 and (xs[srt[r]] > vx or (xs[srt[r]] == vx and ys[srt[r]] > vy)):
                    srt[r + 1] = srt[r]
                    r -= 1
                srt[r + 1] = v
            # Andrew's monotone chain, counter-clockwise; a point that does not turn strictly left
            # (within round-off of the two edges' lengths, and by more than 1e-15 of the unit box) is
            # dropped: collinear, duplicate and near-duplicate points
            k = 0
            for pass_ in range(2):
                lo = k
                for q in range(c):
                    ii = srt[q] if pass_ == 0 else srt[c - 1 - q]
                    while k >= lo + 2:
                        a = st[k - 2]
                        bb = st[k - 1]
                        ax = xs[bb] - xs[a]
                        ay = ys[bb] - ys[a]
                        bx = xs[ii] - xs[a]
                        by = ys[ii] - ys[a]
                        cr = ax * by - ay * bx
                        if cr > 1e-12 * (abs(ax) + abs(ay)) * (abs(bx) + abs(by)) + 1e-15:
                            break
                        k -= 1
                    st[k] = ii
                    k += 1
                k -= 1                              # the last point starts the other chain
            for q in range(k):
                order[b, q] = ids[st[q]]
            m[b] = k
        return 0

    return _hulls


def hulls(pts: np.ndarray, pairs: tuple[np.ndarray, np.ndarray] | None = None, scratch_out: bool = False
          ) -> tuple[np.ndarray, np.ndarray] | None:
    """Convex hull (counter-clockwise vertex rows, strictly convex) of each row of ``pts`` (B, R, 2),
    zero points ignored; ``(order, m)`` as :func:`engine.timeparam._hull_sym` returns them, or ``None``
    without numba.  Starts at the lowest-x vertex (the monotone chain's order).

    ``pairs = (ipos, ineg)``: the rows are centrally symmetric, ``pts[:, ineg] == -pts[:, ipos]``
    (checked exactly, per row): the chain then runs on the ``ipos`` half and mirrors its result, the
    same vertices in the same order as on every point.  ``scratch_out``: ``order`` is the thread's
    :func:`scratch` array (valid until the next such call)."""
    kern = _compiled(_HULL, "hulls", _build_hull)
    if kern is None:
        return None
    B, R = pts.shape[0], pts.shape[1]
    if scratch_out:
        order = scratch("hull_order", (B, max(R, 1)), np.int64, zero=True)
    else:
        order = np.zeros((B, max(R, 1)), np.int64)
    m = np.zeros(B, np.int64)
    partner = np.full(R, -1, np.int64)
    posr = np.zeros(0, np.int64)
    if pairs is not None:
        ipos = np.asarray(pairs[0], np.int64)
        ineg = np.asarray(pairs[1], np.int64)
        partner[ipos] = ineg
        partner[ineg] = ipos
        if ipos.size == ineg.size and 2 * ipos.size == R and np.all(partner >= 0):
            posr = ipos
    kern(np.ascontiguousarray(pts, float), order, m, posr, partner)
    return order, m


def kernel(nodes: int) -> Any:
    """The compiled forward pass, or ``None`` when the numpy pass should run (see the module doc).

    numba's kernel where it is loaded in this process (:func:`warm`; it releases the GIL), else the
    ahead-of-time one (:mod:`engine.aot`; no numba needed), else numba's, imported for a problem of
    ``nodes`` nodes from :data:`IMPORT_THRESHOLD` on (0 = only if numba is loaded already)."""
    if _KERNEL and _KERNEL[0] is not None:
        return _KERNEL[0]
    if os.environ.get("WINDER_NUMBA", "1") == "0":
        return None
    aot = _aot().get("forward")
    if aot is not None:
        return aot
    if _KERNEL:
        return None
    if "numba" not in sys.modules and nodes < IMPORT_THRESHOLD:
        return None
    return _load_jit()


def _load_jit() -> Any:
    """numba's forward kernel, built (loaded from numba's cache, or compiled) now; None where numba is unusable."""
    if not _KERNEL:
        try:
            _light_blas()
            k = _build_kernel()
        except Exception:  # noqa: BLE001 - no numba, or no cache locator (frozen build): numpy pass
            k = None
        _KERNEL.append(k)
    return _KERNEL[0]


def _jit_on() -> bool:
    """Whether numba's kernels are the ones in use here (numba's forward kernel is loaded)."""
    return bool(_KERNEL) and _KERNEL[0] is not None


def _compiled(cache: list[Any], name: str | tuple[str, ...], build: Callable[[], Any]) -> Any:
    """Kernel ``name``: numba's where numba's kernels are in use here (``build()``, kept in ``cache``), else
    the ahead-of-time one; None where no compiled kernel runs (the numpy pass).  A tuple of names: a builder
    of several kernels, their ahead-of-time names in the order it returns them (a tuple back)."""
    if kernel(0) is None:
        return None
    if _jit_on():
        if not cache:
            try:
                cache.append(build())
            except Exception:  # noqa: BLE001 - see kernel()
                cache.append(None)
        return cache[0]
    aot = _aot()
    if isinstance(name, tuple):
        return tuple(aot[n] for n in name) if all(n in aot for n in name) else None
    return aot.get(name)


def _aot() -> dict[str, Any]:
    """The ahead-of-time kernels by name (:func:`engine.aot.load`; empty where there are none)."""
    from engine import aot

    return aot.load()


def _light_blas() -> None:
    """SciPy's BLAS and LAPACK for Cython (``scipy.linalg.cython_blas``, ``cython_lapack``) loaded from their
    files alone (:func:`engine._lightimport.extension_module`) before numba looks for them: numba's first
    compile or cache load imports them only to check that a BLAS exists, and through ``scipy.linalg``'s
    ``__init__`` that import costs ~0.13 s (all of ``scipy.linalg`` and its docstrings).  The kernels use
    neither."""
    if "scipy.linalg" in sys.modules:
        return
    from engine._lightimport import extension_module

    extension_module("scipy.linalg.cython_blas")
    extension_module("scipy.linalg.cython_lapack")


def forward_pass(levf: np.ndarray, klo: np.ndarray, cnt: np.ndarray, bad: np.ndarray, two_h: np.ndarray,
                 kq: np.ndarray, use_k: bool, M: int, lomask: int, himask: int, Jraw: np.ndarray) -> bool:
    """Run the forward pass into ``Jraw`` (int64 view of J, shape (N·M,)) if the kernel is available.

    ``levf`` (N·M,) level speeds (mm/s); ``klo``, ``cnt`` (N-1, M) first departure level and window
    size; ``bad`` (N-1, M) no feasible departure; ``two_h``, ``kq`` (N-1,) the per-interval ``2h`` and
    ``K/(4h²)`` exactly as the numpy pass uses them.  Returns False (nothing done) without the kernel.
    """
    k = kernel(0)
    if k is None:
        return False
    try:
        k(levf, klo, cnt, bad, two_h, kq, bool(use_k), int(M), np.int64(lomask), np.int64(himask), Jraw)
    except Exception:  # noqa: BLE001 - a compile failure on an unusual platform: the numpy pass
        _KERNEL[:] = [None]
        return False
    return True


def warm() -> bool:
    """Import numba and load (or compile) every kernel now, e.g. in a background thread at start-up of a
    long-running process, so that no later run pays for it while holding the GIL, and so that its threads
    run numba's kernels, which release the GIL (the ahead-of-time ones do not).  Returns whether the
    kernels are available."""
    if _load_jit() is None:
        return False
    from engine.timeparam import TimeLimits, parametrize

    s = np.linspace(0.0, 10.0, 21)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    parametrize(s, X, one, 0.0 * one, TimeLimits(v_max=(1e3,), a_max=(100.0,), levels=20))   # windows, pass, sweep
    hulls(np.array([[[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]]))
    return True


__all__ = ["IMPORT_THRESHOLD", "SCRATCH_MAX_ELEMENTS", "chains", "constraint_rows", "dp_pass", "forward_pass",
           "group_rows", "hulls", "hull_sym_order", "hull_sym_prep", "hull_sym_rows", "kernel", "limit_ratios",
           "scratch", "sweep_kernels", "warm", "windows"]
