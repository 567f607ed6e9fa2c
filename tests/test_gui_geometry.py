"""The view data computed off the GUI thread (winder_gui.views.geometry): no Qt needed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine.mandrel import Mandrel
from winder_gui.views.geometry import check_points, handle_points, mandrel_view_data


def test_surface_is_the_revolved_generatrix() -> None:
    m = Mandrel.cone(50.0, 30.0, 200.0)
    d = mandrel_view_data(m, n_z=101, n_theta=37)
    assert d.surface_x.shape == (len(d.z), 37)
    np.testing.assert_allclose(d.r, 50.0 - 20.0 * d.z / 200.0, rtol=1e-12)  # closed form of the cone
    np.testing.assert_allclose(np.hypot(d.surface_y, d.surface_z), np.repeat(d.r[:, None], 37, axis=1), rtol=1e-12)
    np.testing.assert_allclose(d.surface_x[:, 0], d.z)
    # the ring closes: last angle = first angle
    np.testing.assert_allclose(d.surface_y[:, -1], d.surface_y[:, 0], atol=1e-9)
    np.testing.assert_allclose(d.surface_z[:, -1], d.surface_z[:, 0], atol=1e-9)
    np.testing.assert_allclose(d.d2r, 0.0, atol=1e-12)
    assert d.concave == ()


def test_hemisphere_curvature_and_handles() -> None:
    m = Mandrel.vessel(100.0, 300.0, dome="hemisphere", pole_radii=30.0)
    d = mandrel_view_data(m)
    dome = d.z < -1.0
    # r = sqrt(R² - z²)  =>  r'' = -R² / r³
    np.testing.assert_allclose(d.d2r[dome], -(100.0**2) / d.r[dome] ** 3, rtol=1e-9)
    assert d.concave == ()
    hz, hr = handle_points(m)
    assert np.all(np.diff(hz) > 0) and hz[0] == pytest.approx(m.z_min) and hz[-1] == pytest.approx(m.z_max)
    for joint in (0.0, 300.0):
        assert np.any(np.isclose(hz, joint))  # segment joints are kept
    zl = np.clip(hz, None, 0.0)  # distance into the left dome
    zr = np.clip(hz - 300.0, 0.0, None)  # and into the right dome
    np.testing.assert_allclose(hr, np.sqrt(np.maximum(100.0**2 - zl**2 - zr**2, 0.0)), rtol=1e-9)


def test_sketch_points_are_the_handles() -> None:
    z, r = [0.0, 10.0, 20.0, 30.0, 40.0], [20.0, 30.0, 35.0, 30.0, 20.0]
    m = Mandrel.from_points(z, r)
    d = mandrel_view_data(m, sketch=(z, r))
    np.testing.assert_array_equal(d.handle_z, z)
    np.testing.assert_array_equal(d.handle_r, r)


@pytest.mark.parametrize(
    ("z", "r", "index", "words"),
    [
        ([0, 1, 2, 3], [1, 1, 1, 1], None, ""),
        ([0, 1, 2, 3], [0, 1, 1, 0], None, ""),  # closed poles are fine
        ([0, 1, 1, 3], [1, 1, 1, 1], 2, "z must increase"),
        ([0, 2, 1, 3], [1, 1, 1, 1], 2, "z must increase"),
        ([0, 1, 2, 3], [1, 0, 1, 1], 1, "radius must be > 0"),
        ([0, 1, 2, 3], [-1, 1, 1, 1], 0, "radius must be > 0"),
        ([0, 1, 2], [1, 1, 1], 2, "at least 4 points"),
        ([0, 1, math.nan, 3], [1, 1, 1, 1], 2, "not a finite"),
    ],
)
def test_check_points(z, r, index, words) -> None:
    res = check_points(np.asarray(z, dtype=float), np.asarray(r, dtype=float))
    if index is None:
        assert res is None
    else:
        assert res is not None and res[0] == index and words in res[1]


@pytest.mark.parametrize("example", ["bottle", "pressure_vessel", "pipe"])
def test_convert_to_sketch_points_reproduce_the_template(example: str) -> None:
    """The spline through the converted points stays within 0.01 mm of the template (checked
    independently on a fine grid) and keeps exactly the template's concave zones."""
    from engine.job import build_mandrel, load_job
    from engine.resources import resource_path
    from winder_gui.views.geometry import sketch_points

    m = build_mandrel(load_job(resource_path("examples", f"{example}.toml")))
    z, r, dev = sketch_points(m, tol_mm=0.01)
    assert dev <= 0.01 and np.all(np.diff(z) > 0) and z.size < 400
    spline = Mandrel.from_points(z, r)
    zz = np.linspace(z[0], z[-1], 20001)
    assert np.max(np.abs(spline.r(zz) - m.r(zz))) < 0.012
    want = [(a.z_from, a.z_to) for a in m.concave_zones()]
    got = [(a.z_from, a.z_to) for a in spline.concave_zones()]
    assert len(got) == len(want)
    for (a0, a1), (b0, b1) in zip(got, want):
        assert abs(a0 - b0) < 0.5 and abs(a1 - b1) < 0.5


def test_closed_pole_profile_builds_and_converts() -> None:
    """A sampled sphere closed at both poles (r = 0 at the ends; r() gives -1e-15 there): the view data
    builds and the converted sketch has no negative radius."""
    from winder_gui.views.geometry import sketch_points

    th = np.linspace(0.0, np.pi, 41)
    r0 = 50.0 * np.sin(th)
    r0[0] = r0[-1] = 0.0
    m = Mandrel.from_points(-50.0 * np.cos(th), r0)
    d = mandrel_view_data(m)
    assert np.all(d.handle_r >= 0.0)
    z, r, dev = sketch_points(m, tol_mm=0.05)
    assert np.all(r >= 0.0) and r[0] < 1e-12 and r[-1] < 1e-12
    Mandrel.from_points(z, r)              # a valid sketch


def test_sorted_unique_is_numpy_unique() -> None:
    """The sort-based unique of the decimation (lets the GUI thread run) equals np.unique."""
    import numpy as np

    from winder_gui.views.geometry import _sorted_unique

    rng = np.random.default_rng(0)
    for n in (0, 1, 2, 1000, 100_000):
        a = rng.integers(0, n // 2 + 1, n).astype(np.int64)
        assert np.array_equal(_sorted_unique(a), np.unique(a))
