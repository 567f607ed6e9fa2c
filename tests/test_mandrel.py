"""Mandrel generatrix (engine/mandrel.py) against closed forms and independent computations."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from engine.errors import InputError
from engine.mandrel import IsotensoidSegment, Mandrel, validate_points

PI = math.pi


# ------------------------------------------------------------------------------------------------
# area and volume
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("R, L", [(100.0, 200.0), (37.5, 0.0), (5.0, 1000.0)])
def test_closed_hemisphere_vessel_area_volume(R: float, L: float) -> None:
    m = Mandrel.vessel(R, L, "hemisphere", pole_radii=0.0)
    assert m.area_mm2 == pytest.approx(2 * PI * R * L + 4 * PI * R * R, rel=1e-6)
    assert m.volume_mm3 == pytest.approx(PI * R * R * L + 4.0 / 3.0 * PI * R**3, rel=1e-6)
    assert m.pole_radii == pytest.approx((0.0, 0.0), abs=1e-9)


@pytest.mark.parametrize("rp", [(10.0, 10.0), (30.0, 55.0), (0.0, 70.0)])
def test_hemisphere_vessel_with_polar_openings_spherical_zones(rp: tuple[float, float]) -> None:
    R, L = 80.0, 150.0
    m = Mandrel.vessel(R, L, "hemisphere", pole_radii=rp)
    h = [math.sqrt(R * R - p * p) for p in rp]  # height of each spherical zone from the equator
    area = 2 * PI * R * L + sum(2 * PI * R * hh for hh in h)
    vol = PI * R * R * L + sum(PI * (R * R * hh - hh**3 / 3.0) for hh in h)
    assert m.area_mm2 == pytest.approx(area, rel=1e-6)
    assert m.volume_mm3 == pytest.approx(vol, rel=1e-6)
    assert m.length == pytest.approx(L + sum(h), rel=1e-12)
    assert m.pole_radii == pytest.approx(rp, abs=1e-9)


def _spheroid_area(a: float, b: float) -> float:
    """Surface of the spheroid with axial semi-axis a and equatorial radius b."""
    if abs(a - b) < 1e-12 * b:
        return 4 * PI * b * b
    if a < b:  # oblate
        e = math.sqrt(1 - a * a / (b * b))
        return 2 * PI * b * b * (1 + (1 - e * e) / e * math.atanh(e))
    e = math.sqrt(1 - b * b / (a * a))  # prolate
    return 2 * PI * b * b * (1 + a / (b * e) * math.asin(e))


@pytest.mark.parametrize("ratio", [0.3, 0.5, 1.0, 1.6, 3.0])
def test_closed_ellipsoidal_vessel_area_volume(ratio: float) -> None:
    R, L = 60.0, 90.0
    m = Mandrel.vessel(R, L, "ellipse", pole_radii=0.0, dome_ratio=ratio)
    a = ratio * R
    assert m.volume_mm3 == pytest.approx(PI * R * R * L + 4.0 / 3.0 * PI * R * R * a, rel=1e-6)
    assert m.area_mm2 == pytest.approx(2 * PI * R * L + _spheroid_area(a, R), rel=1e-6)


def test_cone_and_pipe_area_volume() -> None:
    r0, r1, L = 40.0, 25.0, 120.0
    m = Mandrel.cone(r0, r1, L)
    assert m.area_mm2 == pytest.approx(PI * (r0 + r1) * math.hypot(L, r0 - r1), rel=1e-12)
    assert m.volume_mm3 == pytest.approx(PI * L * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0, rel=1e-12)
    p = Mandrel.pipe(30.0, 500.0)
    assert p.area_mm2 == pytest.approx(2 * PI * 30.0 * 500.0, rel=1e-12)
    assert p.volume_mm3 == pytest.approx(PI * 900.0 * 500.0, rel=1e-12)


# ------------------------------------------------------------------------------------------------
# r, r', r'' of analytic shapes
# ------------------------------------------------------------------------------------------------
def test_cylinder_and_cone_derivatives() -> None:
    z = np.linspace(0.0, 100.0, 101)
    r, d1, d2 = Mandrel.pipe(25.0, 100.0).evaluate(z)
    np.testing.assert_allclose(r, 25.0, atol=1e-12)
    np.testing.assert_allclose(d1, 0.0, atol=1e-12)
    np.testing.assert_allclose(d2, 0.0, atol=1e-12)
    r, d1, d2 = Mandrel.cone(10.0, 30.0, 100.0).evaluate(z)
    np.testing.assert_allclose(r, 10.0 + 0.2 * z, atol=1e-12)
    np.testing.assert_allclose(d1, 0.2, atol=1e-12)
    np.testing.assert_allclose(d2, 0.0, atol=1e-12)


def test_hemisphere_derivatives() -> None:
    R, L = 50.0, 100.0
    m = Mandrel.vessel(R, L, "hemisphere", pole_radii=(5.0, 20.0))
    # right dome, away from the joint at z = L and from the pole
    u = np.linspace(0.5, math.sqrt(R * R - 400.0) - 0.5, 200)
    r, d1, d2 = m.evaluate(L + u)
    s = np.sqrt(R * R - u * u)
    np.testing.assert_allclose(r, s, atol=1e-8)
    np.testing.assert_allclose(d1, -u / s, atol=1e-8)
    np.testing.assert_allclose(d2, -R * R / s**3, atol=1e-8)
    # left dome (mirror)
    r, d1, d2 = m.evaluate(-u)
    np.testing.assert_allclose(r, s, atol=1e-8)
    np.testing.assert_allclose(d1, u / s, atol=1e-8)
    np.testing.assert_allclose(d2, -R * R / s**3, atol=1e-8)


@pytest.mark.parametrize("ratio", [0.25, 0.5, 0.8, 1.0, 1.5, 2.5])
def test_elliptical_dome_derivatives(ratio: float) -> None:
    """Oblate (ratio < 1) and prolate (ratio > 1) domes: r = R sqrt(1 − (u/a)²)."""
    R, L = 60.0, 80.0
    a = ratio * R
    m = Mandrel.vessel(R, L, "ellipse", pole_radii=15.0, dome_ratio=ratio)
    umax = a * math.sqrt(1 - (15.0 / R) ** 2)
    u = np.linspace(0.01 * a, umax * 0.999, 200)
    for z, sign in ((L + u, 1.0), (-u, -1.0)):
        r, d1, d2 = m.evaluate(z)
        w = np.sqrt(a * a - u * u)  # r = (R/a) w
        np.testing.assert_allclose(r, R / a * w, atol=1e-8)
        np.testing.assert_allclose(d1, -sign * R * u / (a * w), atol=1e-8)
        np.testing.assert_allclose(d2, -R * a / w**3, atol=1e-8)
    # the derivatives also agree with finite differences of r (independent of the closed forms)
    z = L + u[5:-5]
    h = 1e-4
    fd1 = (m.r(z + h) - m.r(z - h)) / (2 * h)
    fd2 = (m.r(z + h) - 2 * m.r(z) + m.r(z - h)) / (h * h)
    np.testing.assert_allclose(m.dr(z), fd1, atol=1e-6)
    np.testing.assert_allclose(m.d2r(z), fd2, atol=2e-4)


@pytest.mark.parametrize(
    "m",
    [
        Mandrel.vessel(100.0, 200.0, "hemisphere", pole_radii=(30.0, 20.0)),
        Mandrel.vessel(100.0, 200.0, "ellipse", pole_radii=(30.0, 20.0), dome_ratio=(0.5, 2.0)),
        Mandrel.vessel(100.0, 200.0, "isotensoid", pole_radii=(30.0, 20.0)),
        Mandrel.vessel(100.0, 0.0, ("hemisphere", "isotensoid"), pole_radii=(10.0, 40.0)),
        Mandrel.bottle(),
    ],
    ids=["hemisphere", "ellipse", "isotensoid", "mixed-no-cylinder", "bottle"],
)
def test_r_and_slope_continuous_at_joints(m: Mandrel) -> None:
    joints = [s.z1 for s in m.segments[:-1]]
    assert joints
    for zj in joints:
        eps = 1e-7 * max(1.0, abs(zj))
        r, d1, _ = m.evaluate(np.array([zj - eps, zj + eps]))
        assert abs(r[1] - r[0]) < 1e-6 * m.r_max, zj
        assert abs(d1[1] - d1[0]) < 1e-5, zj


# ------------------------------------------------------------------------------------------------
# isotensoid dome, against an independent integration of the netting-theory meridian
# ------------------------------------------------------------------------------------------------
def _rho0_sq(rho_p: float) -> float:
    """Clairaut constant² such that the meridian is parallel to the axis at ρ_p (root of D(ρ_p) = 0)."""
    return brentq(lambda c: rho_p**2 - c - rho_p**6 * (1 - c), 0.0, rho_p**2, xtol=1e-16, rtol=1e-15)


@pytest.mark.parametrize("rho_p", [0.05, 0.2, 0.45, 0.8])
def test_isotensoid_meridian_matches_quadrature(rho_p: float) -> None:
    R, L = 100.0, 150.0
    m = Mandrel.vessel(R, L, "isotensoid", pole_radii=rho_p * R)
    c2 = _rho0_sq(rho_p)

    def dzeta_drho(x: float) -> float:  # −dζ/dρ of the meridian
        return x**3 * math.sqrt(1 - c2) / math.sqrt(x * x - c2 - x**6 * (1 - c2))

    P = np.polynomial.polynomial
    d_coef = np.array([-c2, 0.0, 1.0, 0.0, 0.0, 0.0, -(1.0 - c2)])  # D(x) = x² − c² − x⁶(1 − c²), increasing powers

    def half(end: float, sign: float, span: float) -> float:
        """∫ dζ/dρ over [end, end + sign·span] with x = end + sign·w²; D(x) = D(end) + sign·w²·Q(x) exactly."""
        q, rem = P.polydiv(d_coef, np.array([-end, 1.0]))
        d_end = float(rem[0])

        def g(w: float) -> float:
            x = end + sign * w * w
            dd = d_end + sign * w * w * P.polyval(x, q)
            return 2.0 * w * x**3 * math.sqrt(1 - c2) / math.sqrt(dd)

        val, _ = quad(g, 0.0, math.sqrt(span), epsabs=1e-14, epsrel=1e-12, limit=200)
        return val

    def integral(a: float, b: float) -> float:
        """∫_a^b dζ/dρ dρ, the 1/sqrt end singularities removed by x = a + w², x = b − w² on the halves."""
        return half(a, 1.0, 0.5 * (b - a)) + half(b, -1.0, 0.5 * (b - a))

    length = integral(rho_p, 1.0)
    assert IsotensoidSegment.dome_length(R, rho_p * R) == pytest.approx(R * length, rel=1e-8)
    assert m.z_max - L == pytest.approx(R * length, rel=1e-8)
    for frac in (0.02, 0.1, 0.3, 0.5, 0.7, 0.9, 0.98):
        rho = 1.0 - frac * (1.0 - rho_p)
        zeta = integral(rho, 1.0)
        assert m.r(L + R * zeta) == pytest.approx(R * rho, abs=1e-8 * R)  # right dome
        assert m.r(-R * zeta) == pytest.approx(R * rho, abs=1e-8 * R)  # left dome, mirrored
        # slope: dr/dz = 1 / (dz/dr) = −1 / (dζ/dρ)
        assert m.dr(L + R * zeta) == pytest.approx(-1.0 / dzeta_drho(rho), rel=1e-7, abs=1e-9)


@pytest.mark.parametrize("rho_p", [0.1, 0.3, 0.6])
def test_isotensoid_is_in_netting_equilibrium(rho_p: float) -> None:
    """Geodesic fibres (sin α = ρ0/ρ) carry equal tension everywhere: tan²α = 2 − R2/R1."""
    R = 80.0
    m = Mandrel.vessel(R, 50.0, "isotensoid", pole_radii=rho_p * R)
    c = math.sqrt(_rho0_sq(rho_p))
    seg = m.segments[-1]
    z = np.linspace(seg.z0 + 1e-3, seg.z1 - 1e-3, 60)
    r, d1, d2 = m.evaluate(z)
    R1 = -((1 + d1 * d1) ** 1.5) / d2  # meridian radius of curvature (> 0 where convex)
    R2 = r * np.sqrt(1 + d1 * d1)  # second principal radius: along the normal to the axis
    sin_a = c * R / r
    tan2 = sin_a**2 / (1 - sin_a**2)
    np.testing.assert_allclose(tan2, 2.0 - R2 / R1, rtol=1e-6, atol=1e-8)
    # the dome has an inflection: convex near the equator, concave (r'' > 0) near the pole
    assert d2[0] < 0 < d2[-1]


# ------------------------------------------------------------------------------------------------
# spline mandrels
# ------------------------------------------------------------------------------------------------
def test_spline_mandrel_is_c2_and_interpolates() -> None:
    rng = np.random.default_rng(7)
    z = np.cumsum(rng.uniform(2.0, 15.0, 25))
    r = 40.0 + 8.0 * np.sin(z / 30.0) + rng.uniform(-1, 1, 25)
    m = Mandrel.from_points(z, r, name="s")
    np.testing.assert_allclose(m.r(z), r, atol=1e-12)
    for zk in z[1:-1]:
        eps = 1e-7
        rr, d1, d2 = m.evaluate(np.array([zk - eps, zk + eps]))
        assert abs(d1[1] - d1[0]) < 1e-6
        assert abs(d2[1] - d2[0]) < 1e-5 * max(1.0, np.abs(d2).max())
    # third derivative of a cubic spline jumps at knots: r'' is only continuous, not smooth
    zz = np.linspace(z[0], z[-1], 5001)
    d2 = m.d2r(zz)
    assert np.max(np.abs(np.diff(d2))) < 0.01


def test_spline_reproduces_cubic_exactly() -> None:
    z = np.linspace(0.0, 10.0, 7)
    f = 20.0 + 0.1 * z - 0.02 * z**2 + 0.003 * z**3
    m = Mandrel.from_points(z, f)
    zz = np.linspace(0.0, 10.0, 101)
    np.testing.assert_allclose(m.r(zz), 20.0 + 0.1 * zz - 0.02 * zz**2 + 0.003 * zz**3, atol=1e-10)
    np.testing.assert_allclose(m.d2r(zz), -0.04 + 0.018 * zz, atol=1e-10)


# ------------------------------------------------------------------------------------------------
# bottle, summary, concave zones
# ------------------------------------------------------------------------------------------------
def test_bottle_has_concave_waist() -> None:
    m = Mandrel.bottle(radius=60.0, body_length=160.0, shoulder_length=40.0, waist_radius=18.0,
                       neck_length=40.0, neck_radius=24.0)
    z_waist = 200.0  # shoulder and neck steps meet at the waist with r' = r'' = 0
    assert m.r(z_waist) == pytest.approx(18.0)
    assert m.r_min == pytest.approx(15.0)  # bottom pole opening
    assert (m.d2r(np.linspace(181.0, 199.0, 50)) > 0).all()
    assert (m.d2r(np.linspace(201.0, 219.0, 50)) > 0).all()
    zones = m.concave_zones()
    assert any(zn.z_from < 185.0 and zn.z_to > 199.0 for zn in zones)
    assert any(zn.z_from < 201.0 and zn.z_to > 215.0 for zn in zones)
    # the smooth steps have their analytic second derivative: r'' = d·P''(u)/h², P = 10u³ − 15u⁴ + 6u⁵
    u = np.linspace(0.05, 0.95, 19)
    np.testing.assert_allclose(m.d2r(200.0 + 40.0 * u), 6.0 * 60.0 * u * (1 - u) * (1 - 2 * u) / 1600.0, atol=1e-12)
    # the body and the bottom are convex
    zb = np.linspace(m.z_min + 0.1, 150.0, 200)
    assert (m.d2r(zb) <= 1e-12).all()
    assert m.r_max == pytest.approx(60.0)


def test_vessel_domes_are_convex() -> None:
    for dome in ("hemisphere", "ellipse"):
        assert Mandrel.vessel(50.0, 100.0, dome, pole_radii=10.0).concave_zones() == []


def test_summary_and_sample() -> None:
    m = Mandrel.vessel(50.0, 100.0, "hemisphere", pole_radii=(10.0, 20.0), name="v")
    s = m.summary()
    assert s["name"] == "v" and s["pole_radii"] == pytest.approx([10.0, 20.0])
    assert s["length_mm"] == pytest.approx(100.0 + math.sqrt(2500 - 100) + math.sqrt(2500 - 400))
    assert [seg["kind"] for seg in s["segments"]] == ["arc", "line", "arc"]
    z, r = m.sample(300)
    assert z[0] == m.z_min and z[-1] == m.z_max and np.all(np.diff(z) > 0)
    for seg in m.segments:  # joints are sampled
        assert np.any(np.isclose(z, seg.z0))
    np.testing.assert_allclose(r, m.r(z))


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "call, field",
    [
        (lambda: Mandrel.vessel(-5.0, 100.0), "radius"),
        (lambda: Mandrel.vessel(50.0, -1.0), "cylinder_length"),
        (lambda: Mandrel.vessel(50.0, 100.0, pole_radii=60.0), "pole_radius_mm"),
        (lambda: Mandrel.vessel(50.0, 100.0, "isotensoid", pole_radii=0.0), "pole_radius_mm"),
        (lambda: Mandrel.vessel(50.0, 100.0, "ellipse", dome_ratio=0.0), "dome_ratio"),
        (lambda: Mandrel.vessel(50.0, 100.0, "torispherical"), "dome"),
        (lambda: Mandrel.cone(10.0, float("nan"), 5.0), "r1"),
        (lambda: Mandrel.bottle(waist_radius=30.0, neck_radius=24.0), "waist_radius"),
    ],
)
def test_constructor_errors_name_the_field(call, field: str) -> None:  # noqa: ANN001
    with pytest.raises(InputError) as ei:
        call()
    assert ei.value.location.field == field


@pytest.mark.parametrize(
    "z, r, words, line",
    [
        ([0, 1, 2], [1, 1, 1], "at least 4", None),
        ([0, 1, 1, 2], [1, 1, 1, 1], "increase strictly", 12),
        ([0, 1, 2, 3], [1, -1, 1, 1], "negative radius", 11),
        ([0, 1, 2, 3], [1, 0, 1, 1], "meets the axis", 11),
        ([0, 1, np.nan, 3], [1, 1, 1, 1], "not a finite", 12),
    ],
)
def test_validate_points(z: list[float], r: list[float], words: str, line: int | None) -> None:
    with pytest.raises(InputError) as ei:
        validate_points(np.array(z, float), np.array(r, float), file="t.csv", lines=[10, 11, 12, 13][: len(z)])
    assert words in ei.value.message
    assert ei.value.location.line == line
    assert ei.value.location.file == "t.csv"


def test_points_may_close_at_the_ends() -> None:
    m = Mandrel.from_points([0, 1, 2, 3, 4], [0.0, 2.0, 2.5, 2.0, 0.0])
    assert m.pole_radii == (0.0, 0.0)
    # the cubic evaluates to -1.8e-15 at the right end here: roundoff, not a negative pole
    z = [2.083, 3.046, 5.421, 6.292, 8.837, 9.306, 11.835, 12.579, 13.892]
    r = [0.0, 9.751, 15.37, 7.679, 10.944, 5.087, 8.937, 11.318, 0.0]
    assert Mandrel.from_points(z, r).pole_radii == (0.0, 0.0)


def test_isotensoid_answers_kept_are_the_same_numbers() -> None:
    """IsotensoidSegment.eval keeps its last answers: a repeated input gets the numbers of a fresh
    evaluation bit for bit, as new arrays (changing one does not change the next answer); a dome with
    other parameters, or an input differing in one bit, is evaluated afresh; big inputs are not kept and
    the cache stays bounded."""
    import engine.mandrel as mm

    ves = Mandrel.vessel(100.0, 200.0, "isotensoid", pole_radii=(30.0, 20.0))
    dome = next(s for s in ves.segments if isinstance(s, mm.IsotensoidSegment))
    rng = np.random.default_rng(4)
    lo, hi = sorted((dome.zc, dome.zc + dome.direction * dome.dome_length(dome.R, dome.R * dome.rho_p)))
    for n in (1, 7, 300, 5000):
        z = rng.uniform(lo, hi, n)
        ref = dome._eval(z.copy())
        first = dome.eval(z)
        first[0][:] = -1.0                                  # the caller's array: not the kept one
        again = dome.eval(z.copy())
        for a, b in zip(ref, again, strict=True):
            assert a.tobytes() == b.tobytes()
        z2 = z.copy()
        z2[0] = np.nextafter(z2[0], np.inf)
        assert dome.eval(z2)[0].tobytes() == dome._eval(z2)[0].tobytes()
    other = replace(dome, rho_p=dome.rho_p * 1.01)
    z = np.linspace(lo, hi, 200)
    assert other.eval(z)[0].tobytes() == other._eval(z)[0].tobytes() != dome.eval(z)[0].tobytes()
    size = len(mm._EVAL_CACHE)
    dome.eval(np.linspace(lo, hi, mm._EVAL_CACHE_MAX + 1))
    assert len(mm._EVAL_CACHE) == size
    for k in range(mm._EVAL_CACHE_SIZE + 10):
        dome.eval(np.array([lo + k * 1e-3]))
    assert len(mm._EVAL_CACHE) == mm._EVAL_CACHE_SIZE
