"""Fixed-point number text for whole columns at once (the NC writers' numbers), without a ``str.format``
per number.

:func:`fixed_digits` finds, for every value, the integer ``k`` whose digits ``"{:.{d}f}".format(x)``
writes (Python rounds the exact binary value correctly, ties to even): ``x·10^d`` as an exact
two-float product (Dekker), rounded to the nearest integer and corrected where the product's
rounding hid which side of a tie the exact value lies on.  :func:`texts_of_digits` writes the
numbers of ``k`` into one byte buffer with numpy (sign, integer digits, point, fraction without
trailing zeros) and splits it into ``str`` s.  Values that are not finite or whose ``|k|`` reaches
:data:`K_MAX` (where a double no longer holds every integer) are marked for the caller's
value-by-value reference (``engine.post.base``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

K_MAX = 1e15
"""The fast path handles ``|x|·10^d < K_MAX``: integers there are exact doubles and the products'
rounding error stays far below one unit of the last decimal."""

_SPLIT = 134217729.0  # 2^27 + 1: Dekker's splitting constant


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = _SPLIT * a
    hi = c - (c - a)
    return hi, a - hi


def fixed_digits(values: Any, decimals: int) -> tuple[np.ndarray, np.ndarray]:
    """``(k, ok)``: for every value with ``ok`` the integer (int64) whose digits with ``decimals``
    decimals are what ``f"{x:.{decimals}f}"`` writes (its sign included; ``k = 0`` for a value that
    rounds to zero of either sign); ``ok`` is False for non-finite values and ``|x|·10^d >= K_MAX``
    (their ``k`` is 0)."""
    x = np.asarray(values, dtype=float).ravel()
    if not 0 <= decimals <= 22:
        raise ValueError(f"decimals must be 0..22, got {decimals}")
    f = 10.0 ** decimals                      # exact for d <= 22
    with np.errstate(over="ignore", invalid="ignore"):
        p = x * f
        ok = np.abs(p) < K_MAX                # False for inf and NaN too
        x = np.where(ok, x, 0.0)
        p = np.where(ok, p, 0.0)
        xh, xl = _split(x)
        fh, fl = _split(np.float64(f))
        e = ((xh * fh - p) + xh * fl + xl * fh) + xl * fl     # x·f = p + e exactly
    k = np.rint(p)                            # ties of p to even, as the exact value's ties are
    r = p - k                                 # exact (|p| < 2^52: p and k are multiples of ulp(p))
    # p at a half: the exact value x·f = p + e lies on the side of e (on the half itself: even, as rint)
    k += (r == 0.5) & (e > 0)
    k -= (r == -0.5) & (e < 0)
    return k.astype(np.int64), ok


def _chunk_table() -> np.ndarray:
    if not _TABLE:  # the ASCII digits of 0..9999, four per row (as "".join(f"{i:04d}"), 30x faster)
        i = np.arange(10_000)
        tab = (np.stack([i // 1000, i // 100 % 10, i // 10 % 10, i % 10], axis=1) + 48).astype(np.uint8)
        tab.flags.writeable = False
        _TABLE.append(tab)
    return _TABLE[0]


_TABLE: list[np.ndarray] = []   # the 4-digit groups "0000".."9999" as bytes, made on first use


def digit_width(k: np.ndarray, decimals: int) -> int:
    """Columns :func:`write_digits` needs for ``k``: sign, the integer digits of the largest, point, fraction."""
    a_max = int(np.abs(np.asarray(k, dtype=np.int64)).max()) if np.size(k) else 0
    return 1 + max(len(str(a_max // 10 ** int(decimals))), 1) + 1 + int(decimals)


def write_digits(k: np.ndarray, decimals: int, force_point: bool, chars: np.ndarray, show: np.ndarray) -> None:
    """Write the text of every ``k / 10^decimals`` into ``chars`` (uint8) and ``show`` (bool), views of
    shape (n, :func:`digit_width`): ASCII bytes (sign, integer digits, point, fraction digits) and which of
    them the text has - ``-`` for negative ``k``, no leading zeros, a point only with a fraction unless
    ``force_point``, no trailing zeros.  ``|k|`` must be below :data:`K_MAX`."""
    k = np.asarray(k, dtype=np.int64).ravel()
    n = k.size
    d = int(decimals)
    nint = chars.shape[1] - 2 - d
    ndig = nint + d                           # every |k| as ndig digits with leading zeros
    a = np.abs(k)
    nch = -(-ndig // 4)
    groups = np.empty((n, nch), np.int64)     # 4-digit groups, most significant first
    rest = a
    for j in range(nch - 1, -1, -1):
        rest, groups[:, j] = np.divmod(rest, 10_000)
    digits = _chunk_table()[groups].reshape(n, 4 * nch)[:, 4 * nch - ndig:]
    chars[:, 0] = ord("-")
    np.less(k, 0, out=show[:, 0])
    chars[:, 1:1 + nint] = digits[:, :nint]
    for j in range(nint - 1):                 # no leading zeros: digit j shows when |k| reaches its place
        np.greater_equal(a, 10 ** (d + nint - 1 - j), out=show[:, 1 + j])
    show[:, nint] = True                      # the units digit, also of 0
    chars[:, 1 + nint] = ord(".")
    if d:
        chars[:, 2 + nint:] = digits[:, nint:]
        for j in range(d):                    # a fraction digit stays when it or one after it is not zero
            np.not_equal(a % 10 ** (d - j), 0, out=show[:, 2 + nint + j])
        if force_point:
            show[:, 1 + nint] = True
        else:
            show[:, 1 + nint] = show[:, 2 + nint]
    else:
        show[:, 1 + nint] = force_point


def texts_of_digits(k: np.ndarray, decimals: int, force_point: bool = False) -> list[str]:
    """The text of every ``k / 10^decimals`` as :func:`write_digits` writes it, as a list of ``str``."""
    k = np.asarray(k, dtype=np.int64).ravel()
    if k.size == 0:
        return []
    return join_rows([(("digits", k, decimals, force_point), None)], k.size)


def join_rows(parts: list[tuple[Any, Any]], n: int) -> list[str]:
    """Rows of text from pieces side by side, row i the concatenation of the shown bytes of row i of every
    piece (UTF-8, no newline in them).  A piece is ``(chars, show)``: uint8 and bool arrays of shape (n, w)
    or broadcastable to it (a constant word: shape (1, w)), or ``(("digits", k, decimals, force_point),
    shown)`` - the numbers ``k / 10^decimals`` written by :func:`write_digits` where ``shown`` (bool (n,)
    or None for every row)."""
    from engine.numtext_jit import join_rows as compiled

    fast = compiled(parts, n)   # the same bytes by one compiled loop (engine.numtext_jit), where it applies
    if fast is not None:
        return fast
    return join_rows_reference(parts, n)


def join_rows_reference(parts: list[tuple[Any, Any]], n: int) -> list[str]:
    """:func:`join_rows` by numpy on whole byte matrices (where the compiled loop does not run; its test
    reference)."""
    widths = [digit_width(c[1], c[2]) if isinstance(c, tuple) else np.shape(c)[-1] for c, _ in parts]
    total = sum(widths) + 1
    chars = np.empty((n, total), np.uint8)
    show = np.empty((n, total), bool)
    col = 0
    for (c, s), w in zip(parts, widths):
        cv, sv = chars[:, col:col + w], show[:, col:col + w]
        if isinstance(c, tuple):
            write_digits(c[1], c[2], c[3], cv, sv)
            if s is not None:
                sv &= s[:, None]
        else:
            cv[...] = c
            sv[...] = s
        col += w
    chars[:, -1] = ord("\n")
    show[:, -1] = True
    out = chars[show].tobytes().decode("utf-8").split("\n")
    out.pop()
    return out
