"""The NC move lines' text written by one compiled loop (issue 16): :func:`engine.post._numtext.join_rows`'s
bytes, exactly.

Rendering the vessel's 56 000 blocks is ~0.1 s of numpy on whole (rows × columns) byte matrices (the
digits of every number at full width, then a masked gather), and it runs after the last layer, when
nothing else can run beside it.  A row of the text is a sequence of pieces - a constant word (``G1``,
`` X``, `` F``) or a number ``k / 10^d`` - each written where its row mask says so.  The kernel writes
them straight into one byte buffer, row after row, with the rules of :func:`engine.post._numtext.write_digits`:
``-`` for ``k < 0``, the integer digits without leading zeros (``0`` for none), the point where the
fraction is not zero (or always with ``force_point``), the fraction without trailing zeros.  It runs
compiled ahead of time (:mod:`engine.aot`; this module is one of its sources) or not at all (the numpy
code runs).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _build_rows() -> Any:
    """numba's kernel ``(n, kinds, wbytes, woff, kmat, kidx, dec, force, mask, out) -> length``: row i of the
    text is piece p for every p with ``mask[i, p]`` - the bytes ``wbytes[woff[p]:woff[p + 1]]`` where
    ``kinds[p] == 0``, else the number ``kmat[i, kidx[p]] / 10^dec[p]`` (``force[p]``: the point always) -
    and a newline; written into ``out``, the length returned (see :func:`join_rows`)."""
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def _rows(n, kinds, wbytes, woff, kmat, kidx, dec, force, mask, out):  # pragma: no cover - compiled
        P = kinds.shape[0]
        pw = np.empty(19, np.int64)  # 10^0 .. 10^18
        pw[0] = 1
        for j in range(1, 19):
            pw[j] = pw[j - 1] * 10
        pos = 0
        for i in range(n):
            for p in range(P):
                if not mask[i, p]:
                    continue
                if kinds[p] == 0:
                    for b in range(woff[p], woff[p + 1]):
                        out[pos] = wbytes[b]
                        pos += 1
                    continue
                k = kmat[i, kidx[p]]
                d = dec[p]
                if k < 0:
                    out[pos] = 45  # '-'
                    pos += 1
                    k = -k
                ip = k // pw[d]
                fr = k - ip * pw[d]
                nd = 1  # the integer digits, no leading zeros (0 for none)
                while nd < 18 and ip >= pw[nd]:
                    nd += 1
                e = pos + nd
                while e > pos:  # written from the last digit back
                    q = ip // 10
                    out[e - 1] = 48 + (ip - q * 10)
                    ip = q
                    e -= 1
                pos += nd
                if fr != 0:
                    out[pos] = 46  # '.'
                    pos += 1
                    nf = d  # the fraction's digits without trailing zeros (it is not zero: one stays)
                    q = fr // 10
                    while fr - q * 10 == 0:
                        fr = q
                        q = fr // 10
                        nf -= 1
                    e = pos + nf
                    while e > pos:  # with its leading zeros
                        q = fr // 10
                        out[e - 1] = 48 + (fr - q * 10)
                        fr = q
                        e -= 1
                    pos += nf
                elif force[p]:
                    out[pos] = 46
                    pos += 1
            out[pos] = 10  # '\n'
            pos += 1
        return pos

    return _rows


CHUNK = 2048
"""Rows per kernel call: an ahead-of-time kernel does not release the GIL, so one call for a whole program
would stall the GUI's thread; a chunk takes well under 1 ms."""

_KERNEL: list[Any] = []


def kernel() -> Any | None:
    """The ahead-of-time kernel ``nc_rows`` without its argument check, or None where it does not run."""
    from engine import aot

    got = aot.raw_kernels(("nc_rows",), _KERNEL)
    return None if got is None else got[0]


def join_rows(parts: list[tuple[Any, Any]], n: int) -> list[str] | None:
    """:func:`engine.post._numtext.join_rows` by the kernel, or None where it does not apply (not built; a
    piece other than a constant word - shape (1, w), shown where its (1, w) mask says, or in the rows of an
    (n, 1) mask - or digits with an (n,) mask or None; ``|k|`` not below 1e15; more than 9 decimals)."""
    fn = kernel()
    if fn is None or n < 1:
        return None
    P = len(parts)
    kinds = np.zeros(P, np.int64)
    words: list[bytes] = []
    woff = np.zeros(P + 1, np.int64)
    krows: list[np.ndarray] = []
    kidx = np.zeros(P, np.int64)
    dec = np.zeros(P, np.int64)
    force = np.zeros(P, np.bool_)
    mask = np.ones((n, P), np.bool_)   # row by row, as the loop reads it
    width = 1
    for p, (c, s) in enumerate(parts):
        if isinstance(c, tuple):
            _tag, k, d, fp = c
            k = np.asarray(k)
            if k.dtype != np.int64 or k.shape != (n,) or not 0 <= int(d) <= 9:
                return None
            a_max = int(np.abs(k).max())
            if a_max >= 10**15:
                return None
            kinds[p], kidx[p], dec[p], force[p] = 1, len(krows), int(d), bool(fp)
            krows.append(k)
            width += 2 + max(len(str(a_max)), int(d) + 1)   # sign, digits (0.00k: d + 1), point
            word = b""
            if s is not None:
                s = np.asarray(s)
                if s.dtype != np.bool_ or s.shape != (n,):
                    return None
                mask[:, p] = s
        else:
            c = np.asarray(c)
            s = np.asarray(s)
            if c.dtype != np.uint8 or c.ndim != 2 or c.shape[0] != 1 or s.dtype != np.bool_:
                return None
            if s.shape == c.shape:
                word = c[0][s[0]].tobytes()
            elif s.shape == (n, 1):
                word = c[0].tobytes()
                mask[:, p] = s.reshape(n)
            else:
                return None
            width += len(word)
        words.append(word)
        woff[p + 1] = woff[p] + len(word)
    wbytes = np.frombuffer(b"".join(words), np.uint8).astype(np.int64) if woff[-1] else np.zeros(1, np.int64)
    kmat = np.ascontiguousarray(np.stack(krows, axis=1)) if krows else np.zeros((n, 1), np.int64)
    out = np.empty(n * width, np.uint8)
    length = 0
    for a in range(0, n, CHUNK):  # the kernel holds the GIL: a GUI's thread gets it between chunks
        b = min(a + CHUNK, n)
        length += int(fn(b - a, kinds, wbytes, woff, kmat[a:b], kidx, dec, force, mask[a:b], out[length:]))
    text = out[:length].tobytes().decode("utf-8").split("\n")
    text.pop()
    return text
