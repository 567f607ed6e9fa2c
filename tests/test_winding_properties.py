"""Property tests of the winding line on random vessels, cones and pipes (hypothesis)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.errors import InputError
from engine.job import WindingSpec
from engine.mandrel import Mandrel
from engine.winding import winding_line


def check_invariants(wl, mandrel: Mandrel) -> None:
    assert np.all(np.isfinite(wl.xyz)) and np.all(np.isfinite(wl.v))
    assert np.all(np.diff(wl.v) >= -1e-12)  # twist never decreases
    assert np.all(np.diff(wl.s) >= -1e-12)
    assert np.all(wl.C <= wl.r * (1 + 1e-12)) and np.all(wl.C >= 0)
    assert np.all((wl.beta >= 0) & (wl.beta <= math.pi / 2 + 1e-15))
    assert np.allclose(np.linalg.norm(wl.tau, axis=1), 1.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(wl.normal, axis=1), 1.0, atol=1e-12)
    assert np.max(np.abs(np.sum(wl.tau * wl.normal, axis=1))) < 1e-12
    # the points lie on the mandrel
    assert np.allclose(np.hypot(wl.xyz[:, 0], wl.xyz[:, 1]), mandrel.r(wl.xyz[:, 2]), atol=1e-9)
    # C = r at turnarounds (4)
    sel = (wl.pass_id == 0) & ~wl.dwell
    if wl.end_kinds[0] == "turn":
        assert abs(wl.C[sel][0] - wl.r[sel][0]) < 1e-9
    if wl.end_kinds[1] == "turn":
        assert abs(wl.C[sel][-1] - wl.r[sel][-1]) < 1e-9
    # the pattern closes: p circuits bring the line back to its start
    frac = wl.twist_per_circuit_rad / (2 * math.pi)
    assert abs((frac - math.floor(frac)) - (wl.pattern_q % wl.pattern_p) / wl.pattern_p) < 1e-9 or wl.pattern_p == 1
    assert math.gcd(wl.pattern_p, wl.pattern_q) == 1
    # slips are reported exactly when λ exceeds μ
    # (the line's λ at every integration node, and each dwell arc's λ = r' of its parallel)
    worst = max(wl.max_abs_lambda, float(np.abs(wl.lam[wl.dwell]).max(initial=0.0)))
    assert bool(wl.slips) == (worst > wl.mu + 1e-12)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    R=st.floats(40.0, 200.0),
    L=st.floats(0.0, 400.0),
    dome=st.sampled_from(["hemisphere", "ellipse"]),
    ratio=st.floats(0.4, 1.5),
    p0=st.floats(0.05, 0.6),
    p1=st.floats(0.05, 0.6),
    band=st.floats(2.0, 15.0),
    mu=st.floats(0.0, 0.4),
)
def test_random_vessels(R, L, dome, ratio, p0, p1, band, mu) -> None:
    m = Mandrel.vessel(R, L, dome, (p0 * R, p1 * R), dome_ratio=ratio)
    try:
        wl = winding_line(m, band, mu, WindingSpec(points_per_pass=200))
    except InputError as exc:  # μ = 0 with unequal poles, or an infeasible set-up: a clear message
        assert str(exc)
        return
    check_invariants(wl, m)


@settings(max_examples=15, deadline=None)
@given(r0=st.floats(10.0, 100.0), r1=st.floats(10.0, 100.0), L=st.floats(50.0, 500.0), angle=st.floats(10.0, 80.0))
def test_random_cones_with_an_angle(r0, r1, L, angle) -> None:
    m = Mandrel.cone(r0, r1, L)
    spec = WindingSpec(mode="geodesic", angles=[{"z_mm": 0.5 * L, "angle_deg": angle}], points_per_pass=150)
    try:
        wl = winding_line(m, 5.0, 0.2, spec)
    except InputError as exc:
        assert str(exc)
        return
    check_invariants(wl, m)
    assert wl.max_abs_lambda == 0.0 and np.ptp(wl.C[~wl.dwell]) < 1e-12 * wl.C.max()
