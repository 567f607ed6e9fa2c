"""NC blocks: linear approximation within tolerance, times (17), pairwise minimisation (18)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import LinearConstraint, minimize

from engine.blocks import (
    Blocks,
    check_blocks,
    check_program,
    make_blocks,
    optimise_block_times,
    preliminary_times,
    solve_pairs,
)
from engine.errors import InputError
from engine.kinematics import demo_eye_path, forward_kinematics, inverse_kinematics, load_machine, parse_machine

MACHINES = ["gantry6", "lathe2", "lathe3", "lathe4", "robot_cell"]


def _setup(name: str, kind: str = "dome", n: int = 4000, circuits: int = 2):
    m = load_machine(name)
    p = demo_eye_path("helix" if name == "lathe2" else kind, n=n, circuits=circuits)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    return m, p, ap


def _to_polyline(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of every point to the polyline ``poly`` (segments next to the 4 nearest vertices)."""
    from scipy.spatial import cKDTree

    k = min(4, len(poly))
    _, idx = cKDTree(poly).query(pts, k=k)
    idx = idx.reshape(len(pts), k)
    best = np.full(len(pts), np.inf)
    for off in (-1, 0):
        s = np.clip(idx + off, 0, len(poly) - 2)
        a, b = poly[s], poly[s + 1]
        dv = b - a
        tt = np.clip(np.einsum("nkj,nkj->nk", pts[:, None, :] - a, dv) /
                     np.maximum(np.einsum("nkj,nkj->nk", dv, dv), 1e-300), 0, 1)
        d = np.linalg.norm(pts[:, None, :] - (a + tt[..., None] * dv), axis=2).min(axis=1)
        best = np.minimum(best, d)
    return best


@pytest.mark.parametrize("name", MACHINES)
def test_blocks_within_tolerance_both_ways(name):
    m, p, ap = _setup(name)
    tol = 0.05
    b = make_blocks(m, ap, tol)
    assert b.index[0] == 0 and b.index[-1] == len(ap.q) - 1
    assert np.all(np.diff(b.index) > 0)
    assert np.all(b.max_error <= tol)
    assert np.array_equal(b.q, ap.q[b.index])
    # independent check 1: every path point is within tol of its block's interpolated segment
    # (nearest point on a dense sampling of the block, not the time-fraction rule used inside)
    # independent check 2: every point of the interpolated block is near the eye path
    worst_path, worst_block = 0.0, 0.0
    for i in range(0, b.n, max(1, b.n // 40)):
        a, c = b.index[i], b.index[i + 1]
        u = np.linspace(0, 1, max(200, 8 * (c - a)))
        qs = b.q[i] + u[:, None] * (b.q[i + 1] - b.q[i])
        e_blk, _ = forward_kinematics(m, qs)
        seg = ap.eye_xyz[a:c + 1]
        worst_path = max(worst_path, _to_polyline(seg, e_blk).max())
        worst_block = max(worst_block, _to_polyline(e_blk, seg).max())
    assert worst_path <= tol * (1 + 1e-6)
    assert worst_block <= tol * (1 + 1e-6) + 1e-3     # chord error of the path's own sampling


def test_tighter_tolerance_gives_more_blocks():
    m, p, ap = _setup("lathe4")
    counts = [make_blocks(m, ap, t).n for t in (0.5, 0.1, 0.02)]
    assert counts[0] < counts[1] < counts[2]


def test_preliminary_times_formula_17():
    m, p, ap = _setup("lathe3")
    b = make_blocks(m, ap, 0.1)
    fmax = [a.max_speed for a in m.axes]
    for i in range(b.n):
        expect = max(max(abs(b.delta[i, k]) / fmax[k] for k in range(len(fmax))), m.min_block_time)
        assert b.t17[i] == pytest.approx(expect, rel=1e-14)
    assert np.allclose(preliminary_times([[0.0, 0.0]], [1.0, 1.0], 0.01), [0.01])


def _scipy_pair(ti, tj, a, b, p, xlo, xhi, ylo, yhi, x0, y0):
    A = np.vstack([np.stack([a, -b], axis=1), np.stack([-a, b], axis=1)])
    cons = LinearConstraint(A, -np.inf, np.concatenate([p, p]))
    best = np.inf
    for s in [(x0, y0), (0.5 * (xlo + xhi), 0.5 * (ylo + yhi))]:
        r = minimize(lambda z: ti / z[0] + tj / z[1], s, jac=lambda z: np.array([-ti / z[0] ** 2, -tj / z[1] ** 2]),
                     bounds=[(max(xlo, 1e-9), xhi), (max(ylo, 1e-9), yhi)], constraints=[cons], method="SLSQP",
                     options={"ftol": 1e-15, "maxiter": 500})
        z = r.x
        viol = max(0.0, (A @ z - np.concatenate([p, p])).max(), xlo - z[0], z[0] - xhi, ylo - z[1], z[1] - yhi)
        if viol < 1e-10:
            best = min(best, ti / z[0] + tj / z[1])
            if r.success:
                break
    return best


def test_pair_solver_agrees_with_scipy_on_random_pairs():
    rng = np.random.default_rng(18)
    P, m = 2000, 3
    ti = rng.uniform(0.002, 1.0, P)
    tj = rng.uniform(0.002, 1.0, P)
    a = rng.uniform(-1, 1, (P, m))
    b = rng.uniform(-1, 1, (P, m))
    # half of the pairs without reversals (the paper's class), half with some
    same = rng.random(P) < 0.5
    b[same] = np.abs(b[same]) * np.sign(a[same])
    x0 = rng.uniform(0.05, 1, P)
    y0 = rng.uniform(0.05, 1, P)
    p = np.maximum(rng.uniform(0.01, 0.6, (P, m)), np.abs(a * x0[:, None] - b * y0[:, None]) * 1.01 + 1e-6)
    xlo = x0 * rng.uniform(0, 1, P) * (rng.random(P) < 0.5)
    ylo = y0 * rng.uniform(0, 1, P) * (rng.random(P) < 0.5)
    xhi = np.where(rng.random(P) < 0.5, 1.0, x0 + (1 - x0) * rng.uniform(0, 1, P))
    yhi = np.where(rng.random(P) < 0.5, 1.0, y0 + (1 - y0) * rng.uniform(0, 1, P))
    x, y = solve_pairs(ti, tj, a, b, p, xlo, xhi, ylo, yhi, x0, y0)
    ours = ti / x + tj / y
    # ours is feasible ...
    jump = np.abs(a * x[:, None] - b * y[:, None]) - p
    assert jump.max() <= 1e-12 * (1 + p.max())
    assert np.all((x >= xlo - 1e-12) & (x <= xhi + 1e-12) & (y >= ylo - 1e-12) & (y <= yhi + 1e-12))
    # ... never worse than the start ...
    assert np.all(ours <= ti / x0 + tj / y0 + 1e-12)
    # ... and equal to a generic NLP solver's optimum
    rel = []
    for k in range(P):
        ref = _scipy_pair(ti[k], tj[k], a[k], b[k], p[k], xlo[k], xhi[k], ylo[k], yhi[k], x0[k], y0[k])
        rel.append((ours[k] - ref) / ref)
    rel = np.array(rel)
    assert rel.max() < 1e-7, f"scipy found a better point (rel {rel.max():.2e})"
    assert rel.min() > -1e-9, f"ours below scipy's optimum (rel {rel.min():.2e})"


def _program_blocks(delta: np.ndarray, t17: np.ndarray, cyclic: bool = True) -> Blocks:
    n, m = delta.shape
    q = np.vstack([np.zeros(m), np.cumsum(delta, axis=0)])
    return Blocks("synthetic", tuple("XYZABC"[:m]), np.arange(n + 1), q, delta, t17, t17.copy(),
                  np.ones(n), np.zeros(n), 0.1, cyclic, float(t17.sum()), float(t17.sum()))


def _synthetic_machine(m: int, p: float):
    axes = [{"name": "A", "role": "mandrel", "type": "rotary", "units": "deg", "max_speed": 1.0,
             "max_accel": 1.0, "max_jump": p}]
    for k, role in enumerate(["carriage", "cross", "vertical"][: m - 1]):
        axes.append({"name": "XYZ"[k], "role": role, "type": "linear", "units": "mm", "max_speed": 1.0,
                     "max_accel": 1.0, "max_jump": p})
    data = {"kind": "cartesian", "axes": axes}
    if m < 3:
        data["eye_radius"] = 100.0
    return parse_machine(data, "synthetic.toml")


def _scipy_program(v, t, p, cyclic, start=None):
    n, m = v.shape
    rows, ub = [], []
    pairs = [(i, (i + 1) % n) for i in range(n if cyclic else n - 1)]
    for i, j in pairs:
        for k in range(m):
            r = np.zeros(n)
            r[i], r[j] = v[i, k], -v[j, k]
            rows += [r, -r]
            ub += [p[k], p[k]]
    cons = LinearConstraint(np.array(rows), -np.inf, np.array(ub))
    starts = [np.full(n, 1e-3), np.full(n, 0.05)] + ([] if start is None else [np.asarray(start)])
    A, ub = np.array(rows), np.array(ub)

    def run(s, method, opts):
        r = minimize(lambda z: np.sum(t / z), s, jac=lambda z: -t / z ** 2, bounds=[(1e-6, 1)] * n,
                     constraints=[cons], method=method, options=opts)
        ok = np.all(A @ r.x <= ub + 1e-7) and np.all(r.x <= 1 + 1e-9)
        return float(np.sum(t / r.x)) if ok else np.inf

    res = [run(s, "SLSQP", {"ftol": 1e-15, "maxiter": 2000}) for s in starts]
    best = min(res)
    if start is not None and not np.isfinite(res[-1]):
        # SLSQP stopped a hair outside the polygon: a slower interior method from the same start
        best = min(best, run(starts[-1], "trust-constr", {"gtol": 1e-12}))
    return best


@pytest.mark.parametrize("method", ["pairwise", "global"])
@pytest.mark.parametrize("reversals", [False, True])
def test_program_optimum_vs_generic_nlp(reversals, method):
    rng = np.random.default_rng(7 + reversals)
    gaps = []
    for _ in range(30):
        n, m = int(rng.integers(3, 12)), 2
        delta = rng.uniform(0.05, 1.0, (n, m)) * rng.choice([1.0, 5.0], (n, 1))
        if reversals:
            delta *= rng.choice([-1.0, 1.0], (n, m))
        t17 = preliminary_times(delta, np.ones(m), 0.01)
        pj = float(rng.uniform(0.05, 0.5))
        mach = _synthetic_machine(m, pj)
        b = optimise_block_times(_program_blocks(delta, t17), mach, method=method)
        ref = _scipy_program(delta / t17[:, None], t17, np.full(m, pj), True, start=b.alpha)
        assert not check_blocks(mach, b)
        assert b.total >= b.total_t17 - 1e-12
        assert all(x >= y - 1e-12 for x, y in zip(b.history, b.history[1:]))
        assert b.total <= b.total_start + 1e-12
        gaps.append((b.total - ref) / ref)
    gaps = np.array(gaps)
    assert gaps.min() > -1e-6            # never better than the global optimum (it is feasible)
    if not reversals or method == "global":
        # the paper's class: pairwise minimisation is globally optimal; the global method always is
        assert gaps.max() < 1e-6
    else:
        # with axis reversals pairwise minimisation can stop short of the global optimum (a known
        # limit of the method, cf. the paper's restriction); measured here, documented in docs/machines.md
        assert np.median(gaps) < 0.05


@pytest.mark.parametrize("name", MACHINES)
def test_optimised_program_respects_speed_and_jump_limits(name):
    m, p, ap = _setup(name)
    b = optimise_block_times(make_blocks(m, ap, 0.05), m)
    assert b.violations == ()
    assert not check_blocks(m, b)
    spd = b.speed
    vmax = m.limits("max_speed")
    pj = m.limits("max_jump")
    assert np.all(np.abs(spd) <= vmax * (1 + 1e-9))
    jumps = np.abs(np.roll(spd, -1, axis=0) - spd)
    assert np.all(jumps <= pj * (1 + 1e-9))
    assert b.total >= b.total_t17 * (1 - 1e-12)
    assert b.total <= b.total_start * (1 + 1e-12)
    assert all(x >= y * (1 - 1e-12) for x, y in zip(b.history, b.history[1:]))
    assert np.all((b.alpha > 0) & (b.alpha <= 1))
    assert np.allclose(b.time, b.t17 / b.alpha)


@pytest.mark.parametrize("name", ["lathe2", "lathe4"])
def test_global_method_reaches_the_nlp_optimum_on_machine_programs(name):
    m, p, ap = _setup(name, n=3000, circuits=1)
    b0 = make_blocks(m, ap, 0.3)
    bp = optimise_block_times(b0, m, method="pairwise")
    bg = optimise_block_times(b0, m, method="global")
    t = np.asarray(b0.t17)
    ref = _scipy_program(b0.delta / t[:, None], t, m.limits("max_jump"), True, start=bg.alpha)
    assert bg.total == pytest.approx(ref, rel=1e-6)
    assert bg.total <= bp.total * (1 + 1e-12) and bg.total <= bg.total_start
    assert not bg.violations


def test_turnaround_reversal_pairs_use_lagrange_edges():
    """A carriage that reverses between two blocks: |v_i| a_i + |v_j| a_j <= p binds."""
    delta = np.array([[1.0, 1.0], [1.0, -1.0]] * 3)
    t17 = preliminary_times(delta, np.ones(2), 0.01)
    mach = _synthetic_machine(2, 0.5)
    b = optimise_block_times(_program_blocks(delta, t17), mach)
    ref = _scipy_program(delta / t17[:, None], t17, np.full(2, 0.5), True)
    assert b.total == pytest.approx(ref, rel=1e-6)
    # symmetric: every block at speed 0.25 so that the jump 0.25 - (-0.25) = 0.5 is exactly p
    assert np.allclose(np.abs(b.speed[:, 1]), 0.25)


def test_violations_located_by_axis_and_block():
    m, p, ap = _setup("lathe3")
    b = optimise_block_times(make_blocks(m, ap, 0.1), m)
    import tomllib
    from pathlib import Path

    with open(Path(__file__).resolve().parents[1] / "resources/machines/lathe3.toml", "rb") as fh:
        data = tomllib.load(fh)
    data["axes"][1]["max"] = 750.0            # carriage X
    data["axes"][0]["max_speed"] = 100.0      # mandrel A slower than the program runs
    tight = parse_machine(data, "tight.toml")
    vs = check_blocks(tight, b)
    pos = [v for v in vs if v.kind == "position" and v.axis == "X"]
    spd = [v for v in vs if v.kind == "speed" and v.axis == "A"]
    assert pos and spd
    first = int(np.flatnonzero(b.q[1:, 1] > 750.0)[0])
    assert pos[0].block == first
    assert pos[0].amount == pytest.approx(b.q[1:, 1][b.q[1:, 1] > 750].max() - 750.0, abs=1e-9) or \
        max(v.amount for v in pos) == pytest.approx(b.q[1:, 1].max() - 750.0, abs=1e-9)
    assert "block" in pos[0].message and "axis X" in pos[0].message
    # the writer's guard: a program with violations is not safe to write
    assert check_program(ap, b, tight)
    assert check_program(ap, b, m) == []


def test_bad_tolerance_and_mismatch():
    m, p, ap = _setup("lathe3", n=500, circuits=1)
    with pytest.raises(InputError, match="method"):
        optimise_block_times(make_blocks(m, ap, 0.1), m, method="simplex")
    with pytest.raises(InputError, match="tolerance"):
        make_blocks(m, ap, 0.0)
    with pytest.raises(InputError, match="axes"):
        make_blocks(load_machine("lathe4"), ap, 0.1)


def test_state_progress(state):
    m, p, ap = _setup("lathe4", n=2000, circuits=1)
    b = make_blocks(m, ap, 0.05, state=state)
    optimise_block_times(b, m, state=state)
    assert state.fractions and state.fractions[-1] <= 1.0


def test_blocks_of_repeated_circuits_are_computed_once() -> None:
    """Issue 16: from 8 circuits on (100 until 2026-11-29), the blocks of circuits 2 .. n-1 are circuit
    2's, replicated (the mandrel angle differs, the eye error does not see it).  Every block still holds
    the tolerance (measured independently on all points), every middle circuit has the same block
    pattern, and the program is no longer than the whole-path approximation's (within 0.5 %); so on
    the shipped vessel itself (74 circuits)."""
    from pathlib import Path

    from engine.job import load_job
    from engine.pipeline import _block_errors, _block_pieces, run_pipeline

    path = Path(__file__).resolve().parents[1] / "resources" / "examples" / "pressure_vessel.toml"
    job = load_job(path)
    job = job.replace(winding={**job.winding.model_dump(), "circuits": 110, "points_per_pass": 120},
                      payout={**job.payout.model_dump(), "grid_points": 200})
    res = run_pipeline(job, path, upto="axes")
    pieces = _block_pieces(res)
    assert pieces is not None and len(pieces) == 110
    rep = make_blocks(res.machine, res.axes, tol_mm=0.05, pieces=pieces)
    whole = make_blocks(res.machine, res.axes, tol_mm=0.05)
    idx = np.asarray(rep.index)
    from dataclasses import replace as dc_replace

    assert res.axes.circuits is not None          # replicated by engine.periodic: measure every point anyway
    err = _block_errors(res.machine, dc_replace(res.axes, circuits=None), idx)
    assert err.max() <= 0.05 * (1 + 1e-9)
    assert np.abs(err - rep.max_error).max() <= 1e-8
    a1, b1 = pieces[1]
    pat1 = idx[(idx >= a1) & (idx <= b1)] - a1
    for a, b in pieces[2:-1]:
        assert np.array_equal(idx[(idx >= a) & (idx <= b)] - a, pat1)
    assert rep.t17.sum() <= whole.t17.sum() * 1.005
    # the shipped vessel's polar layer (74 circuits at its own points per pass): replicated too, and as good
    ex = run_pipeline(load_job(path), path, upto="axes")
    pieces = _block_pieces(ex)
    assert pieces is not None and len(pieces) == ex.line.circuits == 74
    rep = make_blocks(ex.machine, ex.axes, tol_mm=0.05, pieces=pieces)
    whole = make_blocks(ex.machine, ex.axes, tol_mm=0.05)
    err = _block_errors(ex.machine, dc_replace(ex.axes, circuits=None), np.asarray(rep.index))
    assert err.max() <= 0.05 * (1 + 1e-9)
    assert rep.t17.sum() <= whole.t17.sum() * 1.005
    # below the threshold: approximated as a whole
    few = job.replace(winding={**job.winding.model_dump(), "circuits": 6})
    assert _block_pieces(run_pipeline(few, path, upto="axes")) is None


def test_time_metric_is_the_17_metric_bit_for_bit():
    from engine.blocks import time_metric

    rng = np.random.default_rng(2)
    q = np.cumsum(rng.normal(size=(5000, 4)), axis=0)
    fmax = np.array([1000.0, 20.0, 300.0, 7.5])
    ref = np.concatenate(([0.0], np.cumsum(np.max(np.abs(np.diff(q, axis=0)) / fmax, axis=1))))
    assert np.array_equal(time_metric(q, fmax), ref)
    assert np.array_equal(time_metric(q[:1], fmax), [0.0])


def _split_level_pointwise(machine, q, eye, w, P, breaks, seg_err, tol):  # noqa: ANN001, ANN202
    """The Douglas–Peucker level as it was written point by point (gathers per point, both branches of
    the time fraction, ``numpy.unique``, ``numpy.linalg.norm``): the reference for the per-segment form."""
    bpos = np.flatnonzero(breaks[P])
    active = np.stack([bpos[:-1], bpos[1:]], axis=1)
    while active.size:
        a, b = active[:, 0], active[:, 1]
        lengths = b - a - 1
        has = lengths > 0
        seg_err[P[a[~has]]] = 0.0
        a, b, lengths = a[has], b[has], lengths[has]
        if a.size == 0:
            break
        seg_id = np.repeat(np.arange(a.size), lengths)
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
        pos = np.arange(lengths.sum()) - np.repeat(starts - a - 1, lengths)
        pts = P[pos]
        pa, pb = P[a][seg_id], P[b][seg_id]
        span = w[pb] - w[pa]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(span > 0, (w[pts] - w[pa]) / np.where(span > 0, span, 1.0), (pts - pa) / (pb - pa))
        qa = q[pa]
        qi = qa + u[:, None] * (q[pb] - qa)
        e_fk, _ = forward_kinematics(machine, qi, fibre=False)
        err = np.linalg.norm(e_fk - eye[pts], axis=1)
        smax = np.maximum.reduceat(err, starts)
        ok = smax <= tol
        seg_err[P[a[ok]]] = smax[ok]
        bad = np.flatnonzero(~ok)
        if bad.size == 0:
            break
        cand = np.flatnonzero(err == smax[seg_id])
        uniq, first = np.unique(seg_id[cand], return_index=True)
        split_of = np.full(a.size, -1)
        split_of[uniq] = pos[cand[first]]
        split = split_of[bad]
        breaks[P[split]] = True
        active = np.concatenate([np.stack([a[bad], split], axis=1), np.stack([split, b[bad]], axis=1)])


@pytest.mark.parametrize("name", MACHINES)
def test_linear_approximation_per_segment_equals_point_by_point(name, monkeypatch):
    """The per-segment Douglas–Peucker (segment ends gathered once, repeated for their points) makes the
    same block ends and errors bit for bit as the point-by-point form, also where the path rests
    (no time-like progress over a segment: the time fraction falls back to the point count)."""
    import engine.blocks as blocks_mod
    from engine.blocks import time_metric

    m, p, ap = _setup(name, n=3000)
    q = np.asarray(ap.q, dtype=float)
    eye = np.asarray(ap.eye_xyz, dtype=float)
    rest = np.r_[np.arange(0, 700), np.full(40, 700), np.arange(700, q.shape[0])]   # 40 points at rest
    q, eye = q[rest], eye[rest]
    w = time_metric(q, m.limits("max_speed"))
    assert (np.diff(w) == 0).sum() >= 40
    for tol in (0.05, 0.01):
        got = blocks_mod._douglas_peucker(m, q, eye, w, tol, None)
        monkeypatch.setattr(blocks_mod, "_split_level", lambda *args: _split_level_pointwise(*args[:-1]))
        ref = blocks_mod._douglas_peucker(m, q, eye, w, tol, None)
        monkeypatch.undo()
        assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
        assert got[0].sum() > 2
    # a level whose first segment lies inside the rest (zero span of the time metric)
    n = q.shape[0]
    P = np.arange(n)
    out = []
    for level in (blocks_mod._split_level, None):
        breaks = np.zeros(n, dtype=bool)
        breaks[[0, 701, 739, n - 1]] = True
        seg_err = np.zeros(n)
        if level is None:
            _split_level_pointwise(m, q, eye, w, P, breaks, seg_err, 0.05)
        else:
            level(m, q, eye, w, P, breaks, seg_err, 0.05, None)
        out.append((breaks, seg_err))
    assert w[739] == w[701]
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("local_metric", [False, True])
def test_block_errors_per_block_gather_bit_for_bit(local_metric):
    """The time law's block errors (``_block_errors_of``) with the block ends gathered once per block
    equal the point-by-point formula q[a] + u·(q[b] − q[a]), ‖FK − eye‖ bit for bit."""
    from engine.pipeline import _block_errors_of

    m, p, ap = _setup("lathe4", n=3000)
    b = make_blocks(m, ap, 0.05)
    idx = np.asarray(b.index)
    chosen = np.arange(idx.size - 1)
    got = _block_errors_of(m, ap, idx, chosen, local_metric)
    if not local_metric:   # the reference: every block point by point
        from engine.blocks import time_metric

        q = np.asarray(ap.q, dtype=float)
        w = time_metric(q, m.limits("max_speed"))
        ref = np.zeros(idx.size - 1)
        for k in range(idx.size - 1):
            a, c = idx[k], idx[k + 1]
            pts = np.arange(a + 1, c + (k == idx.size - 2))
            if pts.size == 0:
                continue
            span = w[c] - w[a]
            u = (w[pts] - w[a]) / span if span > 0 else (pts - a) / (c - a)
            qi = q[a] + u[:, None] * (q[c] - q[a])
            e, _ = forward_kinematics(m, qi, fibre=False)
            ref[k] = np.linalg.norm(e - ap.eye_xyz[pts], axis=1).max()
        assert np.array_equal(got, ref)
    assert np.abs(got - b.max_error).max() <= 1e-8
