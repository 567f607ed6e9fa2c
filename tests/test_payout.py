"""Payout-eye path (7)–(10), geometric laws (11) and the min-range law (13)–(15).

Every check is against something independent: an analytic helix / great circle, a second root
finder, the nonlinear formulas evaluated directly, or SLSQP in the original variables l.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine.errors import Cancelled, InfeasibleError, InputError
from engine.job import PayoutSpec
from engine.mandrel import Mandrel
from engine.payout import (
    BoxWorkspace,
    ContactLine,
    _first_root,
    _grid,
    eye_path,
    geometric_law,
    min_range_law,
    parallel_free_length,
    reference_vessel_circuit,
)
from engine.state import RecordingState

A, LC, CC = 100.0, 300.0, 40.0  # vessel radius, cylinder length, Clairaut constant (mm)


@pytest.fixture(scope="module")
def vessel() -> Mandrel:
    return Mandrel.vessel(A, LC, "hemisphere", pole_radii=30.0)


@pytest.fixture(scope="module")
def circuit() -> ContactLine:
    return reference_vessel_circuit(A, LC, CC, 2400)


def helix(n: int = 200, radius: float = 75.0, beta: float = 0.9, length: float = 600.0) -> tuple[ContactLine, dict]:
    """A helix on a cylinder with its analytic tangent."""
    s = np.linspace(0.0, length, n)
    v = s * math.sin(beta) / radius
    z = s * math.cos(beta)
    line = ContactLine(z, np.full(n, radius), np.zeros(n), v, np.full(n, beta), np.ones(n), s)
    tau = np.column_stack([-np.sin(v) * math.sin(beta), np.cos(v) * math.sin(beta), np.full(n, math.cos(beta))])
    xyz = np.column_stack([radius * np.cos(v), radius * np.sin(v), z])
    return line, {"tau": tau, "xyz": xyz}


# ------------------------------------------------------------------------------------------------
# Geometry (7)–(10)
# ------------------------------------------------------------------------------------------------
def test_helix_eye_on_analytic_tangent_line() -> None:
    line, ref = helix()
    l = np.linspace(10.0, 300.0, line.z.size)
    eye = eye_path(line, l, k=1)
    assert np.abs(eye.contact_xyz - ref["xyz"]).max() < 1e-9
    # distance from the eye to the analytic tangent line through the contact point
    w = eye.eye_xyz - ref["xyz"]
    along = np.sum(w * ref["tau"], axis=1)
    off = np.linalg.norm(w - along[:, None] * ref["tau"], axis=1)
    assert off.max() < 1e-9
    assert np.abs(along - l).max() < 1e-9  # at the free length l, ahead in the travel direction
    # R from (10) equals the Euclidean distance from the axis; Z is the eye's z; V its polar angle
    assert np.abs(eye.R - np.hypot(eye.eye_xyz[:, 0], eye.eye_xyz[:, 1])).max() < 1e-9
    assert np.abs(eye.Z - eye.eye_xyz[:, 2]).max() < 1e-9
    d = 75.0 + 0.0 * l  # r' = 0: d = r
    assert np.abs(eye.V - (line.v + np.arccos(d / eye.R))).max() < 1e-9  # the seed's arccos form of (10)


def test_circuit_geometry_against_finite_differences(circuit: ContactLine) -> None:
    """τ from (9) equals the derivative of the contact curve; Clairaut r·sinβ = C on the analytic line."""
    line = circuit
    assert np.abs(line.r * np.sin(line.beta) - CC).max() < 1e-9
    l = 50.0 + 100.0 * np.abs(np.sin(line.s / 170.0))
    eye = eye_path(line, l, k=1)
    c = eye.contact_xyz
    ds = np.diff(line.s)
    fd = (c[2:] - c[:-2]) / (ds[1:] + ds[:-1])[:, None]  # central differences, O(h²)
    interior = slice(1, -1)
    err = np.linalg.norm(fd - eye.fibre_dir[interior], axis=1)
    assert np.median(err) < 1e-4 and err.max() < 5e-3  # h ≈ 1.3 mm; joints of curvature make the max larger
    w = eye.eye_xyz - c
    off = np.linalg.norm(w - np.sum(w * eye.fibre_dir, axis=1)[:, None] * eye.fibre_dir, axis=1)
    assert off.max() < 1e-9
    assert np.abs(np.linalg.norm(w, axis=1) - l).max() < 1e-9
    assert np.abs(eye.R - np.hypot(eye.eye_xyz[:, 0], eye.eye_xyz[:, 1])).max() < 1e-9
    # (10) in the seed's form wherever sin β > 0
    dr, beta = line.dr, line.beta
    d = line.r + line.direction * l * dr * np.cos(beta) / np.sqrt(1 + dr * dr)
    R10 = np.sqrt(d * d + (l * np.sin(beta)) ** 2)
    Z10 = line.z + line.direction * l * np.cos(beta) / np.sqrt(1 + dr * dr)
    assert np.abs(R10 - eye.R).max() < 1e-9 and np.abs(Z10 - eye.Z).max() < 1e-9
    dv = np.angle(np.exp(1j * (eye.V - line.v - np.arccos(np.clip(d / R10, -1, 1)))))
    assert np.abs(dv).max() < 1e-7


def test_mu_inverse_round_trip(circuit: ContactLine) -> None:
    geo = _grid(circuit, "s", None)
    rng = np.random.default_rng(1)
    l = rng.uniform(0.0, 500.0, geo.n)
    for k in (0, 1):
        back = geo.l_of_mu(geo.mu(l, k), k)
        assert np.abs(back - l).max() < 1e-8 * 500
    # β = 90° on a cone (b = 0, a = 0) and near it: the other branch of the closed-form inverse
    n = 50
    beta = np.linspace(math.pi / 2 - 1e-3, math.pi / 2, n)
    turn = ContactLine(np.zeros(n), np.full(n, 40.0), np.full(n, -0.7), np.linspace(0, 1, n), beta, np.ones(n),
                       np.linspace(0, 10, n))
    geo = _grid(turn, "s", None)
    l = np.linspace(0.0, 400.0, n)
    assert np.abs(geo.l_of_mu(geo.mu(l, 1), 1) - l).max() < 1e-7


def test_turnaround_is_regular(circuit: ContactLine) -> None:
    eye = eye_path(circuit, 120.0)
    assert np.isfinite(eye.eye_xyz).all() and np.isfinite(eye.V).all()
    assert (np.diff(eye.V) > -1e-12).all()  # constant l on a convex line: the eye never turns back


# ------------------------------------------------------------------------------------------------
# Geometric laws (11)
# ------------------------------------------------------------------------------------------------
def test_parallel_closed_form_matches_root_finder(circuit: ContactLine, vessel: Mandrel) -> None:
    geo = _grid(circuit, "s", 400)
    R0 = 150.0
    l_cf = parallel_free_length(geo, R0)
    l_rf = _first_root(geo, lambda Z, R: R - R0, 600.0, "parallel")
    assert np.abs(l_cf - l_rf).max() < 1e-7
    eye = geometric_law(circuit, vessel, "parallel", PayoutSpec(eye_radius_mm=R0, grid_points=400))
    assert np.abs(eye.R - R0).max() < 1e-9


def test_equidistant_and_equal_tangent(circuit: ContactLine, vessel: Mandrel) -> None:
    spec = PayoutSpec(grid_points=300, offset_mm=35.0)
    eq = geometric_law(circuit, vessel, "equidistant", spec)
    # independent distance: brute force to a dense sampling of the generatrix
    z, r = vessel.sample(20000)
    d = np.min(np.hypot(eq.Z[:, None] - z[None, :], eq.R[:, None] - r[None, :]), axis=1)
    assert np.abs(d - 35.0).max() < 2e-3
    et = geometric_law(circuit, vessel, "equal-tangent", spec)
    assert np.ptp(et.l) == 0.0
    assert et.report["constraints"]["clearance"]["ok"]
    assert abs(et.l[0] - et.l_min.max()) < 1e-12  # the smallest constant that clears everywhere


def test_curve_law_straight_line_equals_parallel(circuit: ContactLine, vessel: Mandrel) -> None:
    spec = PayoutSpec(grid_points=200, curve_zr_mm=[(-500.0, 140.0), (900.0, 140.0)], eye_radius_mm=140.0)
    cur = geometric_law(circuit, vessel, "curve", spec)
    par = geometric_law(circuit, vessel, "parallel", spec)
    assert np.abs(cur.l - par.l).max() < 1e-7
    spline = PayoutSpec(grid_points=200, curve_zr_mm=[(-500.0, 140.0), (0.0, 140.0), (300.0, 140.0), (900.0, 140.0)])
    assert np.abs(geometric_law(circuit, vessel, "curve", spline).R - 140.0).max() < 1e-7


def test_curve_law_input_errors(circuit: ContactLine, vessel: Mandrel) -> None:
    with pytest.raises(InputError, match="curve_zr_mm"):
        geometric_law(circuit, vessel, "curve", PayoutSpec(grid_points=100))
    with pytest.raises(InputError, match="increase"):
        geometric_law(circuit, vessel, "curve", PayoutSpec(grid_points=100, curve_zr_mm=[(0, 150), (0, 160)]))


# ------------------------------------------------------------------------------------------------
# Min-range law (13)–(15)
# ------------------------------------------------------------------------------------------------
def test_helix_min_range_is_constant_speed() -> None:
    """Mean u is 1 for any cyclic law (x = s), so max min u = min max u = 1 and l is constant."""
    line, _ = helix(n=300)
    pipe = Mandrel.pipe(75.0, 700.0)
    for k in (0, 1):
        eye = min_range_law(line, pipe, PayoutSpec(grid_points=300, impregnation_k=k))
        assert abs(eye.u_min - 1.0) < 1e-6 and abs(eye.u_max - 1.0) < 1e-6
        assert eye.report["jerk"] < 1e-9 and eye.feasible


@pytest.mark.parametrize("k", [0, 1])
def test_min_range_beats_geometric_laws(circuit: ContactLine, vessel: Mandrel, k: int) -> None:
    spec = PayoutSpec(grid_points=300, impregnation_k=k)
    mr = min_range_law(circuit, vessel, spec)
    rep = mr.report
    assert rep["feasible"], rep["constraints"]
    assert all(c["ok"] for c in rep["constraints"].values())
    # every constraint at every grid point, recomputed here from the arrays
    tol = 1e-6
    dx = np.diff(mr.x)
    assert (mr.l >= mr.l_min - tol).all() and (mr.l <= mr.l_max + tol).all()
    assert (np.diff(mr.s + mr.l) / dx >= -tol).all()
    assert (np.diff(mr.V) / dx >= -tol).all()
    assert abs(mr.l[0] - mr.l[-1]) < tol
    lam = mr.s + mr.l - k * mr.R
    assert np.abs(np.diff(lam) / dx - mr.u).max() < 1e-9
    for law in ("parallel", "equidistant", "equal-tangent"):
        g = geometric_law(circuit, vessel, law, spec)
        assert rep["u_range"] <= g.report["u_range"] + 1e-6, law
    # the band of (15) is the narrower of (13)-then-(14) and the direct min (u_max − u_min)
    sol = rep["solver"]
    lo, hi = sol["band_15"]
    assert rep["u_min"] >= lo - 1e-6 and rep["u_max"] <= hi + 1e-6
    assert rep["u_range"] <= sol["u_max_14"] - sol["u_min_13"] + 1e-6
    assert rep["u_range"] <= sol["range_lp"]["u_range"] + 1e-6


def _slsqp(line: ContactLine, vessel: Mandrel, k: int, n: int, eye) -> dict[str, float]:
    """(13), (14), (15) in the variables l with the exact nonlinear u, V, by SLSQP (independent of μ and HiGHS)."""
    from scipy.optimize import minimize

    geo = _grid(ContactLine.from_line(line), "s", n)
    assert np.array_equal(geo.x, eye.x)
    lo, hi = eye.l_min, eye.l_max
    dx = np.diff(geo.x)
    s = geo.line.s

    def u_of(l: np.ndarray) -> np.ndarray:
        return np.diff(s + l - k * geo.eye(l)[1]) / dx

    common = [
        {"type": "eq", "fun": lambda y: y[0] - y[n - 1]},
        {"type": "ineq", "fun": lambda y: np.diff(s + y[:n]) / dx},
        {"type": "ineq", "fun": lambda y: np.diff(geo.eye(y[:n])[2]) / dx},
    ]
    bounds = [*zip(lo, hi), (None, None)]
    opts = {"maxiter": 300, "ftol": 1e-13}
    out = {}

    def s13(y0: np.ndarray) -> float:
        r = minimize(lambda y: -y[-1], y0, method="SLSQP", bounds=bounds, options=opts,
                     constraints=[*common, {"type": "ineq", "fun": lambda y: u_of(y[:n]) - y[-1]}])
        return float(r.x[-1])

    mid = 0.5 * (lo + hi)
    mid[-1] = mid[0]
    out["13_mid"] = s13(np.append(mid, u_of(mid).min()))
    out["13_lp"] = s13(np.append(eye.l, eye.u.min()))
    t13 = eye.report["solver"]["u_min_13"]
    b_lo, b_hi = eye.report["solver"]["band_15"]
    r14 = minimize(lambda y: y[-1], np.append(eye.l, eye.u.max()), method="SLSQP", bounds=bounds, options=opts,
                   constraints=[*common, {"type": "ineq", "fun": lambda y: y[-1] - u_of(y[:n])},
                                {"type": "ineq", "fun": lambda y: u_of(y[:n]) - (t13 - 1e-7)}])
    out["14"] = float(r14.x[-1])
    U = (s[-1] - s[0]) / (geo.x[-1] - geo.x[0])
    r15 = minimize(lambda y: float(np.sum((u_of(y[:n]) - U) ** 2 * dx)), np.append(eye.l, 0.0), method="SLSQP",
                   bounds=bounds, options=opts,
                   constraints=[*common, {"type": "ineq", "fun": lambda y: b_hi - u_of(y[:n])},
                                {"type": "ineq", "fun": lambda y: u_of(y[:n]) - b_lo}])
    # the narrowest band: min T − t over (l, t, T)
    rr = minimize(lambda y: y[-1] - y[-2], np.append(eye.l, [eye.u.min(), eye.u.max()]), method="SLSQP",
                  bounds=[*zip(lo, hi), (None, None), (None, None)], options=opts,
                  constraints=[{"type": "eq", "fun": lambda y: y[0] - y[n - 1]},
                               {"type": "ineq", "fun": lambda y: np.diff(s + y[:n]) / dx},
                               {"type": "ineq", "fun": lambda y: np.diff(geo.eye(y[:n])[2]) / dx},
                               {"type": "ineq", "fun": lambda y: y[-1] - u_of(y[:n])},
                               {"type": "ineq", "fun": lambda y: u_of(y[:n]) - y[-2]},
                               {"type": "ineq", "fun": lambda y: y[-2]}])
    out["range"] = float(rr.x[-1] - rr.x[-2])
    out["15"] = float(r15.fun)
    return out


@pytest.mark.parametrize("k", [0, 1])
def test_lp_qp_agree_with_slsqp_in_l(circuit: ContactLine, vessel: Mandrel, k: int) -> None:
    n = 28
    eye = min_range_law(circuit, vessel, PayoutSpec(impregnation_k=k), grid_points=n, refine=False)
    sol = eye.report["solver"]
    ref = _slsqp(circuit, vessel, k, n, eye)
    tol = 1e-5
    assert ref["13_mid"] <= sol["u_min_13"] + tol  # no start does better than the LP (global for the LP)
    assert abs(ref["13_lp"] - sol["u_min_13"]) < tol  # and the LP point is a KKT point of the nonlinear problem
    assert abs(ref["14"] - sol["u_max_14"]) < tol
    assert abs(ref["15"] - eye.report["jerk"]) < 1e-4 * max(1.0, ref["15"])
    assert abs(ref["range"] - sol["range_lp"]["u_range"]) < tol


# ------------------------------------------------------------------------------------------------
# Infeasible set-ups, state
# ------------------------------------------------------------------------------------------------
def test_envelope_too_tight(circuit: ContactLine, vessel: Mandrel) -> None:
    with pytest.raises(InfeasibleError, match="clearance") as ei:
        min_range_law(circuit, vessel, PayoutSpec(grid_points=100, clearance_mm=60.0, free_length_max_mm=60.0))
    assert "z = " in str(ei.value) and "status" not in str(ei.value)


def test_workspace_too_small_for_dome(circuit: ContactLine, vessel: Mandrel) -> None:
    ws = BoxWorkspace(z_range=(-50.0, 350.0), r_range=(0.0, 400.0))
    with pytest.raises(InfeasibleError, match="workspace") as ei:
        min_range_law(circuit, vessel, PayoutSpec(grid_points=100), workspace=ws)
    assert "Z in [-50, 350]" in str(ei.value)
    spec = PayoutSpec(grid_points=100, workspace_z_mm=(-50.0, 350.0))
    with pytest.raises(InfeasibleError, match="workspace"):
        geometric_law(circuit, vessel, "equidistant", spec)


def test_u_min_too_high(circuit: ContactLine, vessel: Mandrel) -> None:
    with pytest.raises(InfeasibleError, match="u_min") as ei:
        min_range_law(circuit, vessel, PayoutSpec(grid_points=100, u_min=1.5))
    assert "best lower bound" in str(ei.value)


def test_progress_and_cancel(circuit: ContactLine, vessel: Mandrel, state: RecordingState) -> None:
    min_range_law(circuit, vessel, PayoutSpec(grid_points=80), state=state)
    assert state.fractions and state.fractions[-1] == 1.0 and state.fractions == sorted(state.fractions)
    with pytest.raises(Cancelled):
        min_range_law(circuit, vessel, PayoutSpec(grid_points=80), state=RecordingState(cancel_after=0))


def test_bad_line_is_input_error() -> None:
    line, _ = helix(n=10)
    bad = ContactLine(line.z, line.r, line.dr, line.v[::-1].copy(), line.beta, line.direction, line.s)
    with pytest.raises(InputError, match="twist angle v decreases"):
        eye_path(bad, 10.0)
