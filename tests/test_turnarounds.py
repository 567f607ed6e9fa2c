"""Honest turnarounds (issue 17 point 3): where a dwell lies, its k_g/k_n, slip reports, labels."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from engine.job import WindingSpec, build_mandrel, load_job
from engine.mandrel import Mandrel
from engine.winding import WindingLine, winding_line

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"


def ratio_at(Pm: np.ndarray, P0: np.ndarray, Pp: np.ndarray, n: np.ndarray) -> np.ndarray:
    """k_g / k_n at P0 from its neighbours by divided differences (independent of the λ labels)."""
    hm = np.linalg.norm(P0 - Pm, axis=1)
    hp = np.linalg.norm(Pp - P0, axis=1)
    d1 = (hm / (hp * (hp + hm)))[:, None] * (Pp - P0) + (hp / (hm * (hp + hm)))[:, None] * (P0 - Pm)
    d2 = 2.0 * ((Pp - P0) / hp[:, None] - (P0 - Pm) / hm[:, None]) / (hp + hm)[:, None]
    t = d1 / np.linalg.norm(d1, axis=1)[:, None]
    k = d2 - np.sum(d2 * t, axis=1)[:, None] * t
    return np.sum(k * np.cross(t, n), axis=1) / -np.sum(k * n, axis=1)


def measured_ratio(P: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """k_g / k_n at the interior points of a polyline."""
    return ratio_at(P[:-2], P[1:-1], P[2:], normal[1:-1])


def _dwell_interior(wl: WindingLine) -> np.ndarray:
    """Indices of dwell points whose both neighbours lie on the same parallel (same z and r)."""
    i = np.flatnonzero(wl.dwell[1:-1]) + 1
    same = (wl.z[i - 1] == wl.z[i]) & (wl.z[i + 1] == wl.z[i]) & (wl.r[i - 1] == wl.r[i]) & (wl.r[i + 1] == wl.r[i])
    return i[same]


def _check_dwell_ratio(wl: WindingLine) -> None:
    i = _dwell_interior(wl)
    assert i.size > 0
    got = ratio_at(wl.xyz[i - 1], wl.xyz[i], wl.xyz[i + 1], wl.normal[i])
    assert np.abs(got - wl.lam[i]).max() < 1e-9


def _check_labels(wl: WindingLine) -> None:
    """Every pass starts with the line's labels, never a dwell's (with or without a dwell)."""
    starts = np.flatnonzero(np.diff(wl.pass_id) != 0) + 1
    assert not wl.dwell[starts].any()
    dirs = np.where(wl.pass_id[starts] % 2 == 0, 1, -1)
    assert (wl.direction[starts] == dirs).all()
    one = wl.one_circuit
    sel = (one.pass_id == 0) & ~one.dwell
    z0, b0 = one.z[sel], one.beta[sel]
    for k in starts:
        j = int(np.argmin(np.abs(z0 - wl.z[k])))
        assert abs(z0[j] - wl.z[k]) < 1e-12 and wl.beta[k] == pytest.approx(b0[j], abs=1e-12)


def test_dwell_on_a_cone_end_parallel_has_lambda_r_prime_and_slips_above_mu() -> None:
    m = Mandrel.cone(40.0, 80.0, 200.0)
    slope = 40.0 / 200.0
    spec = WindingSpec(mode="geodesic", angles=[{"z_mm": 100.0, "angle_deg": 30.0}], dwell_deg=(90.0, 90.0),
                       points_per_pass=400)
    for mu, slips in ((0.25, False), (0.15, True)):
        wl = winding_line(m, 6.0, mu, spec)
        assert wl.lambda_ == 0.0
        assert np.allclose(wl.lam[wl.dwell], slope, atol=1e-12)
        _check_dwell_ratio(wl)
        _check_labels(wl)
        assert bool(wl.slips) == slips
        if slips:
            assert wl.slips == [(0.0, 0.0), (200.0, 200.0)]
            assert any("slips there" in n for n in wl.notes)
        assert [t["dwell_on"] for t in wl.turnarounds] == ["end parallel", "end parallel"]
        assert [t["stable"] for t in wl.turnarounds] == [not slips, not slips]


def test_dwell_on_a_dome_parallel_away_from_the_opening_is_reported_as_slip() -> None:
    m = Mandrel.vessel(100.0, 300.0, "hemisphere", 25.0)
    # C = 60: the line turns on the parallel r = 60, far from the opening (r = 25): no boss holds the dwell
    wl = winding_line(m, 8.0, 0.2, WindingSpec(pole_c_mm=(60.0, 60.0), dwell_deg=(30.0, 30.0), points_per_pass=600))
    r_prime = math.sqrt(100.0**2 - 60.0**2) / 60.0  # |r'| of the sphere on the parallel r = 60
    lam_dw = np.abs(wl.lam[wl.dwell])
    assert np.allclose(lam_dw, r_prime, rtol=1e-9)
    _check_dwell_ratio(wl)
    _check_labels(wl)
    zt = wl.z_turn
    assert wl.slips == [(zt[0], zt[0]), (zt[1], zt[1])]
    assert not wl.ok
    assert all(t["dwell_on"] == "turnaround parallel" and not t["stable"] for t in wl.turnarounds)
    assert all(abs(t["dwell_lambda"]) == pytest.approx(r_prime) for t in wl.turnarounds)


def test_vessel_example_dwell_wraps_the_polar_bosses() -> None:
    job = load_job(EXAMPLES / "pressure_vessel.toml")
    m = build_mandrel(job)
    w = job.winding.model_copy(update={"points_per_pass": 500})
    wl = winding_line(m, job.band.width_mm, job.band.friction, w)
    assert wl.ok and not wl.slips
    for side, t in enumerate(wl.turnarounds):
        assert t["dwell_on"] == "polar boss" and t["stable"] and t["dwell_lambda"] == 0.0
        assert t["dwell_r_mm"] == pytest.approx(m.pole_radii[side])
        assert "boss" in t["how"]
    dw = wl.dwell
    assert set(np.round(wl.r[dw], 9)) <= {25.0, 40.0} and (wl.lam[dw] == 0.0).all()
    _check_dwell_ratio(wl)
    _check_labels(wl)


def test_bottle_closure_dwell_goes_to_the_stable_end() -> None:
    job = load_job(EXAMPLES / "bottle.toml")
    m = build_mandrel(job)
    w = job.winding.model_copy(update={"points_per_pass": 400})
    wl = winding_line(m, job.band.width_mm, job.band.friction, w)
    left, right = wl.turnarounds
    assert left["dwell_on"] == "polar boss" and left["dwell_deg"] > 0
    assert right["dwell_deg"] == 0.0 and right["dwell_on"] == "none"
    assert wl.ok
    assert any("all at the left end" in n for n in wl.notes)


def test_line_ratio_matches_lambda_between_the_turnarounds() -> None:
    """k_g/k_n measured on the output polyline equals the λ labels on a constant-λ line (away from ends)."""
    m = Mandrel.pipe(50.0, 400.0)
    spec = WindingSpec(mode="constant-lambda", angles=[{"z_mm": 50.0, "angle_deg": 30.0},
                                                        {"z_mm": 350.0, "angle_deg": 45.0}],
                       dwell_deg=(90.0, 90.0), points_per_pass=4000)
    wl = winding_line(m, 6.0, 0.3, spec).one_circuit
    sel = np.flatnonzero((wl.pass_id == 0) & ~wl.dwell)
    mid = sel[(wl.z[sel] > 60.0) & (wl.z[sel] < 340.0)]
    ratio = measured_ratio(wl.xyz[mid[0] - 1 : mid[-1] + 2], wl.normal[mid[0] - 1 : mid[-1] + 2])
    assert np.abs(ratio - wl.lam[mid]).max() < 1e-4
    assert abs(wl.lam[mid[0]]) > 1e-3
    _check_dwell_ratio(wl)
