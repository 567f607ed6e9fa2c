"""The payout's compiled interval propagation (engine.payout_jit, built ahead of time by engine.aot) gives
the numpy code's answers bit for bit: g on every branch, the forward closure on random bounds, whole laws."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine import payout, payout_jit
from engine.job import build_mandrel, load_job
from engine.payout import ContactLine
from engine.winding import winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]


def _require_kernels() -> None:
    if payout_jit.kernels() is None or payout_jit.ipm_kernels() is None:
        pytest.fail("engine._aot_kernels is not built from this source: run `make venv` (python -m engine.aot)")


@pytest.fixture
def numpy_only(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN201
    """A switch: inside ``with numpy_only():`` new _Tube objects and the (15) interior point run the numpy code."""
    import contextlib

    @contextlib.contextmanager
    def switch():  # noqa: ANN202
        with monkeypatch.context() as m:
            m.setattr(payout_jit, "_KERNELS", [None])
            m.setattr(payout_jit, "_IPM", [None])
            yield

    return switch


def _example(name: str, points: int = 600, grid: int = 300) -> tuple:
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": points}),
                      payout=job.payout.model_copy(update={"grid_points": grid}))
    return job, build_mandrel(job, path), ContactLine.from_line(winding_line_for_job(job, path).one_circuit)


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
@pytest.mark.parametrize("k", [0, 1])
def test_forward_closure_compiled_is_numpy_bit_for_bit(name: str, k: int, numpy_only) -> None:  # noqa: ANN001
    """forward() on random lower starts and pull-speed bounds (feasible, infeasible, at the edge): the
    compiled steps and the numpy code return the same iterate bit for bit, or both None; both raise alike."""
    _require_kernels()
    job, mandrel, line = _example(name)
    geo, env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    prob = payout._Problem(geo, env, k)
    fast = payout._Tube(prob)
    assert fast._G is not None
    with numpy_only():
        slow = payout._Tube(prob)
    assert slow._G is None
    rng = np.random.default_rng(5)
    u = prob.u(prob.mu_lo)
    seen = {"none": 0, "y": 0}
    with np.errstate(all="ignore"):
        for _ in range(60):
            t = float(np.quantile(u[np.isfinite(u)], rng.uniform(0.0, 0.9)))
            A, _B = fast._steps(t if rng.uniform() < 0.8 else None, None)
            x = fast.lo + rng.uniform(0.0, 1.0) * rng.uniform(0, 1, fast.lo.size) * np.where(
                np.isfinite(fast.hi - fast.lo), fast.hi - fast.lo, 10.0)
            x[0] = x[-1] = max(x[0], x[-1])
            h = fast.hi.copy()
            if rng.uniform() < 0.3:  # a tighter upper bound: some closures run into it (None)
                h = np.maximum(x, h - rng.uniform(0.0, 0.5) * np.where(np.isfinite(h - x), h - x, 10.0))
            got, want = [], []
            for tube, out in ((fast, got), (slow, want)):
                try:
                    out.append(tube.forward(x.copy(), A.copy(), h.copy()))
                except payout._FastFail as exc:
                    out.append(str(exc))
            a, b = got[0], want[0]
            if isinstance(b, np.ndarray):
                assert isinstance(a, np.ndarray) and np.array_equal(a, b, equal_nan=True)
                seen["y"] += 1
            else:
                assert a == b if isinstance(b, str) else a is None
                seen["none"] += b is None
    assert seen["y"] > 5 and seen["none"] > 0, seen


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_min_range_law_compiled_is_numpy_bit_for_bit(name: str, numpy_only) -> None:  # noqa: ANN001
    """The refined min-range law, (13) (14) band (15) and the line check, with and without the compiled
    steps: the same law and the same bounds bit for bit."""
    _require_kernels()
    job, mandrel, line = _example(name)
    a = payout.min_range_law(line, mandrel, job.payout)
    with numpy_only():
        b = payout.min_range_law(line, mandrel, job.payout)
    sa, sb = a.report["solver"], b.report["solver"]
    assert sa["fallback"] == sb["fallback"] == []
    assert (sa["u_min_13"], sa["u_max_14"], sa["band_15"]) == (sb["u_min_13"], sb["u_max_14"], sb["band_15"])
    assert sa["iterations"] == sb["iterations"]
    for f in ("x", "l", "Z", "R", "V"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f


def test_g_takes_the_numpy_code_for_arguments_not_the_kernels(numpy_only) -> None:  # noqa: ANN001
    """Arguments the kernels do not take (float32, strided, a partial slice, indices of another type or out
    of range) go to the numpy code: its answers, its IndexError."""
    _require_kernels()
    job, mandrel, line = _example("pipe")
    geo, env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    prob = payout._Problem(geo, env, 1)
    tube = payout._Tube(prob)
    with numpy_only():
        slow = payout._Tube(prob)
    mu = tube.lo[:-1] + 3.0
    n = mu.size
    with np.errstate(all="ignore"):
        ref = tube.g_reference(mu)
        assert np.array_equal(tube.g(mu), ref) and np.array_equal(slow.g(mu), ref)
        m32 = mu.astype(np.float32)
        got = tube.g(m32)
        assert got.dtype == slow.g(m32).dtype and np.array_equal(got, slow.g(m32))
        wide = np.repeat(mu, 2)[::2]   # a strided view
        assert not wide.flags.c_contiguous and np.array_equal(tube.g(wide), ref)
        assert np.array_equal(tube.g(mu[1:], slice(1, None)), ref[1:])
        idx = np.arange(0, n, 3)
        for ix in (idx, idx.astype(np.int32), list(idx)):
            assert np.array_equal(tube.g(mu[idx], ix), ref[idx])
        for t in (tube, slow):
            with pytest.raises(IndexError):
                t.g(mu[:2], np.array([0, n + 5]))
        assert tube.g(np.zeros(0), np.zeros(0, dtype=np.int64)).shape == (0,)


def test_the_kernels_run_without_numba() -> None:
    """The frozen build has no numba: the payout's kernels load there (the module needs neither numba nor
    llvmlite) and a tube takes them."""
    import subprocess
    import sys

    _require_kernels()
    code = ("import sys; sys.modules['numba'] = None\n"
            "from engine import payout_jit\n"
            "assert payout_jit.kernels() is not None\n"
            "assert 'llvmlite' not in sys.modules\n"
            "print('ok')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0 and proc.stdout.split() == ["ok"], proc.stderr


def test_the_kernels_sums_are_numpys_pairwise_sums() -> None:
    """The interior point's dot products (its gap, the affine step's centring) are numpy's pairwise
    ``add.reduce``: the kernel's sum against numpy on every size up to 600 and long arrays (several levels
    of numpy's halving), signed zeros, NaN and infinities included."""
    import scipy.sparse as sp

    _require_kernels()
    res_k = payout_jit.ipm_kernels()[0]
    rng = np.random.default_rng(2)
    Q = sp.csc_matrix(sp.identity(2))
    sizes = list(range(1, 600)) + [int(k) for k in rng.integers(600, 300_000, 40)]
    specials = [np.full(9, -0.0), np.full(3, -0.0), np.array([np.nan, 1.0] * 80), np.array([np.inf, -np.inf, 1.0])]
    for a in [rng.standard_normal(n) * 10 ** rng.uniform(-4, 4, n) for n in sizes] + specials:
        m = a.size
        A = sp.csr_matrix((np.ones(m), (np.arange(m), np.arange(m) % 2)), shape=(m, 2))
        At = A.T.tocsr()
        parts = [np.ascontiguousarray(v, dtype=t) for M in (Q, A, At) for v, t in
                 ((M.indptr, np.int64), (M.indices, np.int64), (M.data, np.float64))]
        info = np.empty(8)
        with np.errstate(all="ignore"):
            res_k(*parts[:3], True, *parts[3:], np.zeros(2), np.ascontiguousarray(a), np.ones(m), np.zeros(2),
                  np.zeros(m), np.empty(2), np.empty(2), np.empty(2), np.empty(m), np.empty(max(m, 2)), info)
            want = np.add.reduce(a * np.ones(m))
        assert info[0] == want or (np.isnan(info[0]) and np.isnan(want)), m
        assert np.signbit(info[0]) == np.signbit(want), m


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_interior_point_compiled_is_numpy_bit_for_bit(name: str, numpy_only, monkeypatch) -> None:  # noqa: ANN001
    """Every (15) QP the law solves, by the compiled Newton steps and by the numpy code: the same iterate
    bit for bit (or both None), on the examples' refined grids."""
    _require_kernels()
    job, mandrel, line = _example(name)
    calls: list[tuple] = []
    real = payout._ipm_qp

    def record(Q, c, A, b, x0, max_iter=100, kkt=None, state=None):  # noqa: ANN001, ANN202
        got = real(Q, c, A, b, x0, max_iter, kkt, state)
        calls.append((Q, c, A, b, x0.copy(), max_iter, kkt, got))
        return got

    compiled = []
    real_compiled = payout._ipm_compiled
    monkeypatch.setattr(payout, "_ipm_qp", record)
    monkeypatch.setattr(payout, "_ipm_compiled", lambda *a: compiled.append(1) or real_compiled(*a))
    payout.min_range_law(line, mandrel, job.payout)
    assert calls and len(compiled) == sum(k is not None for *_r, k, _g in calls) > 0   # the kernels ran
    with numpy_only():
        for Q, c, A, b, x0, max_iter, kkt, got in calls:
            want = real(Q, c, A, b, x0, max_iter, kkt)
            assert (got is None) == (want is None)
            if got is not None:
                assert np.array_equal(got, want)


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_implied_bounds_compiled_are_numpy_bit_for_bit(name: str, numpy_only, monkeypatch) -> None:  # noqa: ANN001
    """The implied upper bounds (their Illinois searches for the edge g(μ) − μ = B) on random pull-speed
    caps: the compiled steps and the numpy code give the same bounds bit for bit (or both none)."""
    _require_kernels()
    job, mandrel, line = _example(name)
    geo, env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    prob = payout._Problem(geo, env, 1)
    fast = payout._Tube(prob)
    with numpy_only():
        slow = payout._Tube(prob)
    edges = []
    real = payout._Tube._edge_compiled
    monkeypatch.setattr(payout._Tube, "_edge_compiled", lambda self, *a: edges.append(1) or real(self, *a))
    u = prob.u(prob.mu_lo)
    rng = np.random.default_rng(8)
    with np.errstate(all="ignore"):
        for _ in range(40):
            T = float(np.quantile(u[np.isfinite(u)], rng.uniform(0.0, 1.0))) * rng.uniform(0.2, 2.0)
            _A, B = fast._steps(None, T)
            a, b = fast.implied_hi(B.copy()), slow.implied_hi(B.copy())
            assert (a is None) == (b is None)
            if a is not None:
                assert np.array_equal(a, b)
    assert len(edges) >= 2   # (the searches ran)
