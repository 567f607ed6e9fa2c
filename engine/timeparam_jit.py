"""Compiled (numba) forward pass of the time-law DP, :func:`engine.timeparam._dp` (issue 16).

The numpy pass in :mod:`engine.timeparam` is the tested reference; this kernel computes the same
candidates in the same floating-point order and the same integer minimum (the departure level rides
in the low 12 bits of the float cost), so ``J`` and the argmins are bit for bit those of the numpy
pass (``tests/test_timeparam_speed.py`` compares both).

numba is imported lazily and only when it pays: :func:`forward_pass` returns ``None`` (the caller
then runs the numpy pass) when numba is not installed or cannot compile/cache here (the frozen build
leaves numba out, see installer/README.md), when ``WINDER_NUMBA=0`` is set, or when the pass is
too small to repay importing numba (~0.5 s, once per process) and numba is not loaded yet.
Compiled code is cached on disk (``cache=True``: ``__pycache__`` next to this file, or numba's
per-user cache directory when that is not writable).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

# A pass with at least this many candidates imports numba if it is not loaded yet (one DP pass of
# 2e6 candidates costs ~60 ms in numpy; the import + cache load ~0.5 s once per process).
IMPORT_THRESHOLD = 2_000_000

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


def kernel(candidates: int) -> Any:
    """The compiled forward pass, or ``None`` when the numpy pass should run (see the module doc)."""
    if _KERNEL:
        return _KERNEL[0]
    if os.environ.get("WINDER_NUMBA", "1") == "0":
        return None
    if "numba" not in sys.modules and candidates < IMPORT_THRESHOLD:
        return None
    try:
        k = _build_kernel()
    except Exception:  # noqa: BLE001 - no numba, or no cache locator (frozen build): numpy pass
        k = None
    _KERNEL.append(k)
    return k


def forward_pass(levf: np.ndarray, klo: np.ndarray, cnt: np.ndarray, bad: np.ndarray, two_h: np.ndarray,
                 kq: np.ndarray, use_k: bool, M: int, lomask: int, himask: int, Jraw: np.ndarray,
                 candidates: int) -> bool:
    """Run the forward pass into ``Jraw`` (int64 view of J, shape (N·M,)) if the kernel is available.

    ``levf`` (N·M,) level speeds (mm/s); ``klo``, ``cnt`` (N-1, M) first departure level and window
    size; ``bad`` (N-1, M) no feasible departure; ``two_h``, ``kq`` (N-1,) the per-interval ``2h`` and
    ``K/(4h²)`` exactly as the numpy pass uses them.  Returns False (nothing done) without the kernel.
    """
    k = kernel(candidates)
    if k is None:
        return False
    try:
        k(levf, klo, cnt, bad, two_h, kq, bool(use_k), int(M), np.int64(lomask), np.int64(himask), Jraw)
    except Exception:  # noqa: BLE001 - a compile failure on an unusual platform: the numpy pass
        _KERNEL[:] = [None]
        return False
    return True


__all__ = ["IMPORT_THRESHOLD", "forward_pass", "kernel"]
