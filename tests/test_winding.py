"""Winding line (engine.winding): against closed forms, an independent discrete curvature, and
independent quadrature / ODE solutions (scipy)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from engine import winding_clairaut as wc
from engine.cli import main as cli_main
from engine.errors import Cancelled, InfeasibleError, InputError
from engine.job import WindingSpec, load_job
from engine.mandrel import Mandrel
from engine.winding import winding_line, winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]


def outgoing(wl, pid: int = 0):
    """Mask of pass ``pid`` without dwell points."""
    return (wl.pass_id == pid) & ~wl.dwell


def measured_ratio(mandrel: Mandrel, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """k_g / k_n of a polyline on the mandrel by divided differences in chord length (independent)."""
    h = np.linalg.norm(np.diff(P, axis=0), axis=1)
    hm, hp = h[:-1], h[1:]
    Pm, P0, Pp = P[:-2], P[1:-1], P[2:]
    d1 = (hm / (hp * (hp + hm)))[:, None] * (Pp - P0) + (hp / (hm * (hp + hm)))[:, None] * (P0 - Pm)
    d2 = 2.0 * ((Pp - P0) / hp[:, None] - (P0 - Pm) / hm[:, None]) / (hp + hm)[:, None]
    t = d1 / np.linalg.norm(d1, axis=1)[:, None]
    k = d2 - np.sum(d2 * t, axis=1)[:, None] * t
    z = P0[:, 2]
    v = np.arctan2(P0[:, 1], P0[:, 0])
    _, dr, _ = mandrel.evaluate(z)
    n = np.column_stack([np.cos(v), np.sin(v), -dr]) / np.sqrt(1 + dr**2)[:, None]
    kn = -np.sum(k * n, axis=1)
    kg = np.sum(k * np.cross(t, n), axis=1)
    return z, kg / kn


def away_from_joints(mandrel: Mandrel, z: np.ndarray, gap: float = 1.0) -> np.ndarray:
    ok = np.ones(len(z), dtype=bool)
    for s in mandrel.segments[1:]:
        ok &= np.abs(z - s.z0) > gap
    return ok


# ------------------------------------------------------------------------------------------------
# Geodesics against closed forms
# ------------------------------------------------------------------------------------------------
def test_cylinder_geodesic_is_helix() -> None:
    R, beta = 75.0, math.radians(55.0)
    m = Mandrel.pipe(R, 1000.0)
    spec = WindingSpec(mode="geodesic", angles=[{"z_mm": 500.0, "angle_deg": 55.0}], points_per_pass=2000)
    wl = winding_line(m, 10.0, 0.15, spec)
    sel = outgoing(wl)
    z, v = wl.z[sel], wl.v[sel]
    assert np.max(np.abs(v - z * math.tan(beta) / R)) < 1e-9
    assert np.allclose(wl.beta[sel], beta, atol=1e-12)
    assert wl.end_kinds == ("open", "open")
    # the return pass is the mirror helix
    sel1 = outgoing(wl, 1)
    off = wl.v[sel1] - (1000.0 - wl.z[sel1]) * math.tan(beta) / R
    assert np.ptp(off) < 1e-9
    # the return pass starts at the end of the dwell (its first point carries the line's labels)
    first = int(np.flatnonzero(sel1)[0])
    assert wl.dwell[first - 1] and wl.z[first] == 1000.0 and wl.beta[first] == pytest.approx(beta, abs=1e-12)
    assert off[0] == pytest.approx(wl.v[sel][-1] + wl.dwell_rad[1], abs=1e-9)


@pytest.mark.parametrize("poles", [0.0, 30.0])
def test_sphere_geodesic_is_great_circle(poles: float) -> None:
    R = 100.0
    m = Mandrel.vessel(R, 0.0, "hemisphere", poles)
    wl = winding_line(m, 10.0, 0.2, WindingSpec(points_per_pass=2000))
    assert wl.mode == "geodesic"
    for pid in (0, 1):
        P = wl.xyz[outgoing(wl, pid)]
        _, _, vt = np.linalg.svd(P)  # plane through the centre (the origin)
        nrm = vt[-1]
        assert np.max(np.abs(P @ nrm)) < 1e-9
        assert np.allclose(np.linalg.norm(P, axis=1), R, atol=1e-9)
    # the turnaround parallel is where r = C = pole + b/2
    assert wl.C[0] == pytest.approx(poles + 5.0, abs=1e-9)
    assert wl.r[0] == pytest.approx(wl.C[0], abs=1e-9)


def test_cone_geodesic_closed_form() -> None:
    r0, r1, L, b = 30.0, 80.0, 200.0, 10.0
    m = Mandrel.cone(r0, r1, L)
    wl = winding_line(m, b, 0.2, WindingSpec(points_per_pass=2000))
    assert wl.mode == "geodesic" and wl.end_kinds == ("turn", "open")
    C = r0 + b / 2
    k = (r1 - r0) / L
    sin_a = k / math.sqrt(1 + k * k)
    sel = outgoing(wl)
    z, v = wl.z[sel], wl.v[sel]
    r = r0 + k * z
    v_exact = np.arccos(np.clip(C / r, -1, 1)) / sin_a  # straight line in the developed cone
    assert np.max(np.abs(v - v_exact)) < 1e-8
    assert np.allclose(wl.beta[sel], np.arcsin(np.clip(C / r, 0, 1)), atol=1e-6)


def test_twist_matches_independent_quadrature() -> None:
    """v over a pass = ∫ C√(1+r'²)/(r√(r²−C²)) dz by QUADPACK, the end singularities removed by
    z = z_end ± u² (a different substitution from the engine's)."""
    m = Mandrel.vessel(100.0, 300.0, "ellipse", 30.0, dome_ratio=0.6)
    wl = winding_line(m, 8.0, 0.2, WindingSpec(points_per_pass=2000))
    assert wl.mode == "geodesic" and wl.max_abs_lambda == 0.0
    C = float(wl.C[0])
    za, zb = wl.z_turn

    def g(z: float) -> tuple[float, float, float]:
        r, dr, _ = (float(x[0]) for x in m.evaluate(np.array([z])))
        return C * math.sqrt(1 + dr * dr) / (r * math.sqrt(r + C)), r, dr

    def end_part(z_end: float, z_joint: float, sign: float) -> float:
        def f(u: float) -> float:
            z = z_end + sign * u * u
            gz, r, dr = g(z)
            lin = abs(dr) if u == 0.0 else (r - C) / (u * u)  # (r − C)/u² -> |r'| at the turnaround
            return gz * 2.0 / math.sqrt(lin)

        return quad(f, 0.0, math.sqrt(abs(z_joint - z_end)), epsabs=1e-13, epsrel=1e-13, limit=200)[0]

    total = end_part(za, 0.0, 1.0) + quad(lambda z: g(z)[0] / math.sqrt(100.0 - C), 0.0, 300.0)[0] + end_part(
        zb, 300.0, -1.0)
    sel = outgoing(wl)
    assert wl.v[sel][-1] == pytest.approx(total, abs=1e-9)


# ------------------------------------------------------------------------------------------------
# Non-geodesic lines
# ------------------------------------------------------------------------------------------------
def test_constant_lambda_ratio_and_boundary_conditions() -> None:
    m = Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0))
    errs = []
    for n in (1000, 2000):
        wl = winding_line(m, 8.0, 0.2, WindingSpec(mode="constant-lambda", points_per_pass=n))
        lam = wl.lambda_
        assert isinstance(lam, float) and 0.01 < lam < 0.2
        sel = outgoing(wl)
        # (4): tangential at both turnarounds, C = r (pole + b/2)
        assert abs(wl.C[sel][0] - wl.r[sel][0]) < 1e-9 and abs(wl.C[sel][-1] - wl.r[sel][-1]) < 1e-9
        assert wl.r[sel][0] == pytest.approx(29.0, abs=1e-9) and wl.r[sel][-1] == pytest.approx(44.0, abs=1e-9)
        worst = 0.0
        for pid in (0, 1):
            z, ratio = measured_ratio(m, wl.xyz[outgoing(wl, pid)])
            ok = away_from_joints(m, z)
            worst = max(worst, float(np.max(np.abs(ratio[ok] - lam))))
        errs.append(worst)
    assert errs[1] < 1e-4
    assert errs[1] < errs[0] / 3.0  # converges with refinement (second order)


def test_constant_lambda_matches_independent_ode_solution() -> None:
    """C(z) from shooting agrees with scipy's DOP853 solution of (3) for the λ found."""
    m = Mandrel.vessel(80.0, 150.0, "hemisphere", (15.0, 30.0))
    wl = winding_line(m, 6.0, 0.3, WindingSpec(mode="constant-lambda", points_per_pass=2000))
    lam = float(wl.lambda_)
    sel = outgoing(wl)
    z, C = wl.z[sel], wl.C[sel]

    def rhs(zz: float, c: np.ndarray) -> list[float]:
        r, dr, d2r = (x[0] for x in m.evaluate(np.array([zz])))
        return [lam * ((1 + dr * dr) * c[0] ** 2 - r * d2r * (r * r - c[0] ** 2)) / (r * r * (1 + dr * dr))]

    edges = [z[0]] + [s.z0 for s in m.segments[1:] if z[0] < s.z0 < z[-1]] + [z[-1]]
    c0 = C[0]
    for a, b in zip(edges[:-1], edges[1:]):
        mask = (z >= a) & (z <= b)
        sol = solve_ivp(rhs, (a, b), [c0], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=z[mask])
        assert np.max(np.abs(sol.y[0] - C[mask])) < 1e-7
        c0 = sol.y[0][-1]
    assert abs(c0 - wl.r[sel][-1]) < 1e-7  # the independent solution also lands on the right BC


def test_piecewise_lambda_meets_required_angles() -> None:
    m = Mandrel.vessel(100.0, 300.0, "hemisphere", (20.0, 35.0))
    spec = WindingSpec(angles=[{"z_mm": 150.0, "angle_deg": 25.0}], points_per_pass=2000)
    wl = winding_line(m, 6.0, 0.3, spec)
    assert wl.mode == "piecewise-lambda"
    pieces = wl.lambda_
    assert isinstance(pieces, list) and len(pieces) == 2
    sel = outgoing(wl)
    i = int(np.argmin(np.abs(wl.z[sel] - 150.0)))
    assert wl.z[sel][i] == pytest.approx(150.0, abs=1e-12)
    assert math.degrees(wl.beta[sel][i]) == pytest.approx(25.0, abs=1e-9)
    z, ratio = measured_ratio(m, wl.xyz[sel])
    for p in pieces:
        ok = away_from_joints(m, z) & (z > p["z_from"] + 1.0) & (z < p["z_to"] - 1.0)
        assert np.max(np.abs(ratio[ok] - p["lambda"])) < 1e-4


# ------------------------------------------------------------------------------------------------
# Concave generatrix: minimax (5)-(6)
# ------------------------------------------------------------------------------------------------
def bracket6(m: Mandrel, z: np.ndarray, C: np.ndarray) -> np.ndarray:
    """(1 + r'²)C² − r r''(r² − C²): >= 0 means the band lies on the surface (6)."""
    r, dr, d2r = m.evaluate(z)
    return (1 + dr * dr) * C * C - r * d2r * (r * r - C * C)


def test_bottle_example_minimax() -> None:
    job = load_job(ROOT / "resources/examples/bottle.toml")
    wl = winding_line_for_job(job)
    assert wl.mode == "minimax" and wl.ok
    sel = outgoing(wl)
    assert np.all(bracket6(Mandrel.bottle(), wl.z[sel], wl.C[sel]) >= -1e-9)
    assert np.all(wl.C[sel] <= wl.r[sel] + 1e-12)


def test_minimax_tube_on_waisted_bottle_satisfies_6_and_beats_constant_lambda() -> None:
    m = Mandrel.bottle(waist_radius=30.0, neck_radius=36.0, bottom_pole_radius=10.0)
    wl = winding_line(m, 5.0, 0.3, WindingSpec(pole_c_mm=(12.5, 29.0)))
    assert wl.mode == "minimax" and wl.end_kinds == ("turn", "open")
    assert any("direct search" in n for n in wl.notes)  # the constant-λ line violates (6) here
    sel = outgoing(wl)
    z, C, r = wl.z[sel], wl.C[sel], wl.r[sel]
    assert np.all(bracket6(m, z, C) >= -1e-9)
    assert np.all(C[1:-1] < r[1:-1]) and np.all(C >= 0)
    assert abs(C[0] - r[0]) < 1e-9 and abs(C[-1] - 29.0) < 1e-9  # both boundary conditions
    # a denser independent check of (6) between the points (C interpolated by a cubic spline)
    from scipy.interpolate import CubicSpline

    zz = np.linspace(z[0], z[-1], 40001)
    assert np.all(bracket6(m, zz, CubicSpline(z, C)(zz)) >= 0.0)
    # the (only) constant-λ line through both conditions violates (6): it is returned with the
    # bridging zone reported, never silently
    wl_c = winding_line(m, 5.0, 0.3, WindingSpec(mode="constant-lambda", pole_c_mm=(12.5, 29.0)))
    assert wl_c.bridging and not wl_c.ok
    assert wl.max_abs_lambda < 0.3 and wl.ok


def test_minimax_free_end_vs_brute_force_constant_lambda_scan() -> None:
    """Left turnaround fixed, right end free: no constant-λ line satisfying (6) has smaller |λ|."""
    m = Mandrel.bottle(waist_radius=30.0, neck_radius=36.0, bottom_pole_radius=10.0)
    C0 = 12.5
    from engine.winding import _crossing

    za = _crossing(m, C0, m.z_min, m.z_max)
    grid = wc.build_grid(m, za, m.z_max, wc.TURN, wc.OPEN, 2000, 1, [])
    rn, _, _ = wc.node_geometry(grid)
    hi = rn.copy()
    hi[1:-1] *= 1 - 1e-9
    lam_star, tb = wc.minimax_search(grid, wc.lower_bound(grid), hi, {0: float(rn[0])}, 0.0)
    C, lam = wc.tube_path(grid, tb, lam_star)
    assert np.all(bracket6(m, grid.z, C) >= -1e-9)
    assert np.max(np.abs(lam)) <= lam_star * (1 + 1e-6)

    # brute force with an independent integrator (DOP853 in z): scan λ upwards from 0 in steps of 0.005
    def feasible(lam_c: float) -> bool:
        def rhs(zz: float, c: np.ndarray) -> list[float]:
            r, dr, d2r = (x[0] for x in m.evaluate(np.array([zz])))
            return [lam_c * ((1 + dr * dr) * c[0] ** 2 - r * d2r * (r * r - c[0] ** 2)) / (r * r * (1 + dr * dr))]

        zs = np.linspace(za, m.z_max, 3001)
        sol = solve_ivp(rhs, (za, m.z_max), [C0], method="DOP853", rtol=1e-9, atol=1e-9, t_eval=zs)
        if not sol.success:
            return False
        c = sol.y[0]
        r = m.r(zs)
        return bool(np.all(bracket6(m, zs, c) >= 0) and np.all(c[1:] < r[1:]))

    assert not feasible(0.0) and not feasible(-0.05)  # the geodesic (and λ < 0) bridges: a search is needed
    first = next((x for x in np.arange(0.005, 0.4, 0.005) if feasible(float(x))), None)
    assert first is not None, "the scan found no constant-λ line that keeps the band on the surface"
    assert lam_star <= first + 1e-9
    assert not feasible(lam_star * 0.97)  # and the search is not far below what constant λ achieves


def test_impossible_waist_is_reported_not_returned() -> None:
    m = Mandrel.bottle()  # waist 18 mm < the no-bridging bound 18.8 mm in the shoulder
    with pytest.raises(InfeasibleError):
        winding_line(m, 5.0, 0.3, WindingSpec(pole_c_mm=(17.5, 22.0)))


# ------------------------------------------------------------------------------------------------
# Friction, pattern, circuits
# ------------------------------------------------------------------------------------------------
def test_slip_is_reported_with_z_range() -> None:
    m = Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0))
    wl = winding_line(m, 8.0, 0.03, WindingSpec(points_per_pass=500))
    assert not wl.ok and wl.slips
    lo, hi = wl.slips[0]
    assert lo == pytest.approx(wl.z_turn[0]) and hi == pytest.approx(wl.z_turn[1])
    assert wl.max_abs_lambda > 0.03


def test_pattern_closure_and_rotation() -> None:
    m = Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0))
    wl = winding_line(m, 8.0, 0.2, WindingSpec(points_per_pass=300, layers=2))
    p, q = wl.pattern_p, wl.pattern_q
    assert math.gcd(p, q) == 1 and wl.circuits == 2 * p
    frac = wl.twist_per_circuit_rad / (2 * math.pi)
    assert frac - math.floor(frac) == pytest.approx(q / p, abs=1e-12)
    assert wl.coverage["fraction"] >= 1.0
    assert sorted(wl.circuit_order) == list(range(p))
    assert np.all(np.diff(wl.v) >= -1e-12)
    # after p circuits the line is back at its start point
    end = wl.circuit_slice(p - 1).stop - 1
    assert np.allclose(wl.xyz[end], wl.xyz[0], atol=1e-9)
    # circuit k is circuit 0 turned by k·Δv
    k = 5
    a, b = wl.xyz[wl.circuit_slice(0)], wl.xyz[wl.circuit_slice(k)]
    ang = k * wl.twist_per_circuit_rad
    rot = np.array([[math.cos(ang), -math.sin(ang), 0], [math.sin(ang), math.cos(ang), 0], [0, 0, 1]])
    assert np.allclose(a @ rot.T, b, atol=1e-9)
    one = wl.one_circuit
    assert one.circuits == 1 and len(one.z) == wl.points_per_circuit + 1
    # tangent: unit, on the surface, along the polyline
    assert np.allclose(np.linalg.norm(wl.tau, axis=1), 1.0)
    assert np.max(np.abs(np.sum(wl.tau * wl.normal, axis=1))) < 1e-12
    sel = outgoing(one)
    d = np.diff(one.xyz[sel], axis=0)
    d /= np.linalg.norm(d, axis=1)[:, None]
    mid = 0.5 * (one.tau[sel][1:] + one.tau[sel][:-1])
    mid /= np.linalg.norm(mid, axis=1)[:, None]
    assert np.min(np.sum(d * mid, axis=1)) > 0.999
    assert np.all(np.diff(one.s) >= 0)


def test_lagging_and_user_pattern() -> None:
    m = Mandrel.pipe(50.0, 400.0)
    base = {"angles": [{"z_mm": 200.0, "angle_deg": 45.0}], "points_per_pass": 200, "dwell_deg": (90.0, 90.0)}
    wl = winding_line(m, 12.0, 0.2, WindingSpec(**base, lead="lagging"))
    assert wl.lead == "lagging"
    wl2 = winding_line(m, 12.0, 0.2, WindingSpec(**base, pattern_p=31, pattern_q=7))
    assert (wl2.pattern_p, wl2.pattern_q) == (31, 7)
    assert wl2.dwell_rad[0] >= math.radians(90.0)
    with pytest.raises(InputError, match="coprime"):
        winding_line(m, 12.0, 0.2, WindingSpec(**base, pattern_p=30, pattern_q=6))


def test_close_by_angle_changes_the_helix_angle() -> None:
    m = Mandrel.pipe(50.0, 400.0)
    spec = WindingSpec(angles=[{"z_mm": 200.0, "angle_deg": 45.0}], points_per_pass=200, dwell_deg=(90.0, 90.0),
                       mode="geodesic", close_by="angle")
    wl = winding_line(m, 12.0, 0.2, spec)
    frac = wl.twist_per_circuit_rad / (2 * math.pi)
    assert frac - math.floor(frac) == pytest.approx(wl.pattern_q / wl.pattern_p, abs=1e-12)
    sel = outgoing(wl)
    assert 2 * wl.v[sel][-1] + sum(wl.dwell_rad) == pytest.approx(wl.twist_per_circuit_rad, abs=1e-9)
    assert wl.dwell_rad == pytest.approx((math.pi / 2, math.pi / 2))
    assert abs(math.degrees(wl.beta[sel][0]) - 45.0) < 5.0


# ------------------------------------------------------------------------------------------------
# Bad input
# ------------------------------------------------------------------------------------------------
def test_bad_inputs_raise_clear_errors() -> None:
    pipe = Mandrel.pipe(75.0, 1000.0)
    with pytest.raises(InputError, match="80"):
        winding_line(pipe, 10.0, 0.2, WindingSpec(pole_c_mm=(80.0, 80.0)))
    vessel = Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0))
    with pytest.raises(InputError, match="μ = 0"):
        winding_line(vessel, 8.0, 0.0, WindingSpec())
    with pytest.raises(InputError, match="1200"):
        winding_line(pipe, 10.0, 0.2, WindingSpec(angles=[{"z_mm": 1200.0, "angle_deg": 40.0}]))
    with pytest.raises(InputError, match="cannot be reached"):
        winding_line(pipe, 10.0, 0.2, WindingSpec(mode="geodesic", angles=[
            {"z_mm": 100.0, "angle_deg": 40.0}, {"z_mm": 800.0, "angle_deg": 50.0}]))
    with pytest.raises(InputError, match="wider than"):
        winding_line(vessel, 700.0, 0.2, WindingSpec())
    with pytest.raises(InputError, match="not determined"):
        winding_line(pipe, 10.0, 0.2, WindingSpec())
    # a geodesic through the poles of a closed sphere works even with μ = 0; the pattern closed by a dwell on
    # the turnaround parallel (no boss at a closed pole; every great circle twists π) slips there, reported
    sphere = Mandrel.vessel(50.0, 0.0)
    wl = winding_line(sphere, 4.0, 0.0, WindingSpec(points_per_pass=100))
    assert wl.lambda_ == 0.0 and not wl.ok
    assert [t["dwell_on"] for t in wl.turnarounds if t["dwell_deg"] > 0] == ["turnaround parallel"] * 2
    assert all(a == b and abs(a) == pytest.approx(math.sqrt(50.0**2 - 4.0)) for a, b in wl.slips)


def test_job_errors_name_the_field(tmp_path: Path) -> None:
    text = (ROOT / "resources/examples/pressure_vessel.toml").read_text().replace("friction = 0.2", "friction = 0.0")
    p = tmp_path / "v.toml"
    p.write_text(text)
    with pytest.raises(InputError) as ei:
        winding_line_for_job(load_job(p), p)
    assert ei.value.location.field == "band.friction"
    assert ei.value.location.file == str(p) and ei.value.location.line is not None
    assert "0.06" in ei.value.message


# ------------------------------------------------------------------------------------------------
# State, CLI
# ------------------------------------------------------------------------------------------------
def test_state_progress_and_cancel(state) -> None:
    m = Mandrel.vessel(100.0, 300.0, "hemisphere", 30.0)
    winding_line(m, 8.0, 0.2, WindingSpec(points_per_pass=200), state=state)
    assert state.fractions[0] == 0.0 and state.fractions[-1] == 1.0
    from engine.state import RecordingState

    with pytest.raises(Cancelled):
        winding_line(m, 8.0, 0.2, WindingSpec(points_per_pass=200), state=RecordingState(cancel_after=0))


def test_cli_json_and_csv(tmp_path: Path, capsys) -> None:
    out = tmp_path / "line.csv"
    job = ROOT / "resources/examples/pressure_vessel.toml"
    rc = cli_main(["trajectory", str(job), "--json", "--csv", str(out), "--one-circuit"])
    assert rc == 0
    rep = json.loads(capsys.readouterr().out)
    for key in ("lambda", "max_abs_lambda", "mu", "slips", "circuits", "pattern_p", "pattern_q",
                "twist_per_circuit_rad", "coverage"):
        assert key in rep
    head = out.read_text().splitlines()
    assert head[0] == "z,r,v,beta,C,lambda,x,y,zz"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[1] == 9 and np.allclose(np.hypot(data[:, 6], data[:, 7]), data[:, 1])


def test_cli_reports_slip_with_exit_code_1_and_bad_input_with_2(tmp_path: Path, capsys) -> None:
    text = (ROOT / "resources/examples/pressure_vessel.toml").read_text().replace("friction = 0.2", "friction = 0.01")
    p = tmp_path / "slip.toml"
    p.write_text(text)
    assert cli_main(["trajectory", str(p)]) == 1
    assert "SLIPS" in capsys.readouterr().out
    p.write_text(text.replace("friction = 0.01", "friction = 0.0"))
    assert cli_main(["trajectory", str(p), "--json"]) == 2
    assert "band.friction" in capsys.readouterr().err


def test_cli_subprocess() -> None:
    exe = Path(sys.executable).parent / "winder"
    res = subprocess.run([str(exe), "trajectory", str(ROOT / "resources/examples/pipe.toml"), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)
    assert rep["mode"] == "geodesic" and rep["max_abs_lambda"] == 0.0


def test_minimax_solves_each_interval_between_conditions_on_its_own() -> None:
    m = Mandrel.bottle(waist_radius=30.0, neck_radius=36.0, bottom_pole_radius=10.0)
    spec = WindingSpec(pole_c_mm=(12.5, 29.0), angles=[{"z_mm": 80.0, "angle_deg": 15.0}])
    wl = winding_line(m, 5.0, 0.3, spec)
    nat = winding_line(m, 5.0, 0.3, WindingSpec(mode="piecewise-lambda", pole_c_mm=(12.5, 29.0),
                                                 angles=[{"z_mm": 80.0, "angle_deg": 15.0}]))
    assert nat.bridging  # the natural piecewise line bridges in the shoulder
    pieces = wl.lambda_
    assert isinstance(pieces, list)
    # the first interval keeps its constant λ (it was feasible), the search runs on the second only
    assert pieces[0]["z_from"] == pytest.approx(wl.z_turn[0]) and pieces[0]["z_to"] == pytest.approx(80.0)
    assert pieces[0]["lambda"] == pytest.approx(nat.lambda_[0]["lambda"], rel=1e-9)
    sel = outgoing(wl)
    assert np.all(bracket6(m, wl.z[sel], wl.C[sel]) >= -1e-9) and not wl.bridging
    i = int(np.argmin(np.abs(wl.z[sel] - 80.0)))
    assert math.degrees(wl.beta[sel][i]) == pytest.approx(15.0, abs=1e-9)


def test_job_angle_error_names_field_and_line(tmp_path: Path) -> None:
    text = (ROOT / "resources/examples/pipe.toml").read_text().replace("z_mm = 500.0", "z_mm = 1500.0")
    p = tmp_path / "pipe.toml"
    p.write_text(text)
    with pytest.raises(InputError) as ei:
        winding_line_for_job(load_job(p), p)
    loc = ei.value.location
    assert loc.field == "winding.angles[0].z_mm" and "1500" in ei.value.message
    assert loc.line is not None and "z_mm = 1500.0" in text.splitlines()[loc.line - 1]


@pytest.mark.parametrize("case", ["vessel", "bottle-bridging"])
def test_close_by_angle_checks_bridging_of_the_kept_pass_only(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pattern-closing root search solves a pass for every constant it tries and keeps one: only the kept
    pass is checked for bridging (6).  The kept pass (every array, the bridging zones, the notes) equals the
    pass solved afresh, checked, at its constant - on a vessel (no bridging) and on a bottle whose closed
    geodesic bridges the shoulder (zones reported); one bridging check instead of one per tried constant."""
    import dataclasses

    import engine.winding as w

    if case == "vessel":
        m = Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0))
        spec = WindingSpec(angles=[{"z_mm": 150.0, "angle_deg": 35.0}], mode="geodesic", close_by="angle",
                           points_per_pass=300)
    else:
        m = Mandrel.bottle()
        spec = WindingSpec(angles=[{"z_mm": 60.0, "angle_deg": 12.0}], mode="geodesic", close_by="angle",
                           points_per_pass=300)
    calls: list[int] = []
    orig = w._bridging

    def counted(*a, **k):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        return orig(*a, **k)

    kept: list = []
    close = w._close_by_angle

    def capture(mandrel, b, spec_, ctx, pl, dwell, p, notes):  # noqa: ANN001, ANN202
        out = close(mandrel, b, spec_, ctx, pl, dwell, p, notes)
        kept.append((out[0], b, ctx))
        return out

    monkeypatch.setattr(w, "_bridging", counted)
    monkeypatch.setattr(w, "_close_by_angle", capture)
    line = winding_line(m, 5.0, 0.3, spec)
    assert len(calls) == 2                               # the first pass (c0) and the kept one
    new, b, ctx = kept[0]
    calls.clear()
    ref = w.solve_pass(m, b, spec, ctx, None, c_override=float(new.C[0]))
    assert len(calls) == 1
    assert bool(ref.bridging) == (case != "vessel") and bool(line.bridging) == (case != "vessel")
    assert new.bridging == ref.bridging and new.notes == ref.notes
    for f in dataclasses.fields(ref):
        a, r = getattr(new, f.name), getattr(ref, f.name)
        if isinstance(r, np.ndarray):
            assert a.tobytes() == r.tobytes(), f.name
