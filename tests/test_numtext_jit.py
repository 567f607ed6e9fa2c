"""The NC move lines' text by the compiled loop (engine.numtext_jit) is numpy's join_rows byte for byte: random
rows of words and numbers (every decimals 0-9, the point forced or not, signs, zeros, the largest values the
fast path takes), words shown under row masks or partly, and Python's own formatting of the numbers."""

from __future__ import annotations

import numpy as np
import pytest

from engine import numtext_jit
from engine.post import _numtext as nt


def _require() -> None:
    if numtext_jit.kernel() is None:
        pytest.fail("engine._aot_kernels is not built from this source: run `make venv` (python -m engine.aot)")


def _word(text: str, show: list[bool] | None = None) -> tuple[np.ndarray, np.ndarray]:
    b = np.frombuffer(text.encode("utf-8"), np.uint8)[None, :]
    s = np.ones(b.shape, bool) if show is None else np.array([show], bool)
    return b, s


def _ks(rng: np.random.Generator, n: int) -> np.ndarray:
    k = rng.integers(-10**9, 10**9, n) // rng.choice([1, 10, 1000, 10**6, 10**9], n)
    edge = np.array([0, 1, -1, 9, 10, -10, 99, 100, 10**15 - 1, -(10**15 - 1), 10**14, 5 * 10**8], np.int64)
    k[rng.integers(0, n, edge.size)] = edge
    return k.astype(np.int64)


def test_random_rows_are_numpys_bytes() -> None:
    _require()
    rng = np.random.default_rng(8)
    for case in range(60):
        n = int(rng.integers(1, 3000))
        if case % 10 == 0:      # over one and two kernel calls' rows
            n = int(rng.integers(1, 3)) * numtext_jit.CHUNK + int(rng.integers(-5, 5))
        parts: list = [_word("G1")]
        for letter in "AXYZBCF"[: int(rng.integers(1, 8))]:
            d = int(rng.integers(0, 10))
            k = _ks(rng, n)
            shown = rng.random(n) < rng.uniform(0.2, 1.0)
            parts += [(_word(" " + letter)[0], shown[:, None]), (("digits", k, d, bool(rng.integers(0, 2))), shown)]
        parts += [_word(" (é)", [True, bool(case % 3), True, True, True]),      # a word shown in part, UTF-8
                  (("digits", _ks(rng, n), int(rng.integers(0, 10)), bool(case % 2)), None)]
        got = numtext_jit.join_rows(parts, n)
        assert got is not None
        assert got == nt.join_rows_reference(parts, n)
        assert nt.join_rows(parts, n) == got


@pytest.mark.parametrize("force_point", [False, True])
def test_numbers_as_python_writes_them(force_point: bool) -> None:
    """Every decimals 0-9: the text of k / 10^d is Python's exact decimal of the integer k with the point
    moved (an independent reference), no trailing zeros, the point only with a fraction unless forced."""
    _require()
    rng = np.random.default_rng(1)
    for d in range(10):
        k = _ks(rng, 4000)
        got = nt.texts_of_digits(k, d, force_point)
        want = []
        for kk in k.tolist():
            s = str(abs(kk)).rjust(d + 1, "0")
            ip, fr = s[:len(s) - d], s[len(s) - d:].rstrip("0")
            pt = "." if fr or force_point else ""
            want.append(("-" if kk < 0 else "") + ip + pt + fr)
        assert got == want


def test_what_the_loop_does_not_take_goes_to_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """A piece of per-row bytes, more than 9 decimals, |k| >= 1e15 or an int32 k: not the loop's (None), and
    join_rows gives numpy's answer; without the kernel, numpy's too."""
    _require()
    n = 5
    k = np.arange(n, dtype=np.int64) * 123 - 200
    chars = np.empty((n, nt.digit_width(k, 2)), np.uint8)    # the numbers as per-row bytes
    show = np.empty(chars.shape, bool)
    nt.write_digits(k, 2, False, chars, show)
    assert numtext_jit.join_rows([(chars, show)], n) is None
    assert nt.join_rows([(chars, show)], n) == nt.join_rows_reference([(chars, show)], n)
    for bad in ((("digits", k, 10, False), None), (("digits", k * 10**13, 2, False), None),
                (("digits", k.astype(np.int32), 2, False), None), (_word("X")[0], np.ones(n, bool))):
        assert numtext_jit.join_rows([bad], n) is None
    good = [_word("X"), (("digits", k, 3, False), None)]
    fast = nt.join_rows(good, n)
    monkeypatch.setattr(numtext_jit, "_KERNEL", [None])
    assert numtext_jit.join_rows(good, n) is None
    assert nt.join_rows(good, n) == fast == ["X-0.2", "X-0.077", "X0.046", "X0.169", "X0.292"]
