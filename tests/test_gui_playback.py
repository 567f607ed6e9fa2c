"""Playback in machine time and the band of true width (winder_gui.views.playback), checked against
closed forms: times from blocks, frame lookup, a band on a cylinder whose edges are ±w/2 across the
helix in the surface."""

from __future__ import annotations

import numpy as np

from winder_gui.views.playback import Timeline, band_strip, point_times


def test_point_times_spread_block_times_over_arc_length() -> None:
    # 3 blocks over 7 points; block 1 spans points 2..5 with unequal spacing
    s = np.array([0.0, 1.0, 2.0, 2.5, 4.0, 6.0, 7.0])
    index = np.array([0, 2, 5, 6])
    time = np.array([2.0, 8.0, 1.0])
    t = point_times(7, index, time, s)
    # boundaries carry the cumulative times exactly; inside a block time ∝ arc length
    np.testing.assert_allclose(t[[0, 2, 5, 6]], [0.0, 2.0, 10.0, 11.0])
    np.testing.assert_allclose(t[1], 1.0)
    np.testing.assert_allclose(t[3], 2.0 + 8.0 * (2.5 - 2.0) / (6.0 - 2.0))
    np.testing.assert_allclose(t[4], 2.0 + 8.0 * (4.0 - 2.0) / (6.0 - 2.0))
    # without s: evenly per point
    np.testing.assert_allclose(point_times(7, index, time)[3], 2.0 + 8.0 / 3.0)


def test_timeline_frame_lookup_and_circuits() -> None:
    tl = Timeline(np.array([0.0, 1.0, 1.0, 2.5, 4.0]), np.array([0, 0, 1, 1, 2]))
    assert tl.total_s == 4.0
    assert [tl.frame_at(t) for t in (-1.0, 0.0, 0.99, 1.0, 3.0, 4.0, 9.0)] == [0, 0, 0, 2, 3, 4, 4]
    assert tl.circuit_start(1) == 2 and tl.circuit_start(2) == 4 and tl.circuit_start(7) == 4


def test_band_on_a_cylinder_has_its_width_across_the_fibre() -> None:
    r, w, beta = 50.0, 8.0, np.radians(55.0)
    s = np.linspace(0.0, 600.0, 400)
    phi = s * np.sin(beta) / r
    x = s * np.cos(beta)  # the axis along x, as in the view frame
    xyz = np.column_stack([x, r * np.cos(phi), r * np.sin(phi)])
    normal = np.column_stack([np.zeros_like(x), np.cos(phi), np.sin(phi)])
    times = s / 100.0
    band = band_strip(xyz, normal, times, w)
    m = band.m
    left, right = band.points[:m], band.points[m:]
    np.testing.assert_allclose(np.linalg.norm(left - right, axis=1), w, rtol=1e-9)
    # the edges are centred on the line and lie on the tangent plane: across ⟂ tangent and ⟂ normal
    np.testing.assert_allclose(0.5 * (left + right), xyz, atol=1e-9)
    across = (left - right) / w
    tangent = np.column_stack([np.full_like(x, np.cos(beta)), -np.sin(beta) * np.sin(phi), np.sin(beta) * np.cos(phi)])
    np.testing.assert_allclose(np.einsum("ij,ij->i", across, tangent)[1:-1], 0.0, atol=2e-4)
    np.testing.assert_allclose(np.einsum("ij,ij->i", across, normal), 0.0, atol=1e-12)
    # laid by time t: the quads whose both ends were wound
    assert band.quads_until(-1.0) == 0 and band.quads_until(times[-1]) == m - 1
    k = band.quads_until(3.0)
    assert times[k] <= 3.0 < times[k + 1]
    assert band.quads().size == 5 * (m - 1)
