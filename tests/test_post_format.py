"""The formatters of engine.post.base give the strings of the one-value reference below (the rules as they
were written first, value by value)."""

import numpy as np
import pytest

from engine.post.base import fmt, fmt_many, format_column


def ref_fmt(x: float, decimals: int, force_point: bool = False) -> str:
    s = f"{x:.{decimals}f}"
    if "." in s:
        s = s.rstrip("0")
        if s.endswith(".") and not force_point:
            s = s[:-1]
    elif force_point:
        s += "."
    if s in ("-0", "-0.", "-"):
        s = "0." if force_point else "0"
    if s == "":
        s = "0"
    return s


def _values(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v = np.concatenate([rng.normal(scale=10.0 ** rng.uniform(-6, 5), size=400),
                        [0.0, -0.0, 0.5, -0.5, 1.5, 2.5, -0.0004, -0.0005, 0.0005, 1e-9, -1e-9, 123456.7895,
                         np.inf, -np.inf, np.nan]])
    return np.concatenate([v, np.round(v, 3), np.round(v, 1)])


@pytest.mark.parametrize("force_point", [False, True])
@pytest.mark.parametrize("decimals", [0, 1, 3, 4, 6])
@pytest.mark.parametrize("seed", range(3))
def test_fmt_many_is_fmt(seed: int, decimals: int, force_point: bool) -> None:
    v = _values(seed)
    want = [ref_fmt(float(x), decimals, force_point) for x in v]
    assert fmt_many(v, decimals, force_point) == want
    assert [fmt(float(x), decimals, force_point) for x in v[:50]] == want[:50]


@pytest.mark.parametrize("force_point", [False, True])
@pytest.mark.parametrize("decimals", [0, 3, 4])
def test_format_column_rules(decimals: int, force_point: bool) -> None:
    v = _values(7)
    v = v[np.isfinite(v)]
    out = format_column(v, decimals, force_point)
    for s, x in zip(out, v):
        assert not s.startswith("-0") or s.strip("-0.") != ""          # never a negative zero
        if decimals and "." in s:
            assert not s.endswith("0")                               # no trailing zeros
        assert ("." in s) if force_point else not s.endswith(".")
        assert float(s.rstrip(".")) == pytest.approx(np.round(x, decimals), abs=10.0 ** -decimals)


# --- the whole-column fast path (engine.post._numtext) against the value-by-value reference ---------------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from engine.post._numtext import K_MAX, fixed_digits, texts_of_digits  # noqa: E402
from engine.post.base import fmt_many_ref, format_column_ref  # noqa: E402


def _hard_values(rng: np.random.Generator, d: int, n: int = 3000) -> np.ndarray:
    """Values where the fast path could slip: exact decimal ties and their neighbours (one ulp either
    side), values already rounded to d decimals, both zeros, the edge of K_MAX, huge, tiny, subnormal
    and non-finite values."""
    f = 10.0 ** d
    ties = (rng.integers(-10**7, 10**7, size=n) + 0.5) / f
    big_ties = (rng.integers(-10**14, 10**14, size=n // 10) + 0.5) / f
    v = rng.normal(scale=10.0 ** rng.uniform(-9, 14, size=n))
    edge = np.array([K_MAX, K_MAX * (1 - 1e-16), (K_MAX - 0.5), K_MAX - 1.0]) / f
    return np.concatenate([
        ties, np.nextafter(ties, np.inf), np.nextafter(ties, -np.inf), big_ties, v, np.round(v, d), -np.round(v, d),
        edge, -edge, [0.0, -0.0, 0.5, -0.5, 1.5, 2.5, -2.5, 1e-300, -1e-300, 5e-324, -5e-324, 1e300, -1e300,
                      np.inf, -np.inf, np.nan, 0.05, 0.15, 0.25, 0.35, 1.005, 2.675, -0.0004999999]])


@pytest.mark.parametrize("force_point", [False, True])
@pytest.mark.parametrize("decimals", range(10))
def test_fast_column_text_is_the_reference(decimals: int, force_point: bool) -> None:
    v = _hard_values(np.random.default_rng(decimals), decimals)
    assert fmt_many(v, decimals, force_point) == fmt_many_ref(v, decimals, force_point)
    with np.errstate(over="ignore"):                  # np.round(1e300, d) overflows in both
        assert format_column(v, decimals, force_point) == format_column_ref(v, decimals, force_point)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=1, max_size=40),
       st.integers(0, 9), st.booleans())
def test_fast_column_text_is_the_reference_hypothesis(xs: list[float], decimals: int, force_point: bool) -> None:
    v = np.array(xs, dtype=float)
    assert fmt_many(v, decimals, force_point) == fmt_many_ref(v, decimals, force_point)
    with np.errstate(over="ignore"):
        assert format_column(v, decimals, force_point) == format_column_ref(v, decimals, force_point)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(-10**9, 10**9), min_size=1, max_size=30), st.integers(0, 9))
def test_fixed_digits_on_exact_decimals(ks: list[int], decimals: int) -> None:
    """k / 10^d as a double (the nearest one) comes back as k, and its text is k's digits with the point
    moved (Python's integer arithmetic as the independent reference)."""
    k = np.array(ks, dtype=np.int64)
    x = k / 10.0 ** decimals
    got, ok = fixed_digits(x, decimals)
    assert ok.all() and got.tolist() == ks
    want = []
    for kk in ks:
        s = str(abs(kk)).rjust(decimals + 1, "0")
        ip, fr = s[:len(s) - decimals], s[len(s) - decimals:].rstrip("0")
        want.append(("-" if kk < 0 else "") + ip + ("." + fr if fr else ""))
    assert texts_of_digits(got, decimals) == want


def test_fixed_digits_marks_what_it_cannot_write() -> None:
    k, ok = fixed_digits([np.nan, np.inf, -np.inf, 1e16, -1e15, 99.5, -0.0], 0)
    assert ok.tolist() == [False, False, False, False, False, True, True]
    assert k.tolist()[-2:] == [100, 0]


def test_the_four_digit_table_is_the_formatted_numbers() -> None:
    from engine.post import _numtext

    tab = _numtext._chunk_table()
    want = np.frombuffer("".join(f"{i:04d}" for i in range(10_000)).encode("ascii"), np.uint8).reshape(10_000, 4)
    assert tab.dtype == np.uint8 and not tab.flags.writeable
    np.testing.assert_array_equal(tab, want)
