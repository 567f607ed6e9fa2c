"""The final sweep after the tube (engine.timeparam._sweep, issue 16): TOPP-RA's backward/forward scheme on the
DP's own constraints.  Checked against a closed form (bang-bang on a straight move), TOPP-RA's time on the
paper's path at every node density and on random paths, the limits on a sub-grid finer than the one the
law reports, the tube's law it replaces (never slower, the tube's log unchanged), and its numpy version
against the compiled one, bit for bit."""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import engine.timeparam as tp
from engine.errors import InputError
from engine.timeparam import TimeLimits, evaluate_limits, limits_from_mapping, parametrize, prepare
from engine.timeparam_example import N_PAPER, S_N_PAPER, example_limits, example_path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_timelaw_variety import nth_case as _case  # noqa: E402


def _paper(n: int) -> tuple:
    return (*example_path(n, S_N_PAPER), example_limits())


def _fine_ratios(prob, sdot) -> float:
    """The worst of the axis acceleration, axis speed and s̈_T ratios on 200 points per interval."""
    r = evaluate_limits(prob, sdot, n_sub=200)
    return max(r["accel"], r["speed"], r["sddot"], r["sdot"])


@pytest.mark.parametrize("n", [21, 40])
def test_straight_move_is_the_closed_form_bang_bang(n: int) -> None:
    """A straight move of L = 10 mm at |a| <= 100 mm/s², rest to rest: ṡ² = 2a·min(s, L - s), T = 2·sqrt(L/a)
    (n = 21: the switch on a node, exact; n = 40: the switch inside an interval, so at most a node short)."""
    s = np.linspace(0.0, 10.0, n)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    lim = TimeLimits(v_max=(1e6,), a_max=(100.0,), levels=50)
    law = parametrize(s, X, one, 0 * one, lim)
    T = 2.0 * math.sqrt(10.0 / 100.0)
    assert law.sweep_gain_s > 0
    if n == 21:
        np.testing.assert_allclose(law.sdot ** 2, 2 * 100.0 * np.minimum(s, 10.0 - s) * (1 - 1e-9), rtol=1e-8,
                                   atol=1e-9)
        assert law.total_time_s == pytest.approx(T, rel=1e-8)
    assert T * (1 - 1e-9) <= law.total_time_s <= T * (1 + 1.0 / n)
    assert law.max_accel_ratio <= 1.0


@pytest.mark.parametrize("n", [N_PAPER, 3000, 10000])
def test_paper_path_reaches_toppra_time_with_the_limits_inside_the_intervals(n: int) -> None:
    """The paper's 7-axis path at the paper's node density and resampled (the tube on node groups): the law is
    within 1e-4 of TOPP-RA's time (the tube's own law is 0.3-0.4 % above it) and keeps every limit on a
    sub-grid of 200 points per interval, where TOPP-RA's law (limits at the nodes only) does not."""
    s, X, D1, D2, lim = _paper(n)
    law = parametrize(s, X, D1, D2, lim)
    ref = parametrize(s, X, D1, D2, lim, method="toppra")
    tube = law.iterations[-1].total_time_s
    assert tube > 1.002 * ref.total_time_s                        # what the sweep is for
    assert abs(law.total_time_s / ref.total_time_s - 1.0) <= 1e-4
    assert law.total_time_s == pytest.approx(tube - law.sweep_gain_s, rel=1e-12)
    prob = prepare(s, X, D1, D2, lim)
    assert _fine_ratios(prob, law.sdot) <= 1.0
    assert law.sdot[0] == law.sdot[-1] == 0.0


# random paths where the tube's law was 0.2-1.2 % above TOPP-RA (bench_timelaw_variety.py, seeds 2 and 3):
# dense short paths where acceleration binds (node groups), and sparse ones
COSTLY = [(2, 2), (2, 10), (3, 3), (3, 5), (3, 9)]


@pytest.mark.parametrize("seed,case", COSTLY)
def test_random_paths_at_toppra_time_never_slower_than_the_tube(seed: int, case: int) -> None:
    s, X, D1, D2, lim = _case(seed, case)
    law = parametrize(s, X, D1, D2, lim)
    plain = parametrize(s, X, D1, D2, replace(lim, sweep=False))
    ref = parametrize(s, X, D1, D2, lim, method="toppra")
    # the tube itself is untouched: the same iterations; its law is the one without the sweep
    assert [it.total_time_s for it in law.iterations] == [it.total_time_s for it in plain.iterations]
    assert plain.sweep_gain_s == 0.0 and plain.total_time_s == pytest.approx(law.iterations[-1].total_time_s,
                                                                              rel=1e-12) or plain.node_group > 1
    assert law.total_time_s < plain.total_time_s
    assert law.total_time_s <= 1.0025 * ref.total_time_s
    prob = prepare(s, X, D1, D2, lim)
    assert _fine_ratios(prob, law.sdot) <= 1.0


@pytest.mark.parametrize("which", ["paper", "dense"])
def test_numpy_sweep_is_the_compiled_one_bit_for_bit(which: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The numpy passes (the reference, used where numba is not loaded) and the compiled ones give the same
    bits, on chains with and without node groups."""
    from engine import timeparam_jit

    if timeparam_jit.kernel(10 ** 6) is None or timeparam_jit.sweep_kernels() is None:
        pytest.skip("numba is not usable here")
    s, X, D1, D2, lim = _paper(N_PAPER) if which == "paper" else _case(3, 3)
    prob = tp._with_chains(tp._prepare(s, X, D1, D2, lim, chains=False))
    compiled = tp._sweep(prob)
    monkeypatch.setattr(tp, "_NUMBA", False)
    reference = tp._sweep(prob)
    assert compiled is not None and reference is not None
    assert np.array_equal(compiled, reference)


def test_a_law_is_only_replaced_by_a_faster_one_within_the_limits(monkeypatch: pytest.MonkeyPatch) -> None:
    """_keep_faster keeps the tube's law when the sweep gives none, a slower one, or one outside a limit."""
    s, X, D1, D2, lim = _paper(N_PAPER)
    prob = tp._with_chains(tp._prepare(s, X, D1, D2, lim, chains=False))
    tube = parametrize(s, X, D1, D2, replace(lim, sweep=False)).sdot
    good = tp._sweep(prob)
    assert good is not None
    law, gain, ratios = tp._keep_faster(prob, tube)
    assert law is good or np.array_equal(law, good)
    assert gain > 0 and ratios is not None and ratios["accel"] <= 1.0
    for alt in (None, tube * 0.999, good * 1.001):
        monkeypatch.setattr(tp, "_sweep", lambda p, alt=alt: alt)
        law, gain, ratios = tp._keep_faster(prob, tube)
        assert law is tube and gain == 0.0 and ratios is None


def test_sweep_switch_in_the_limits_file() -> None:
    base = {"v_max": [100.0], "a_max": [1000.0]}
    assert limits_from_mapping(base).sweep is True
    assert limits_from_mapping({**base, "sweep": False}).sweep is False
    with pytest.raises(InputError) as exc:
        limits_from_mapping({**base, "sweep": "no"}, file="lim.toml")
    assert exc.value.location.field == "sweep" and "true or false" in str(exc.value)


def test_the_node_groups_hull_is_reused_for_the_sweeps_chains() -> None:
    """On a dense path the node groups are built from the hull of every interval's rows; the sweep's chains on
    the given nodes reuse that hull: the same chains, bit for bit, as made from scratch, and one hull less."""
    from dataclasses import replace as dc_replace

    s, X, D1, D2, lim = _paper(3000)
    prob = tp._prepare(s, X, D1, D2, lim, chains=False)
    ell = tp._group_length(prob)
    assert ell is not None
    tp._coarse_problem(prob, ell)
    assert prob.fine_hull is not None
    calls = []
    real = tp._hulls

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    try:
        tp._hulls = counting
        reused = tp._with_chains(prob)
        n_reused = len(calls)
        fresh = tp._with_chains(dc_replace(prob, fine_hull=None))
    finally:
        tp._hulls = real
    assert n_reused == 0 and len(calls) == 1
    for k in ("rq", "rk", "lq", "lk", "xjb", "xjt", "xn", "cap_dp"):
        assert np.array_equal(getattr(reused, k), getattr(fresh, k)), k
    assert reused.fine_hull is None
    no_sweep = tp._prepare(s, X, D1, D2, replace(lim, sweep=False), chains=False)
    tp._coarse_problem(no_sweep, ell)
    assert no_sweep.fine_hull is None                  # nothing kept when no sweep will use it
