"""The DP's dense intervals (engine.timeparam._dp: an (M, M) matrix of every level pair, the pairs outside
the windows at inf) against its candidate lists, the tested reference: the same laws bit for bit.

``_DENSE_SHARE`` above 1 turns the matrix off (lists only), 0 turns it on for every interval (most
windows then leave pairs out, so the inf rows are exercised too); the numpy pass throughout (the
compiled pass, where numba is loaded, is compared with the lists in test_timeparam_speed.py).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import engine.timeparam as tp
from engine.errors import InfeasibleError
from engine.timeparam import TechPoint, TimeLimits
from engine.timeparam_example import example_limits, example_path


def _law(share: float, *args, monkeypatch: pytest.MonkeyPatch, **kw):
    with monkeypatch.context() as mp:
        mp.setattr(tp, "_NUMBA", False)
        mp.setattr(tp, "_DENSE_SHARE", share)
        return tp.parametrize(*args, **kw)


def _same(a, b) -> None:
    assert np.array_equal(a.sdot, b.sdot)
    assert a.total_time_s == b.total_time_s
    assert [it.total_time_s for it in a.iterations] == [it.total_time_s for it in b.iterations]
    assert [(it.w_touches, it.o_touches) for it in a.iterations] == \
        [(it.w_touches, it.o_touches) for it in b.iterations]


@pytest.mark.parametrize("levels", [20, 61, 100])
@pytest.mark.parametrize("penalty", [None, 0.0])
def test_dense_intervals_give_the_lists_law_on_the_example(levels: int, penalty: float | None,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    s, X, dX, ddX = example_path(n=240)
    lim = replace(example_limits(), levels=levels)
    if penalty is not None:
        lim = replace(lim, penalty=penalty)
    ref = _law(2.0, s, X, dX, ddX, lim, monkeypatch=monkeypatch)
    for share in (0.0, 0.5, tp._DENSE_SHARE):
        _same(_law(share, s, X, dX, ddX, lim, monkeypatch=monkeypatch), ref)


@pytest.mark.parametrize("seed", range(3))
def test_dense_intervals_non_uniform_spacing_and_generous_limits(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Non-uniform node spacing (every interval its own 2h and K/4h²), and limits so generous that most
    windows hold every level (the default share then takes the matrix by itself)."""
    rng = np.random.default_rng(seed)
    s, X, dX, ddX = example_path(n=200)
    keep = np.sort(np.r_[0, rng.choice(np.arange(1, 199), 120, replace=False), 199])
    s, X, dX, ddX = s[keep], X[keep], dX[keep], ddX[keep]
    base = example_limits()
    for lim in (replace(base, levels=50),
                replace(base, levels=50, a_max=tuple(100.0 * np.asarray(base.a_max)), sdot_max=400.0)):
        for method in ("tube", "dp"):
            ref = _law(2.0, s, X, dX, ddX, lim, method=method, monkeypatch=monkeypatch)
            for share in (0.0, tp._DENSE_SHARE):
                new = _law(share, s, X, dX, ddX, lim, method=method, monkeypatch=monkeypatch)
                assert np.array_equal(ref.sdot, new.sdot), (method, share)


def test_dense_intervals_over_many_chunks_with_the_builder_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """Small chunks (the uniform-h cost takes the 2h of its chunk's first interval, dense or not), dense and
    listed chunks mixed, the next chunk built in the thread meanwhile."""
    s, X, dX, ddX = example_path(n=160)
    lim = replace(example_limits(), levels=40)
    monkeypatch.setattr(tp, "_CHUNK", 3000)
    monkeypatch.setattr(tp, "_DENSE_BATCH", 5)
    ref = _law(2.0, s, X, dX, ddX, lim, monkeypatch=monkeypatch)
    for threads in (False, True):
        monkeypatch.setattr(tp, "_THREADS", threads)
        for share in (0.0, 0.3, 0.7):
            _same(_law(share, s, X, dX, ddX, lim, monkeypatch=monkeypatch), ref)
    tp.shutdown_pool()          # (its thread would keep later tests of this process from forking)


def test_dense_intervals_report_infeasibility_as_the_lists(monkeypatch: pytest.MonkeyPatch) -> None:
    s = np.linspace(0, 10, 11)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    lim = TimeLimits(v_max=(1e6,), a_max=(100.0,), sdot_start=300.0, sdot_end=0.0, levels=30,
                     points=(TechPoint(10.0, s=3.0, label="feed"),))
    msgs = []
    for share in (2.0, 0.0):
        with pytest.raises(InfeasibleError) as err:
            _law(share, s, X, one, 0 * one, lim, method="dp", monkeypatch=monkeypatch)
        msgs.append(str(err.value))
    assert msgs[0] == msgs[1] and "'feed'" in msgs[0]


@pytest.mark.parametrize("seed", range(4))
def test_one_pass_on_random_tubes(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Single DP passes on random tubes (narrow and wide, some nodes pinned) of the example's problem:
    the same speeds and level indices."""
    rng = np.random.default_rng(seed)
    s, X, dX, ddX = example_path(n=150)
    lim = replace(example_limits(), levels=int(rng.integers(10, 90)))
    prob = tp.prepare(s, X, dX, ddX, lim)
    lo0, hi0 = tp._bounds_check(prob)
    mid = rng.uniform(0.2, 0.9) * hi0
    w = rng.uniform(0.01, 0.6) * hi0
    lo = np.maximum(mid - w, 0.0)
    hi = np.minimum(mid + w, prob.cap)
    lo[0], hi[0], lo[-1], hi[-1] = lo0[0], hi0[0], lo0[-1], hi0[-1]
    pin = rng.random(s.size) < 0.05
    lo[pin] = hi[pin]
    monkeypatch.setattr(tp, "_NUMBA", False)
    cluster = float(rng.choice([0.0, 8.0]))
    out = []
    for share in (2.0, 0.0, 0.6):
        monkeypatch.setattr(tp, "_DENSE_SHARE", share)
        try:
            out.append(tp._dp(prob, lo, hi, lim.levels, None, cluster=cluster))
        except InfeasibleError as exc:
            out.append(str(exc))
    for o in out[1:]:
        if isinstance(out[0], str):
            assert o == out[0]
        else:
            assert np.array_equal(o[0], out[0][0]) and np.array_equal(o[1], out[0][1])
