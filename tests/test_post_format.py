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
