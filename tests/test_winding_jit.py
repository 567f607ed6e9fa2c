"""The Clairaut pass's RK4 integration compiled (engine.winding_jit, ahead of time) is the Python loop of
engine.winding_clairaut.integrate bit for bit: both directions, with and without dC/dλ and envelopes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine import winding_clairaut as wc
from engine import winding_jit
from engine.job import build_mandrel, load_job

ROOT = Path(__file__).resolve().parents[1]


def _require() -> None:
    if winding_jit._kernel() is None:
        pytest.fail("engine._aot_kernels is not built from this source: run `make venv` (python -m engine.aot)")


@pytest.mark.parametrize("name", ["pressure_vessel", "bottle", "pipe"])
def test_compiled_rk4_is_the_python_loop_bit_for_bit(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    _require()
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    mandrel = build_mandrel(load_job(path), path)
    za, zb = float(mandrel.z_min), float(mandrel.z_max)
    grid = wc.build_grid(mandrel, za, zb, "free", "free", 400, 3, [])
    n = grid.n
    rng = np.random.default_rng(4)
    cases = []
    for _ in range(60):
        i0, i1 = (int(v) for v in rng.integers(0, n, 2))
        c0 = float(rng.uniform(0.0, 1.2) * float(np.max(grid.geo["L"][0])))
        lam = float(rng.normal(0.0, 10 ** rng.uniform(-4, 1)))
        sens = bool(rng.uniform() < 0.5)
        lo = hi = None
        if rng.uniform() < 0.3:
            lo = rng.uniform(0.0, 0.5, n) * c0
            hi = lo + rng.uniform(0.1, 2.0, n) * max(c0, 1.0)
        cases.append((i0, i1, c0, lam, sens, lo, hi))
    cases.append((0, n - 1, 1e30, 1e5, True, None, None))     # blows up: the 1e12 clamp
    got = [wc.integrate(grid, *c[:4], sens=c[4], lo=c[5], hi=c[6]) for c in cases]
    assert grid._rk4_arrays is not None   # the kernel ran
    monkeypatch.setattr(winding_jit, "_KERNEL", [None])
    for c, (cs, ss) in zip(cases, got):
        ref_cs, ref_ss = wc.integrate(grid, *c[:4], sens=c[4], lo=c[5], hi=c[6])
        assert type(cs) is list and len(cs) == len(ref_cs)
        assert np.array_equal(np.array(cs), np.array(ref_cs), equal_nan=True)   # (NaN != NaN in a list)
        assert (ss is None) == (ref_ss is None)
        if ss is not None:
            assert type(ss) is list and np.array_equal(np.array(ss), np.array(ref_ss), equal_nan=True)


def test_breakpoints_far_from_the_nodes_as_the_full_scan() -> None:
    """build_grid's test of which breakpoints lie off the uniform nodes (two neighbours by a sorted search)
    gives the full scan's answer: random points, points on nodes, at midpoints, a tolerance away, outside
    the range, NaN and infinities."""
    rng = np.random.default_rng(6)
    for n in (2, 3, 17, 1000, 6001):
        t0, t1 = sorted(rng.uniform(-3, 3, 2))
        tu = np.linspace(t0, t1, n)
        tol = 1e-9 * (t1 - t0)
        mids = 0.5 * (tu[1:] + tu[:-1])
        tb = np.concatenate([rng.uniform(t0 - 1, t1 + 1, 500), tu[rng.integers(0, n, 50)], mids[:50],
                             tu[:20] + tol, tu[:20] - tol, tu[:20] + 2 * tol, tu[:20] + 0.5 * tol,
                             [np.nan, np.inf, -np.inf, t0 - 1e9, t1 + 1e9]])
        np.testing.assert_array_equal(wc._far_from_nodes(tu, tb, tol), wc._far_from_nodes_reference(tu, tb, tol))
    one = np.array([0.5])
    np.testing.assert_array_equal(wc._far_from_nodes(one, np.array([0.5, 0.7]), 1e-9), [False, True])
