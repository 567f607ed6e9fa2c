"""Concave zones of a generatrix (Mandrel.concave_zones): real ones found, spline artefacts dropped.

A zone counts when a fibre spanning it would bridge a gap larger than ``tol_mm`` (default
CONCAVE_GAP_TOL_MM).  Every check here is against something independent of the detector: closed
forms (quintic smooth step, cosine, Gaussian dent, the isotensoid inflection ρ = sqrt(3/2)·ρ0 and a
quadrature of its meridian), or a brute-force chord gap on a dense grid.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize_scalar

from engine.errors import InputError
from engine.job import build_mandrel, load_job
from engine.mandrel import CONCAVE_GAP_TOL_MM, Mandrel
from engine.mandrel_io import load_csv, load_dxf, load_step

TOL = CONCAVE_GAP_TOL_MM


def _gap(m: Mandrel, a: float, b: float, n: int = 20001) -> float:
    """Brute force: largest distance (mm) of the generatrix below the chord of [a, b], normal to the chord."""
    z = np.linspace(a, b, n)
    r = m.r(z)
    k = (r[-1] - r[0]) / (b - a)
    return float(np.max(r[0] + k * (z - a) - r) / math.hypot(1.0, k))


def _spans(m: Mandrel, **kw: float) -> list[tuple[float, float]]:
    return [(zn.z_from, zn.z_to) for zn in m.concave_zones(**kw)]


# ------------------------------------------------------------------------------------------------
# splines through convex profiles: the overshoot at a joint and the wiggle on a cylinder are dropped
# ------------------------------------------------------------------------------------------------
def test_spline_through_cylinder_and_hemisphere_has_no_zone() -> None:
    true = Mandrel.vessel(50.0, 100.0, "hemisphere", pole_radii=10.0)
    z, r = true.sample(200)
    m = Mandrel.from_points(z, r)
    raw = m.concave_zones(tol_mm=0.0)
    assert raw, "the spline overshoots at the r'' jump of the joints (else this test proves nothing)"
    # the true profile is convex (r'' <= 0), so where the spline is within δ of it, it is below none
    # of its chords by more than 2δ: no zone can reach the tolerance
    for zn in raw:
        zz = np.linspace(zn.z_from, zn.z_to, 2001)
        assert 2.0 * float(np.max(np.abs(m.r(zz) - true.r(zz)))) < TOL
    assert m.concave_zones() == []
    # the artefacts: ringing on the cylinder, decaying away from the joints (z = 0 and z = 100)
    for zn in raw:
        assert 0.0 < zn.z_from < zn.z_to < 100.0
        assert min(zn.z_from, 100.0 - zn.z_to) < 20.0
    assert float(np.max(m.d2r(np.linspace(0.0, 2.0, 401)))) > 1e-3  # r'' > +1e-3 1/mm next to the joint


@pytest.mark.parametrize("name, load", [("bottle_profile.csv", load_csv), ("vessel_profile.dxf", load_dxf),
                                        ("vessel.step", load_step)])
def test_sample_imports_keep_only_real_zones(examples_dir: Path, name: str, load) -> None:
    m = load(examples_dir / name)
    raw = m.concave_zones(tol_mm=0.0)
    zones = m.concave_zones()
    assert len(raw) >= 12  # the spline rings on both sides of each cylinder-dome joint
    for zn in raw:
        if not zn.z_from < 200.0 < zn.z_to:
            assert _gap(m, zn.z_from, zn.z_to) < 0.1 * TOL  # ringing: far below the tolerance
    if name == "bottle_profile.csv":  # the waisted neck of Mandrel.bottle(): r'' > 0 on (180, 220)
        assert len(zones) == 1
        assert zones[0].z_from == pytest.approx(180.0, abs=0.3) and zones[0].z_to == pytest.approx(220.0, abs=0.3)
    else:  # hemisphere / ellipse vessels: convex everywhere
        assert zones == []


def test_bottle_template_converted_to_points_has_no_zone_on_the_body() -> None:
    """Points sampled densely from the template: the spline is faithful, only the waist stays."""
    ref = Mandrel.bottle()
    m = Mandrel.from_points(*ref.sample(240))
    zz = np.linspace(0.0, 160.0, 8001)
    assert np.max(np.abs(m.r(zz) - 60.0)) < 0.5 * TOL  # the body is straight within 0.01 mm
    assert any(zn.z_from < 160.0 and zn.z_to > 0.0 for zn in m.concave_zones(tol_mm=0.0))  # raw wiggle exists
    (zone,) = m.concave_zones()
    assert zone.z_from == pytest.approx(180.0, abs=0.5) and zone.z_to == pytest.approx(220.0, abs=0.5)


def test_sparse_sketch_of_the_bottle_reports_only_real_dents() -> None:
    """The GUI's "Convert to sketch" (19 handle points): the r'' ~ 1e-4 1/mm wiggle in the middle of
    the body is dropped; a zone left on the body is a real dent of the spline, checked by brute force."""
    from winder_gui.views.geometry import handle_points

    ref = Mandrel.bottle()
    m = Mandrel.from_points(*handle_points(ref))
    raw = [zn for zn in m.concave_zones(tol_mm=0.0) if 0.0 < zn.z_from and zn.z_to < 160.0]
    kept = [zn for zn in m.concave_zones() if 0.0 < zn.z_from and zn.z_to < 160.0]
    assert len(raw) >= 4
    for zn in raw:
        g = _gap(m, zn.z_from, zn.z_to)
        real = any(abs(k.z_from - zn.z_from) < 1e-6 and abs(k.z_to - zn.z_to) < 1e-6 for k in kept)
        assert real == (g > TOL), (zn, g)
        if not real:  # the dropped ones are the small-r'' wiggle
            assert float(np.max(m.d2r(np.linspace(zn.z_from, zn.z_to, 201)))) < 1e-3
    assert len(kept) < len(raw)
    for zn in kept:  # what stays dips below the true body radius: a real dent of the converted sketch
        assert 60.0 - float(np.min(m.r(np.linspace(zn.z_from, zn.z_to, 2001)))) > 0.5 * TOL
    assert any(zn.z_from < 200.0 < zn.z_to for zn in m.concave_zones())  # the waist stays


# ------------------------------------------------------------------------------------------------
# real concave zones: found, with the analytic extent
# ------------------------------------------------------------------------------------------------
def test_concave_sketch_cosine() -> None:
    """r = 50 + 6 cos(2πz/200): r'' > 0 exactly on (50, 150); the chord there is r = 50, the gap 6 mm."""
    z = np.linspace(0.0, 200.0, 41)
    m = Mandrel.from_points(z, 50.0 + 6.0 * np.cos(2.0 * math.pi * z / 200.0), name="dent")
    (zone,) = m.concave_zones()
    assert zone.z_from == pytest.approx(50.0, abs=0.3)
    assert zone.z_to == pytest.approx(150.0, abs=0.3)
    assert zone.gap_mm == pytest.approx(6.0, abs=0.02)


@pytest.mark.parametrize("gap", [0.5 * TOL, 1.5 * TOL, 1.0])
def test_gaussian_dent_kept_only_above_tolerance(gap: float) -> None:
    """A dent r = 50 − d·exp(−(z − 100)²/2σ²) on a cylinder: r'' > 0 on |z − 100| < σ, and the chord
    over it lies d·(1 − e^(−1/2)) above the bottom (slope 0): a gap we choose through d."""
    sigma = 12.0
    d = gap / (1.0 - math.exp(-0.5))
    z = np.linspace(0.0, 200.0, 401)
    m = Mandrel.from_points(z, 50.0 - d * np.exp(-((z - 100.0) ** 2) / (2.0 * sigma**2)))
    zones = m.concave_zones()
    if gap < TOL:
        assert zones == []
        (zone,) = m.concave_zones(tol_mm=0.0)
    else:
        (zone,) = zones
    assert zone.z_from == pytest.approx(100.0 - sigma, abs=0.05)
    assert zone.z_to == pytest.approx(100.0 + sigma, abs=0.05)
    assert zone.gap_mm == pytest.approx(gap, rel=2e-3)
    assert zone.gap_mm == pytest.approx(_gap(m, zone.z_from, zone.z_to), rel=1e-4)


def test_bottle_waist_is_one_zone_with_the_analytic_ends() -> None:
    """Shoulder and neck are quintic steps P = 10u³ − 15u⁴ + 6u⁵, P'' = 60u(1 − u)(1 − 2u): r'' > 0 on
    the second half of the shoulder (180, 200) and the first half of the neck (200, 220); r'' = 0 at
    the waist z = 200 joins them into one zone."""
    m = Mandrel.bottle()
    (zone,) = m.concave_zones()
    assert zone.z_from == pytest.approx(180.0, abs=1e-6)
    assert zone.z_to == pytest.approx(220.0, abs=1e-6)

    def r(z: float) -> float:  # the closed form, independent of the segments
        h = 40.0
        if z <= 200.0:
            u, r0, r1 = (z - 160.0) / h, 60.0, 18.0
        else:
            u, r0, r1 = (z - 200.0) / h, 18.0, 24.0
        return r0 + (r1 - r0) * u**3 * (10.0 - 15.0 * u + 6.0 * u * u)

    ra, rb = r(180.0), r(220.0)
    k = (rb - ra) / 40.0
    res = minimize_scalar(lambda z: r(z) - (ra + k * (z - 180.0)), bounds=(180.0, 220.0), method="bounded",
                          options={"xatol": 1e-9})
    assert zone.gap_mm == pytest.approx(-res.fun / math.hypot(1.0, k), rel=1e-4)


def _isotensoid_inflection(R: float, rp: float) -> tuple[float, float]:
    """Radius of the inflection of an isotensoid dome and its axial distance from the pole (mm).

    With dρ/dζ = −sqrt(D)/(c·ρ³), D = ρ² − ρ0² − c²ρ⁶, c² = 1 − ρ0², one has
    d²ρ/dζ² = ½·d(D/ρ⁶)/dρ / c² = (−4ρ⁻⁵ + 6ρ0²ρ⁻⁷)/(2c²): r'' changes sign at ρ = sqrt(3/2)·ρ0 and is
    > 0 between it and the pole.  The distance is ∫ c·ρ³/sqrt(D) dρ from ρ_p, with ρ = ρ_p + u².
    """
    p = rp / R
    rho0_sq = (p * p - p**6) / (1.0 - p**6)
    c = math.sqrt(1.0 - rho0_sq)
    rho_i = math.sqrt(1.5 * rho0_sq)

    def f(u: float) -> float:
        rho = p + u * u
        D = rho * rho - rho0_sq - c * c * rho**6
        return 2.0 * u * c * rho**3 / math.sqrt(D) if u > 0 else 2.0 * c * p**3 / math.sqrt(2 * p - 6 * c * c * p**5)

    dz, _ = quad(f, 0.0, math.sqrt(rho_i - p), epsabs=1e-13, epsrel=1e-12)
    return R * rho_i, R * dz


def test_isotensoid_inflection_is_real_and_found() -> None:
    """The pressure-vessel example: R 100 mm, pole openings 25 and 40 mm, isotensoid domes."""
    m = Mandrel.vessel(100.0, 300.0, "isotensoid", pole_radii=(25.0, 40.0))
    left, right = m.concave_zones()
    r_l, dz_l = _isotensoid_inflection(100.0, 25.0)
    r_r, dz_r = _isotensoid_inflection(100.0, 40.0)
    assert left.z_from == pytest.approx(m.z_min, abs=1e-9)
    assert left.z_to == pytest.approx(m.z_min + dz_l, abs=1e-6)
    assert right.z_from == pytest.approx(m.z_max - dz_r, abs=1e-6)
    assert right.z_to == pytest.approx(m.z_max, abs=1e-9)
    assert m.r(left.z_to) == pytest.approx(r_l, abs=1e-6)
    assert m.r(right.z_from) == pytest.approx(r_r, abs=1e-6)
    for zn in (left, right):
        assert zn.gap_mm > 5 * TOL and zn.gap_mm == pytest.approx(_gap(m, zn.z_from, zn.z_to), rel=1e-3)


def test_isotensoid_inflection_with_a_small_pole_is_below_the_tolerance() -> None:
    """ρ_p = 0.1: the inflection is real (found with tol 0) but spans 0.08 mm with a 0.015 mm gap."""
    m = Mandrel.vessel(100.0, 100.0, "isotensoid", pole_radii=10.0)
    _, dz = _isotensoid_inflection(100.0, 10.0)
    left, right = m.concave_zones(tol_mm=0.0)
    assert left.z_to - left.z_from == pytest.approx(dz, abs=1e-6)
    assert right.z_to - right.z_from == pytest.approx(dz, abs=1e-6)
    assert 0.0 < left.gap_mm < TOL
    assert m.concave_zones() == []
    assert len(m.concave_zones(tol_mm=0.01)) == 2


# ------------------------------------------------------------------------------------------------
# the examples, the summary, bad input
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name, count", [("bottle.toml", 1), ("pipe.toml", 0), ("pressure_vessel.toml", 2)])
def test_example_jobs(examples_dir: Path, name: str, count: int) -> None:
    m = build_mandrel(load_job(examples_dir / name), examples_dir / name)
    zones = m.concave_zones()
    assert len(zones) == count
    assert m.summary()["concave_zones"] == [[zn.z_from, zn.z_to] for zn in zones]


def test_zones_are_ordered_disjoint_and_shrink_with_the_tolerance() -> None:
    z = np.linspace(0.0, 300.0, 61)
    r = 60.0 + 3.0 * np.cos(2.0 * math.pi * z / 100.0) + 0.2 * np.cos(2.0 * math.pi * z / 37.0)
    m = Mandrel.from_points(z, r)
    prev = None
    for tol in (0.0, 0.01, 0.1, 1.0, 10.0):
        zones = m.concave_zones(tol_mm=tol)
        assert all(a.z_to < b.z_from for a, b in zip(zones[:-1], zones[1:]))
        assert all(zn.gap_mm > tol for zn in zones)
        if prev is not None:  # a larger tolerance never adds a zone
            assert all(any(p.z_from <= zn.z_from and zn.z_to <= p.z_to for p in prev) for zn in zones)
        prev = zones
    assert prev == []


@pytest.mark.parametrize("bad", [-0.01, float("nan"), float("inf"), "0.02", True])
def test_bad_tolerance_is_an_input_error(bad: object) -> None:
    with pytest.raises(InputError, match="tolerance"):
        Mandrel.bottle().concave_zones(tol_mm=bad)  # type: ignore[arg-type]


def test_numpy_tolerance_and_bad_sample_count() -> None:
    m = Mandrel.bottle()
    assert [(z.z_from, z.z_to) for z in m.concave_zones(tol_mm=np.float32(0.02))] == \
        [(z.z_from, z.z_to) for z in m.concave_zones(tol_mm=0.02)]
    for bad in (0, 15, 100.5, True):
        with pytest.raises(InputError, match="sample count"):
            m.concave_zones(n=bad)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        m.concave_zones(0.02)  # type: ignore[misc]  # keyword-only: an old positional n cannot be read as mm
