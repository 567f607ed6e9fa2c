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
