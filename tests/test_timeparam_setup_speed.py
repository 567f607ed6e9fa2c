"""The time law's set-up and report, rewritten for speed (issue 16), give the former code's bits.

The former numpy expressions are kept here as the reference: the quintic's coefficients
(``np.stack`` of the scaled terms), the constraint rows and the pre-pruned hull rows (stack,
concatenate, ``rows * keep``), and the limit ratios of a law on the sub-grid (Horner from zero on
(interval, axis, sub-point) arrays), the chains' segment slopes (np.diff quotients).  The new numpy
code and the compiled kernels (engine.timeparam_jit, numba: constraint_rows, limit_ratios, the slopes
made by chains) must reproduce them bit for bit, so the laws do not change.  parametrize keeps its
problem's big arrays in the thread's work arrays: laws must not share them.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import engine.timeparam as tp
from engine.timeparam_example import example_limits, example_path


def _quintic_ref(s, X, dX, ddX):
    h = np.diff(s)[:, None]
    a0, a1, a2 = X[:-1], h * dX[:-1], h * h * ddX[:-1] / 2.0
    r0 = X[1:] - a0 - a1 - a2
    r1 = h * dX[1:] - a1 - 2.0 * a2
    r2 = h * h * ddX[1:] - 2.0 * a2
    a3 = 10.0 * r0 - 4.0 * r1 + 0.5 * r2
    a4 = -15.0 * r0 + 7.0 * r1 - r2
    a5 = 6.0 * r0 - 3.0 * r1 + 0.5 * r2
    d1 = np.stack([a1, 2 * a2, 3 * a3, 4 * a4, 5 * a5], axis=-1) / h[..., None]
    d2 = np.stack([2 * a2, 6 * a3, 12 * a4, 20 * a5], axis=-1) / (h * h)[..., None]
    return d1, d2


def _rows_ref(s, dX, ddX, d1, d2, limits):
    """The former construction of the rows, the pre-pruned hull rows and the axis speed caps."""
    n, p = dX.shape
    h = np.diff(s)
    A = np.asarray(limits.a_max, float)
    V = np.asarray(limits.v_max, float)
    b1 = np.abs(d1 @ tp._P2B.T).max(axis=-1)
    if limits.accel_check == "arrival":
        b1n = np.abs(dX)
    else:
        b1n = np.zeros((n, p))
        b1n[:-1] = b1
        b1n[1:] = np.maximum(b1n[1:], b1)
        b1n = np.maximum(b1n, np.abs(dX))
    with np.errstate(divide="ignore"):
        cap_v = np.min(np.where(b1n > 0, V / np.where(b1n > 0, b1n, 1.0), np.inf), axis=1)
    if limits.accel_check == "arrival":
        P = ddX[1:, :, None]
        Q = (2 * h[:, None] * ddX[1:] + dX[1:])[:, :, None]
    else:
        Pp = np.concatenate([d2, np.zeros(d2.shape[:-1] + (1,))], axis=-1)
        Qp = d1.copy()
        Qp[..., 1:] += 2.0 * h[:, None, None] * d2
        P = Pp @ tp._P2B.T
        Q = Qp @ tp._P2B.T
    g = (P / A[None, :, None]).reshape(n - 1, -1)
    c = (Q / A[None, :, None]).reshape(n - 1, -1)
    rows = np.stack([np.concatenate([g, -g], 1), np.concatenate([c, -c], 1)], axis=-1)
    if math.isfinite(limits.sddot_max):
        extra = np.zeros((n - 1, 2, 2))
        extra[:, 0, 1] = 1.0 / limits.sddot_max
        extra[:, 1, 1] = -1.0 / limits.sddot_max
        rows = np.concatenate([rows, extra], axis=1)
    hull_rows = rows
    if P.shape[-1] == 5:
        g5, c5 = P / A[None, :, None], Q / A[None, :, None]
        det = g5[..., 0] * c5[..., 4] - c5[..., 0] * g5[..., 4]
        sd = np.where(np.abs(det) > 0, det, 1.0)
        al = (g5[..., 1:4] * c5[..., 4:5] - c5[..., 1:4] * g5[..., 4:5]) / sd[..., None]
        be = (g5[..., 0:1] * c5[..., 1:4] - c5[..., 0:1] * g5[..., 1:4]) / sd[..., None]
        inner = (np.abs(det)[..., None] > 0) & (al >= 0) & (be >= 0) & (al + be <= 1.0 - 1e-12)
        drop = np.zeros(g5.shape, bool)
        drop[..., 1:4] = inner
        drop = drop.reshape(n - 1, -1)
        keep = ~np.concatenate([drop, drop, np.zeros((n - 1, rows.shape[1] - 2 * drop.shape[1]), bool)], 1)
        hull_rows = rows * keep[..., None]
    return rows, hull_rows, cap_v


def _poly_eval_ref(coef, tau):
    out = np.zeros(coef.shape[:-1] + tau.shape)
    for n in range(coef.shape[-1] - 1, -1, -1):
        out = out * tau + coef[..., n, None]
    return out


def _ratios_ref(prob, sdot, n_sub=tp._N_SUB):
    lim = prob.limits
    v = np.asarray(sdot, float)
    tau = np.linspace(0.0, 1.0, n_sub + 1)
    x0 = v[:-1] ** 2
    u = (v[1:] ** 2 - x0) / (2.0 * prob.h)
    x = x0[:, None] + 2.0 * u[:, None] * prob.h[:, None] * tau[None, :]
    x = np.maximum(x, 0.0)
    q1 = _poly_eval_ref(prob.d1, tau)
    q2 = _poly_eval_ref(prob.d2, tau)
    A = np.asarray(lim.a_max)[None, :, None]
    V = np.asarray(lim.v_max)[None, :, None]
    acc = np.abs(q2 * x[:, None, :] + q1 * u[:, None, None]) / A
    spd = np.abs(q1) * np.sqrt(x)[:, None, :] / V
    return float(acc.max()), float(spd.max())


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _cases():
    lim = example_limits()
    s, X, dX, ddX = example_path()
    yield "example", (s, X, dX, ddX), replace(lim, levels=100)
    yield "arrival", (s, X, dX, ddX), replace(lim, levels=100, accel_check="arrival")
    yield "no sddot", (s, X, dX, ddX), replace(lim, levels=100, sddot_max=float("inf"))
    rng = np.random.default_rng(11)
    s2, X2, dX2, ddX2 = example_path(300)
    s2 = s2 + np.cumsum(rng.uniform(0.0, 3.0, s2.size))
    dX2 = dX2.copy()
    dX2[:40, 2] = 0.0                        # an axis at rest: zero rows, zero determinants
    ddX2 = ddX2.copy()
    ddX2[:40, 2] = 0.0
    yield "non-uniform, axis at rest", (s2, X2, dX2, ddX2), replace(lim, levels=60)


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("name,path,lim", list(_cases()), ids=[c[0] for c in _cases()])
def test_setup_gives_the_former_bits(name, path, lim, compiled, monkeypatch) -> None:
    """The rows and hull rows by numpy and by the compiled kernel (timeparam_jit.constraint_rows), in
    fresh arrays and in the thread's work arrays (parametrize's), equal the former construction."""
    if compiled:
        pytest.importorskip("numba")
        from engine import timeparam_jit

        assert timeparam_jit.kernel(1 << 62) is not None
    monkeypatch.setattr(tp, "_NUMBA", compiled)
    s, X, dX, ddX = path
    d1, d2 = tp._quintic(s, X, dX, ddX)
    r1, r2 = _quintic_ref(s, X, dX, ddX)
    assert _same(d1, r1) and _same(d2, r2)
    rows, hull_rows, cap_v = _rows_ref(s, dX, ddX, d1, d2, lim)
    for work in (False, True):
        prob = tp._prepare(s, X, dX, ddX, lim, chains=False, work=work)
        assert _same(prob.rows, rows)
        assert _same(prob.hull_rows, hull_rows)
        # the node-wise caps are the former ones; the speed caps in use are at least those (_chord_caps)
        old_caps, _xb = tp._interval_caps(d1, np.abs(dX), np.asarray(lim.v_max, float), lim.accel_check == "arrival",
                                          lambda name, shape: np.empty(shape))
        assert _same(old_caps, cap_v)
        assert (prob.cap_v >= cap_v).all()
        if lim.accel_check == "arrival":
            assert _same(prob.cap_v, cap_v)
        assert (np.signbit(prob.hull_rows) == np.signbit(hull_rows)).all()       # signed zeros too
        assert (prob.hull_rows == 0).sum() > (prob.rows == 0).sum() or lim.accel_check == "arrival"


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("name,path,lim", list(_cases()), ids=[c[0] for c in _cases()])
def test_limit_ratios_give_the_former_bits(name, path, lim, compiled, monkeypatch) -> None:
    if compiled:
        pytest.importorskip("numba")
        from engine import timeparam_jit

        assert timeparam_jit.kernel(1 << 62) is not None
    monkeypatch.setattr(tp, "_NUMBA", compiled)
    s, X, dX, ddX = path
    prob = tp.prepare(s, X, dX, ddX, lim)
    law = tp.parametrize(s, X, dX, ddX, replace(lim, levels=40), method="dp")
    rng = np.random.default_rng(2)
    laws = [law.sdot, law.sdot * 1.3, rng.uniform(0.0, 2.0 * law.sdot.max(), s.size)]   # too fast, zigzag
    for v in laws:
        got = tp.evaluate_limits(prob, v)
        acc, spd = _ratios_ref(prob, v)
        assert got["accel"].hex() == acc.hex() and got["speed"].hex() == spd.hex()
    v = laws[2].copy()
    v[5] = np.nan                                                   # NaN wins, as numpy's max
    got = tp.evaluate_limits(prob, v)
    assert math.isnan(got["accel"]) and math.isnan(got["speed"])


def test_compiled_limit_ratios_are_used_where_numba_is_loaded() -> None:
    pytest.importorskip("numba")
    from engine import timeparam_jit

    assert timeparam_jit.kernel(1 << 62) is not None
    s, X, dX, ddX = example_path(200)
    prob = tp.prepare(s, X, dX, ddX, example_limits())
    v = np.full(s.size, 10.0)
    x0 = v[:-1] ** 2
    u = (v[1:] ** 2 - x0) / (2.0 * prob.h)
    tau = np.linspace(0.0, 1.0, 17)
    A, V = np.asarray(example_limits().a_max), np.asarray(example_limits().v_max)
    res = timeparam_jit.limit_ratios(prob.d1, prob.d2, prob.h, x0, u, tau, A, V)
    assert res is not None and res == _ratios_ref(prob, v)


def test_compiled_chain_slopes_are_numpys_quotients() -> None:
    """The chains' segment slopes made by the compiled chains (with or without the thread's work arrays)
    are the quotients the numpy pass computes, np.diff(rk) / np.diff(rq) (and the left chain's)."""
    pytest.importorskip("numba")
    from engine import timeparam_jit

    assert timeparam_jit.kernel(1 << 62) is not None
    for n in (300, 3000):
        s, X, dX, ddX = example_path(n)
        prob = tp._prepare(s, X, dX, ddX, replace(example_limits(), levels=100), chains=False)
        ell = tp._group_length(prob)
        for work in (False, True):
            new = tp._with_chains(prob, work=work) if ell is None else tp._coarse_problem(prob, ell, work=work)[0]
            assert new.chain_slopes is not None
            with np.errstate(divide="ignore", invalid="ignore"):
                rs, ls = np.diff(new.rk) / np.diff(new.rq), np.diff(new.lk) / np.diff(new.lq)
            assert _same(new.chain_slopes[0], rs) and _same(new.chain_slopes[1], ls)


def test_laws_do_not_share_the_work_arrays() -> None:
    """parametrize's problem lives in the thread's work arrays during the call only: a law is not changed
    by the next solve (of another problem), and solving the same problem again gives the same law."""
    lim = replace(example_limits(), levels=60)
    a = tp.parametrize(*example_path(400), lim)
    snap = (a.s.copy(), a.sdot.copy(), a.t.copy(), [(it.sdot.copy(), it.lower.copy(), it.upper.copy())
                                                   for it in a.iterations])
    b = tp.parametrize(*example_path(700), replace(lim, levels=80))
    assert b.s.size == 700
    assert _same(a.s, snap[0]) and _same(a.sdot, snap[1]) and _same(a.t, snap[2])
    for it, (v, lo, hi) in zip(a.iterations, snap[3]):
        assert _same(it.sdot, v) and _same(it.lower, lo) and _same(it.upper, hi)
    again = tp.parametrize(*example_path(400), lim)
    assert _same(again.sdot, a.sdot) and again.total_time_s == a.total_time_s


def test_compiled_reference_hull_sorts_ties_and_signed_zero_angles_as_numpy() -> None:
    """The compiled reference hull buckets the angles before its insertion sort: points on the negative
    x axis (turned to angle -0.0), on the positive one (+0.0), many on one ray, and zero rows keep
    numpy's lexsort order, so the vertices are _hull_sym's numpy ones."""
    pytest.importorskip("numba")
    from engine import timeparam_jit

    assert timeparam_jit.warm()
    rng = np.random.default_rng(7)
    for _ in range(60):
        B, H = int(rng.integers(1, 20)), int(rng.integers(4, 40))
        ang = rng.choice([0.0, np.pi, 0.5, 1.0, np.pi / 2, 2.5], size=(B, H))
        rad = rng.choice([0.0, 0.5, 1.0, 2.0], size=(B, H))
        half = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
        half[..., 1][np.abs(half[..., 1]) < 1e-12] = 0.0             # exact axes: ±0 angles after turning
        half[:, 0] = [1.0, 0.0]
        half[:, 1] = [0.0, 1.0]                                        # the origin strictly inside
        pts = np.concatenate([half, -half], 1)
        ipos, ineg = np.arange(H), np.arange(H, 2 * H)
        a = tp._hull_sym(pts, ipos, ineg, compiled=False)
        b = tp._hull_sym(pts, ipos, ineg, compiled=True)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


@pytest.mark.parametrize("n", [3000, 6000])
def test_compiled_group_rows_are_the_numpy_rows(n: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The node groups' rows by the compiled loop (timeparam_jit.group_rows) are the numpy code's bit for bit
    (signed zeros of dropped and padded rows included), hence the same coarse problem."""
    pytest.importorskip("numba")
    from engine import timeparam_jit

    assert timeparam_jit.kernel(1 << 62) is not None
    s, X, dX, ddX = example_path(n)
    prob = tp._prepare(s, X, dX, ddX, replace(example_limits(), levels=100), chains=False)
    ell = tp._group_length(prob)
    assert ell is not None
    new, idx = tp._coarse_problem(prob, ell)
    monkeypatch.setattr(timeparam_jit, "group_rows", lambda *a: None)
    ref, idx_ref = tp._coarse_problem(prob, ell)
    assert np.array_equal(idx, idx_ref)
    for k in ("rows", "hull_rows", "ipos", "ineg", "rq", "rk", "lq", "lk", "xjb", "xjt", "cap_dp", "xn"):
        assert _same(getattr(new, k), getattr(ref, k)), k
    assert (np.signbit(new.rows) == np.signbit(ref.rows)).all()
