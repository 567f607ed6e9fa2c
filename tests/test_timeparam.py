"""Time parametrization by DP + tube (seed 003, MATH.md §B): engine tests."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad

from engine.errors import Cancelled, InfeasibleError, InputError
from engine.state import RecordingState
from engine.timeparam import (
    IterationLog,
    TechPoint,
    TimeLimits,
    _bounds_check,
    _dp,
    block_feeds,
    curvature_energy,
    limits_from_mapping,
    parametrize,
    prepare,
    time_at,
)
from engine.timeparam_example import _HARMONICS, _TRACK_RAMP, N_PAPER, S_N_PAPER, example_limits, example_path

# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------


def _random_path(rng: np.random.Generator, n: int, p: int) -> tuple[np.ndarray, ...]:
    s = np.concatenate([[0.0], np.cumsum(rng.uniform(2.0, 5.0, n - 1))])
    L = s[-1]
    X = np.zeros((n, p))
    dX = np.zeros((n, p))
    ddX = np.zeros((n, p))
    for c in range(p):
        a, k, ph = rng.uniform(0.2, 1.0), rng.uniform(0.3, 2.0), rng.uniform(0, 6)
        w = 2 * np.pi * k / L
        X[:, c] = a * np.sin(w * s + ph)
        dX[:, c] = a * w * np.cos(w * s + ph)
        ddX[:, c] = -a * w * w * np.sin(w * s + ph)
    return s, X, dX, ddX


def _brute_force(prob, lo, hi, M, square, cluster=0.0):
    """Enumerate every level sequence; feasibility straight from the constraint rows."""
    n = prob.s.size
    plo, phi = (lo**2, hi**2) if square else (lo, hi)
    xi = np.array([-1.0 + 2.0 * j / (M - 1) for j in range(M)])
    frac = 0.5 * (1.0 + (xi + cluster * xi**3) / (1.0 + cluster))
    lev = []
    for i in range(n):
        if phi[i] <= plo[i]:
            vals = [plo[i]]
        else:
            vals = list(plo[i] + (phi[i] - plo[i]) * frac)
        lev.append(np.sqrt(vals) if square else np.asarray(vals))
    K = prob.limits.penalty * prob.p**2
    best = math.inf
    for combo in itertools.product(*[range(len(v)) for v in lev[1:-1]]):
        v = np.array([lev[0][0], *[lev[i + 1][j] for i, j in enumerate(combo)], lev[-1][0]])
        x = v * v
        u = (x[1:] - x[:-1]) / (2 * prob.h)
        val = np.einsum("irk,ik->ir", prob.rows, np.stack([x[:-1], u], 1))
        if np.any(val > 1.0) or np.any(v[:-1] + v[1:] <= 0):
            continue
        cost = float(np.sum(2 * prob.h / (v[:-1] + v[1:]) + K * u * u))
        best = min(best, cost)
    return best


def _path_cost(prob, v):
    K = prob.limits.penalty * prob.p**2
    u = (v[1:] ** 2 - v[:-1] ** 2) / (2 * prob.h)
    return float(np.sum(2 * prob.h / (v[:-1] + v[1:]) + K * u * u))


@pytest.fixture(scope="module")
def example():
    s, X, dX, ddX = example_path()
    lim = example_limits()
    return s, X, dX, ddX, lim


@pytest.fixture(scope="module")
def tube_law(example):
    s, X, dX, ddX, lim = example
    return parametrize(s, X, dX, ddX, lim, method="tube")


@pytest.fixture(scope="module")
def toppra_law(example):
    s, X, dX, ddX, lim = example
    return parametrize(s, X, dX, ddX, lim, method="toppra")


# --------------------------------------------------------------------------------------------------
# the DP procedure
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(12))
def test_dp_equals_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, p, M = 6, 2, 4
    s, X, dX, ddX = _random_path(rng, n, p)
    check = "arrival" if seed % 3 == 0 else "interval"
    lim = TimeLimits(v_max=(1.0, 1.0), a_max=tuple(rng.uniform(0.05, 1.0, p)), sdot_max=float(rng.uniform(20, 60)),
                     sddot_max=float(rng.uniform(100, 400)), levels=M, penalty=float(rng.choice([0.0, 1e-6])),
                     accel_check=check)
    prob = prepare(s, X, dX, ddX, lim)
    lo, hi = _bounds_check(prob)
    if seed % 2:                                    # a tube-like band for odd seeds
        mid = rng.uniform(0.3, 0.8, n) * hi
        lo, hi = np.maximum(mid - 10, 0), np.minimum(mid + 10, hi)
        lo[0] = hi[0] = 0.0
        lo[-1] = hi[-1] = 0.0
    square = seed % 4 == 1
    cluster = 8.0 if seed % 4 == 3 else 0.0
    best = _brute_force(prob, lo, hi, M, square, cluster)
    if math.isinf(best):
        with pytest.raises(InfeasibleError):
            _dp(prob, lo, hi, M, square=square, cluster=cluster)
        return
    v, _ = _dp(prob, lo, hi, M, square=square, cluster=cluster)
    assert _path_cost(prob, v) == pytest.approx(best, rel=1e-9)


def test_brute_force_instances_are_mostly_feasible() -> None:
    """Guard for the test above: most random instances must have an answer to compare."""
    feasible = binding = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        s, X, dX, ddX = _random_path(rng, 6, 2)
        lim = TimeLimits(v_max=(1.0, 1.0), a_max=tuple(rng.uniform(0.05, 1.0, 2)), sdot_max=40.0,
                         sddot_max=300.0, levels=4)
        prob = prepare(s, X, dX, ddX, lim)
        lo, hi = _bounds_check(prob)
        best = _brute_force(prob, lo, hi, 4, False)
        feasible += math.isfinite(best)
        # the limits bind: without acceleration limits the optimum would be faster
        free = prepare(s, X, dX, ddX, replace(lim, a_max=(1e9, 1e9), sddot_max=1e9))
        binding += math.isfinite(best) and _brute_force(free, lo, hi, 4, False) < best * (1 - 1e-9)
    assert feasible >= 8 and binding >= 6


def test_arrival_check_matches_the_paper_formula() -> None:
    """With accel_check='arrival' the rows are exactly the paper's check at node i (Table 2 data)."""
    rng = np.random.default_rng(7)
    s, X, dX, ddX = _random_path(rng, 8, 3)
    lim = TimeLimits(v_max=(1, 1, 1), a_max=(0.1, 0.2, 0.3), sddot_max=250.0, accel_check="arrival")
    prob = prepare(s, X, dX, ddX, lim)
    for _ in range(200):
        i = int(rng.integers(0, 7))
        vk, vj = rng.uniform(0, 40, 2)
        u = (vj**2 - vk**2) / (2 * prob.h[i])
        paper_ok = np.all(np.abs(ddX[i + 1] * vj**2 + dX[i + 1] * u) <= np.array(lim.a_max)) and abs(u) <= 250
        rows_ok = np.all(prob.rows[i] @ np.array([vk**2, u]) <= 1.0)
        assert paper_ok == rows_ok


def test_bernstein_rows_bound_the_acceleration_inside_intervals() -> None:
    """Any (ṡ_k², s̈) admitted by the rows keeps |a_c| <= A_c on a fine sub-grid of the quintic path."""
    rng = np.random.default_rng(3)
    s, X, dX, ddX = _random_path(rng, 10, 3)
    A = np.array([0.1, 0.2, 0.3])
    lim = TimeLimits(v_max=(1, 1, 1), a_max=tuple(A))
    prob = prepare(s, X, dX, ddX, lim)
    tau = np.linspace(0, 1, 201)
    worst = 0.0
    for _ in range(300):
        i = int(rng.integers(0, 9))
        z = np.array([rng.uniform(0, 1), rng.uniform(-1, 1)])
        z *= rng.uniform(0.9, 1.0) / np.max(prob.rows[i] @ z)     # admitted, close to the boundary
        x0, u = z
        q1 = np.polynomial.polynomial.polyval(tau, prob.d1[i].T)           # (p, 201)
        q2 = np.polynomial.polynomial.polyval(tau, prob.d2[i].T)
        x = x0 + 2 * u * prob.h[i] * tau
        worst = max(worst, float(np.max(np.abs(q2 * x + q1 * u) / A[:, None])))
    assert 0.9 < worst <= 1.0 + 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_symmetric_hull_equals_qhull(seed: int) -> None:
    """The vectorised hull of centrally symmetric sets equals scipy's Qhull, row by row, incl.
    duplicates, zero rows, points on one ray and nearly flat sets."""
    from scipy.spatial import ConvexHull

    from engine.timeparam import _hull_sym

    rng = np.random.default_rng(seed)
    B, R = 300, 20
    half = rng.normal(size=(B, R, 2)) * rng.uniform(0.01, 100, (B, 1, 2))
    half[:, 3] = half[:, 2]                                   # duplicates
    half[:, 5] = 0.3 * half[:, 4]                             # on one ray, inside
    half[:, 7] = 0.0                                          # dropped rows
    half[::7, :, 1] *= 1e-9                                   # nearly flat rows
    half[:, 0] = [1.0, 0.0]                                   # a box pair keeps the origin inside
    half[:, 1] = [0.0, 1.0]
    pts = np.concatenate([half, -half], axis=1)
    order, m = _hull_sym(pts, np.arange(R), np.arange(R, 2 * R))
    for b in range(B):
        got = order[b, :m[b]]
        p = pts[b, got]
        # counter-clockwise, strictly convex
        e = np.roll(p, -1, axis=0) - p
        assert np.all(e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0] > 0)
        ref = ConvexHull(pts[b])
        want = {tuple(pts[b, i]) for i in ref.vertices}
        assert {tuple(q) for q in p} == want


def test_quintic_interpolant_reproduces_the_example_derivatives(example) -> None:
    s, X, dX, ddX, lim = example
    prob = prepare(s, X, dX, ddX, lim)
    tau = 0.37
    i = 300
    sq = s[i] + tau * prob.h[i]
    u = sq / S_N_PAPER
    exact1 = np.zeros(7)
    for c, terms in enumerate(_HARMONICS):
        for amp, k, ph in terms:
            w = 2 * np.pi * k / S_N_PAPER
            exact1[c] += amp * w * np.cos(2 * np.pi * k * u + ph)
    exact1[-1] += _TRACK_RAMP / S_N_PAPER
    got = np.polynomial.polynomial.polyval(tau, prob.d1[i].T)
    assert np.allclose(got, exact1, rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------------------------------------------
# the tube algorithm on the paper's setting
# --------------------------------------------------------------------------------------------------


def test_example_has_the_papers_size(example) -> None:
    s, X, dX, ddX, lim = example
    assert s.size == N_PAPER == 893 and X.shape == (893, 7)
    assert s[-1] == pytest.approx(2846.9)
    assert lim.v_max[6] == pytest.approx(1866.667) and lim.a_max[3] == pytest.approx(0.611)
    assert [p.label for p in lim.points] == ["feed", "cut"]
    assert lim.levels == 100 and lim.penalty == 0.5e-11 and lim.tube_share == 0.1 and lim.stop_percent == 0.5


def _exact_ratios(law, lim):
    """Limit ratios on a fine sub-grid, with the example's exact (analytic) derivatives."""
    s, v = law.s, law.sdot
    h = np.diff(s)
    u = (v[1:] ** 2 - v[:-1] ** 2) / (2 * h)
    tau = np.linspace(0, 1, 9)
    sq = (s[:-1, None] + h[:, None] * tau).ravel()
    x = np.maximum((v[:-1, None] ** 2 + 2 * (u * h)[:, None] * tau).ravel(), 0)
    uq = np.repeat(u, tau.size)
    d1 = np.zeros((sq.size, 7))
    d2 = np.zeros((sq.size, 7))
    for c, terms in enumerate(_HARMONICS):
        for amp, k, ph in terms:
            w = 2 * np.pi * k / S_N_PAPER
            d1[:, c] += amp * w * np.cos(w * sq + ph)
            d2[:, c] += -amp * w * w * np.sin(w * sq + ph)
    d1[:, -1] += _TRACK_RAMP / S_N_PAPER
    acc = np.abs(d2 * x[:, None] + d1 * uq[:, None]) / np.array(lim.a_max)
    spd = np.abs(d1) * np.sqrt(x)[:, None] / np.array(lim.v_max)
    return acc.max(), spd.max(), np.abs(u).max() / lim.sddot_max


def test_tube_result_keeps_every_limit(tube_law, example) -> None:
    s, X, dX, ddX, lim = example
    law = tube_law
    acc, spd, sdd = _exact_ratios(law, lim)
    assert acc <= 1.0 + 1e-6 and spd <= 1.0 + 1e-9 and sdd <= 1.0 + 1e-9
    assert law.max_accel_ratio <= 1.0 + 1e-9 and law.max_speed_ratio <= 1.0 + 1e-9
    assert law.sdot.max() <= lim.sdot_max + 1e-9
    assert law.sdot[0] == 0.0 and law.sdot[-1] == 0.0
    for pt in lim.points:                       # ṡ is monotone inside an interval: bracketing nodes
        i = int(np.searchsorted(s, pt.s))
        assert law.sdot[i - 1] <= pt.sdot_max + 1e-9 and law.sdot[i] <= pt.sdot_max + 1e-9
    assert acc > 0.99                             # and the law really uses the limits


def test_arrival_check_overshoots_inside_intervals(example) -> None:
    """The paper's check at the arrival node lets the acceleration exceed A_c inside intervals."""
    s, X, dX, ddX, lim = example
    law = parametrize(s, X, dX, ddX, replace(lim, accel_check="arrival"), method="dp")
    acc, _, _ = _exact_ratios(law, lim)
    assert acc > 1.01


def test_tube_is_near_the_time_optimum(tube_law, toppra_law) -> None:
    """The tube's own law is within 0.5 % of TOPP-RA's time; the final sweep brings the law to TOPP-RA's
    time (to 1e-4: both solve the same continuous problem, TOPP-RA with its limits at the nodes only, ours
    inside every interval)."""
    assert tube_law.iterations[-1].total_time_s <= 1.005 * toppra_law.total_time_s
    assert tube_law.sweep_gain_s > 0
    assert abs(tube_law.total_time_s / toppra_law.total_time_s - 1.0) <= 1e-4
    assert max(tube_law.max_accel_ratio, tube_law.max_speed_ratio, tube_law.max_sddot_ratio) <= 1.0


def test_iteration_log_follows_the_paper_rules(tube_law, example) -> None:
    s, X, dX, ddX, lim = example
    its = tube_law.iterations
    assert its[0].r == 1 and its[0].half_width is None and its[0].decrease_percent is None
    assert its[1].half_width == pytest.approx(lim.tube_share * its[0].sdot.max())
    for a, b in zip(its[:-1], its[1:]):
        assert b.r == a.r + 1
        assert b.specific_time == pytest.approx(b.total_time_s / (s[-1] - s[0]))
        assert b.decrease_percent == pytest.approx((1 - b.specific_time / a.specific_time) * 100)
        assert b.halved == (b.w_touches == 0)
        assert b.w_touches == _runs(b.w_mask)
        if a.r >= 2:
            assert b.half_width == pytest.approx(a.half_width / 2 if a.halved else a.half_width)
        stop_rule = b.w_touches == 0 and a.r >= 2 and a.w_touches == 0 and b.decrease_percent < lim.stop_percent
        assert b.stop == stop_rule
        assert np.all(b.lower <= b.sdot + 1e-9) and np.all(b.sdot <= b.upper + 1e-9)
    assert its[-1].stop and not any(it.stop for it in its[:-1])
    # the law is the last iteration's, or the final sweep's where that is faster (by sweep_gain_s)
    if tube_law.sweep_gain_s == 0:
        assert np.array_equal(its[-1].sdot, tube_law.sdot)
    assert tube_law.total_time_s == pytest.approx(its[-1].total_time_s - tube_law.sweep_gain_s, rel=1e-12)


def _runs(mask):
    m = np.concatenate([[0], mask.astype(int)])
    return int(np.sum(np.diff(m) == 1))


def test_touch_masks_mark_the_bounds(tube_law) -> None:
    for it in tube_law.iterations[1:]:
        at_bound = np.isclose(it.sdot, it.upper) | np.isclose(it.sdot, it.lower)
        assert np.all(at_bound[it.w_mask]) and np.all(at_bound[it.o_mask])
        assert not np.any(it.w_mask & it.o_mask)


def test_state_gets_every_iteration_and_can_cancel(example) -> None:
    s, X, dX, ddX, lim = example
    st = RecordingState()
    law = parametrize(s[:200], X[:200], dX[:200], ddX[:200], replace(lim, points=()), state=st)
    assert [p.r for p in st.partials] == [it.r for it in law.iterations]
    assert all(isinstance(p, IterationLog) for p in st.partials)
    assert st.fractions[-1] == 1.0 and all(0 <= f <= 1 for f in st.fractions)
    with pytest.raises(Cancelled):
        parametrize(s[:200], X[:200], dX[:200], ddX[:200], replace(lim, points=()),
                    state=RecordingState(cancel_after=1))


# --------------------------------------------------------------------------------------------------
# technological points and infeasibility
# --------------------------------------------------------------------------------------------------


def test_zero_speed_point_inside_an_interval_is_infeasible(example) -> None:
    s, X, dX, ddX, lim = example
    pts = (TechPoint(0.0, s=1000.5, label="clamp"),)
    with pytest.raises(InfeasibleError) as err:
        parametrize(s, X, dX, ddX, replace(lim, points=pts), method="dp")
    msg = str(err.value)
    assert "'clamp'" in msg and "1000.50" in msg


def test_zero_speed_point_on_a_node_stops_there(example) -> None:
    s, X, dX, ddX, lim = example
    law = parametrize(s, X, dX, ddX, replace(lim, points=(TechPoint(0.0, s=float(s[400]), label="stop"),)),
                      method="dp")
    assert law.sdot[400] == 0.0 and law.sdot[399] > 0 and law.sdot[401] > 0
    assert math.isfinite(law.total_time_s)


def test_interval_point_caps_the_speed(example) -> None:
    s, X, dX, ddX, lim = example
    pt = TechPoint(120.0, s_from=1500.0, s_to=1700.0, label="lay-up")
    law = parametrize(s, X, dX, ddX, replace(lim, points=(pt,)), method="dp")
    i0 = int(np.searchsorted(s, 1500.0)) - 1
    i1 = int(np.searchsorted(s, 1700.0))
    assert law.sdot[i0:i1 + 1].max() <= 120.0 + 1e-9
    assert law.sdot[i0:i1 + 1].max() >= 119.0


def test_unreachable_start_speed_is_reported(example) -> None:
    s, X, dX, ddX, lim = example
    with pytest.raises(InfeasibleError, match="start speed"):
        parametrize(s, X, dX, ddX, replace(lim, sdot_start=5000.0))


def test_infeasible_acceleration_is_reported_with_s() -> None:
    """Start at a speed that cannot be braked to the technological point in time."""
    s = np.linspace(0, 10, 11)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    lim = TimeLimits(v_max=(1e6,), a_max=(100.0,), sdot_start=300.0, sdot_end=0.0,
                     points=(TechPoint(10.0, s=3.0, label="feed"),))
    with pytest.raises(InfeasibleError) as err:
        parametrize(s, X, one, 0 * one, lim, method="dp")
    assert "'feed'" in str(err.value) and "s = " in str(err.value)


def test_bad_inputs_are_input_errors(example) -> None:
    s, X, dX, ddX, lim = example
    with pytest.raises(InputError, match="increase"):
        parametrize(s[::-1], X, dX, ddX, lim)
    with pytest.raises(InputError, match="p = 7"):
        parametrize(s, X, dX, ddX, replace(lim, v_max=(1.0,), a_max=(1.0,)))
    with pytest.raises(InputError, match="outside"):
        parametrize(s, X, dX, ddX, replace(lim, points=(TechPoint(1.0, s=5000.0),)))
    with pytest.raises(InputError, match="method"):
        parametrize(s, X, dX, ddX, lim, method="magic")
    with pytest.raises(InputError, match="s_to"):
        limits_from_mapping({"v_max": [1.0], "a_max": [1.0], "points": [{"s_from": 5.0, "s_to": 1.0,
                                                                         "sdot_max": 1.0}]})
    with pytest.raises(InputError, match="levels"):
        limits_from_mapping({"v_max": [1.0], "a_max": [1.0], "levels": 1})
    flat = np.zeros_like(dX)
    with pytest.raises(InputError, match="unbounded"):
        parametrize(s, flat, flat, flat, replace(lim, sdot_max=math.inf, sddot_max=math.inf, points=()))


# --------------------------------------------------------------------------------------------------
# curvature energy and NC feeds
# --------------------------------------------------------------------------------------------------


def test_curvature_energy_of_a_circle_arc() -> None:
    R = 2.0
    t = np.linspace(-1.0, 1.0, 4001)
    y = np.sqrt(R * R - t * t)
    E = curvature_energy(t, y, speed_unit=1.0)
    assert E == pytest.approx((t[-1] - t[0] - (t[1] - t[0])) / R**2, rel=1e-6)   # dual cells of interior nodes
    assert curvature_energy(t, 3 * t + 1) == pytest.approx(0.0, abs=1e-12)


def test_energies_are_reported(tube_law, toppra_law) -> None:
    for law in (tube_law, toppra_law):
        assert law.energy > 0 and law.energy_mm > 0


def test_time_at_matches_quadrature(tube_law) -> None:
    law = tube_law
    i = 500
    h = law.s[i + 1] - law.s[i]
    x0 = law.sdot[i] ** 2
    u = (law.sdot[i + 1] ** 2 - x0) / (2 * h)
    for frac in (0.1, 0.5, 0.9):
        sig = frac * h
        ref, _ = quad(lambda q: 1.0 / math.sqrt(x0 + 2 * u * q), 0.0, sig)
        assert time_at(law, law.s[i] + sig) - law.t[i] == pytest.approx(ref, rel=1e-10)


def test_block_feeds_reproduce_the_program_time(tube_law) -> None:
    law = tube_law
    ends = np.arange(10, law.s.size, 10)
    ends = np.append(ends, law.s.size - 1) if ends[-1] != law.s.size - 1 else ends
    dur, feed = block_feeds(law, ends)
    assert dur.sum() == pytest.approx(law.total_time_s, rel=1e-12)
    assert np.allclose(feed, 60.0 / dur)
    # arbitrary s values, and the controller's rounding of F to 3 decimals
    rng = np.random.default_rng(1)
    s_ends = np.sort(rng.uniform(law.s[0], law.s[-1], 150))
    s_ends = np.append(s_ends, law.s[-1])
    dur2, feed2 = block_feeds(law, s_ends, decimals=3)
    program_time = float(np.sum(60.0 / feed2))
    assert abs(program_time / law.total_time_s - 1) < 0.01
    assert np.all(np.round(feed2, 3) == feed2)
    with pytest.raises(InputError, match="increase"):
        block_feeds(law, np.array([100.0, 50.0]))


def test_uniform_tube_levels_follow_the_same_rules(example) -> None:
    """tube_cluster = 0 is the paper's uniform level grid: same rules, a valid (slower) answer."""
    s, X, dX, ddX, lim = example
    law = parametrize(s, X, dX, ddX, replace(lim, tube_cluster=0.0, levels=74))
    assert law.max_accel_ratio <= 1.0 + 1e-9
    its = law.iterations
    assert its[-1].stop and all(b.halved == (b.w_touches == 0) for b in its[1:])
    assert law.total_time_s < its[0].total_time_s


def test_threaded_chunk_building_gives_the_same_answer(example, monkeypatch) -> None:
    import engine.timeparam as tp

    s, X, dX, ddX, lim = example
    prob = prepare(s, X, dX, ddX, replace(lim, levels=300))
    lo, hi = _bounds_check(prob)
    monkeypatch.setattr(tp, "_THREADS", False)
    v0, j0 = _dp(prob, lo, hi, 300)
    monkeypatch.setattr(tp, "_THREADS", True)
    v1, j1 = _dp(prob, lo, hi, 300)
    tp.shutdown_pool()          # (its thread would keep later tests of this process from forking)
    assert np.array_equal(j0, j1) and np.array_equal(v0, v1)


def test_tube_keeps_the_previous_law_if_a_tube_grid_is_infeasible(example, monkeypatch) -> None:
    import engine.timeparam as tp

    s, X, dX, ddX, lim = example
    real = tp._dp
    calls = []

    def flaky(*args, **kw):
        calls.append(1)
        if len(calls) == 3:
            raise InfeasibleError("synthetic")
        return real(*args, **kw)

    monkeypatch.setattr(tp, "_dp", flaky)
    law = parametrize(s, X, dX, ddX, replace(lim, sweep=False))
    its = law.iterations
    assert len(its) == 3 and its[-1].stop and "previous" in its[-1].note
    assert np.array_equal(law.sdot, its[1].sdot) and law.max_accel_ratio <= 1 + 1e-9
    calls.clear()                                  # with the final sweep: the same log, a law at least as good
    swept = parametrize(s, X, dX, ddX, lim)
    assert [it.total_time_s for it in swept.iterations] == [it.total_time_s for it in its]
    assert swept.total_time_s <= law.total_time_s and swept.max_accel_ratio <= 1.0


@pytest.mark.parametrize("method", ["tube", "toppra"])
def test_straight_line_bang_bang_closed_form(method) -> None:
    """A straight move of L = 10 mm with |a| <= 100 mm/s², rest to rest: T = 2·sqrt(L/a)."""
    s = np.linspace(0.0, 10.0, 21)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    lim = TimeLimits(v_max=(1e6,), a_max=(100.0,), levels=50)
    law = parametrize(s, X, one, 0 * one, lim, method=method)
    T = 2.0 * math.sqrt(10.0 / 100.0)
    assert law.total_time_s == pytest.approx(T, rel=5e-3)
    assert law.total_time_s >= T * (1 - 1e-9) or method == "toppra"
    assert np.max(law.sdot) == pytest.approx(math.sqrt(100.0 * 10.0), rel=5e-3)   # peak at the middle


# speed limits up to the largest the limits accept (1e9 units/s: beyond is refused as a units error)
@pytest.mark.parametrize(("v_lin", "noise"), [(1e6, 1e-16), (1e9, 0.0), (3e8, 0.0), (1e9, 1e-13), (1e9, 1e-12),
                                             (1e6, 1e-14), (1e9, 1e-16)])
def test_axis_at_rest_and_linear_axis(v_lin: float, noise: float) -> None:
    """One axis constant, one linear in s (X'' = 0, maybe round-off noise on the derivatives), no sdot_max.

    The constraint normals of such intervals are parallel or at round-off level; the hull/chains used
    to give 0/0 vertices (NaN, "path speed is unbounded") or lose the thin feasible polygon inside a
    huge speed box (wrong windows, "no admissible law").  The answer is the bang-bang closed form of
    the linear axis: L = 20 mm of axis travel, |a| <= 100 mm/s², T = 2·sqrt(L/a).
    """
    rng = np.random.default_rng(5)
    s = np.linspace(0.0, 10.0, 21)
    X = np.stack([np.full_like(s, 3.0), 2.0 * s], 1)
    dX = np.stack([rng.normal(0.0, noise, s.size), 2.0 + rng.normal(0.0, noise, s.size)], 1)
    ddX = rng.normal(0.0, noise, X.shape)
    lim = TimeLimits(v_max=(5.0, v_lin), a_max=(10.0, 100.0), levels=50)
    prob = prepare(s, X, dX, ddX, lim)
    assert np.all(np.isfinite(prob.cap_dp)) and np.all(np.isfinite(prob.rk)) and np.all(np.isfinite(prob.lk))
    law = parametrize(s, X, dX, ddX, lim, method="tube")
    T = 2.0 * math.sqrt(20.0 / 100.0)
    assert T * (1 - 1e-9) <= law.total_time_s <= T * 1.005
    assert law.max_accel_ratio <= 1.0 + 1e-9


def test_user_levels_below_the_schema_minimum_are_refused(tmp_path) -> None:  # noqa: ANN001
    """``--levels`` and a limits file ask for at least as many levels as a job may (5): with 2 the DP had no
    speed between rest and the cap and failed with 'no admissible law' against a file with no line."""
    import subprocess
    import sys

    from engine.job import TimeLawSpec
    from engine.timeparam import MIN_USER_LEVELS, limits_from_toml

    assert min(m.ge for m in TimeLawSpec.model_fields["levels"].metadata if hasattr(m, "ge")) == MIN_USER_LEVELS
    out = subprocess.run([sys.executable, "-m", "engine", "timeparam", "--example", "--levels", "2"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "--levels" in out.stderr and "Traceback" not in out.stderr
    lim = tmp_path / "lim.toml"
    lim.write_text("v_max = [1.0]\na_max = [1.0]\nlevels = 3\n")
    with pytest.raises(InputError, match="levels"):
        limits_from_toml(lim)
