"""A million winding-path points in the 3D view (issue 9), and the thinning that keeps the turnarounds.

The tests marked ``gl`` build the real pyvistaqt view and need OpenGL (xvfb)::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/pytest -m gl tests/test_gui_gl_big.py

The thinning tests (:func:`winder_gui.views.geometry.decimate_indices`) are plain numpy and run
everywhere.  Speed is measured in ``benchmarks/bench_gui_3d.py``, not here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder_gui.views.geometry import LOD_POINTS, decimate_indices, feature_indices, paths_view_data, to_view

N = 1_000_000


def helix_line(n: int, circuits: int, radius: float = 50.0, length: float = 1000.0) -> SimpleNamespace:
    """``circuits`` out-and-back helices on a cylinder with a dwell at both ends (mm, rad).

    z(index) is piecewise linear with corners at the turnarounds, which fall between the points of
    any regular stride (the circuit length is not a round number).
    """
    t = np.linspace(0.0, circuits, n, endpoint=False)
    ph = t % 1.0
    z = np.interp(ph, [0.0, 0.45, 0.5, 0.95, 1.0], [0.0, length, length, 0.0, 0.0])
    theta = 2.0 * np.pi * (3.3 * t + 0.37 * np.floor(t))
    r = np.full(n, radius)
    xyz = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    return SimpleNamespace(z=z, r=r, xyz=xyz, beta=np.full(n, 0.6), lam=np.sin(theta) * 0.1,
                           circuit=np.floor(t).astype(np.int64))


def zigzag_line(n: int, corners: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """Points whose z is piecewise linear in the index with the given corner indices and heights."""
    z = np.interp(np.arange(n), corners, heights)
    return np.column_stack([np.cos(np.arange(n) * 0.01), np.sin(np.arange(n) * 0.01), z])


# -- thinning (no GL) -----------------------------------------------------------------------------
def test_thinning_keeps_every_turnaround_where_a_stride_cuts_the_corners() -> None:
    n, circuits = 200_003, 37
    line = helix_line(n, circuits)
    idx, _ = decimate_indices(line.xyz, 20_000, line.circuit)
    assert idx.size <= 20_000 and idx[0] == 0 and idx[-1] == n - 1 and np.all(np.diff(idx) > 0)
    # z is piecewise linear in the index between samples: with the corner samples kept, the thinned line is
    # off by less than one source step (the true corner lies between two samples), nowhere more
    step = np.abs(np.diff(line.z)).max()
    assert np.abs(np.interp(np.arange(n), idx, line.z[idx]) - line.z).max() <= step + 1e-9
    # each circuit reaches both ends of the mandrel, as the source does
    for c in range(circuits):
        shown = line.z[idx[line.circuit[idx] == c]]
        assert shown.max() == line.z[line.circuit == c].max() and shown.min() == line.z[line.circuit == c].min()
    # a plain stride of the same size does cut them (so the check above means something)
    stride = np.arange(0, n, int(np.ceil(n / 20_000)))
    assert np.abs(np.interp(np.arange(n), stride, line.z[stride]) - line.z).max() > 2 * step
    # every circuit change is kept on both sides
    ch = np.flatnonzero(np.diff(line.circuit))
    assert np.isin(ch, idx).all() and np.isin(ch + 1, idx).all()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 3000), min_size=1, max_size=60), st.integers(500, 5000), st.data())
def test_thinning_reproduces_any_zigzag_axial_motion(gaps, budget, data) -> None:
    """z runs back and forth between turnarounds at arbitrary points: the thinned line has all of them."""
    corners = np.concatenate([[0], np.cumsum(gaps)])
    n = int(corners[-1]) + 1
    legs = np.array(data.draw(st.lists(st.floats(0.01, 500), min_size=len(gaps), max_size=len(gaps))))
    heights = np.concatenate([[0.0], np.cumsum(legs * (-1.0) ** np.arange(legs.size))])
    xyz = zigzag_line(n, corners, heights)
    idx, _ = decimate_indices(xyz, budget)
    assert idx.size <= max(budget, 64) and idx[0] == 0 and idx[-1] == n - 1 and np.all(np.diff(idx) > 0)
    if corners.size <= budget // 2 - 8:
        err = np.abs(np.interp(np.arange(n), idx, xyz[idx, 2]) - xyz[:, 2]).max()
        assert err <= 1e-9 * (1.0 + np.ptp(heights))
    # the thinned line spans the same box
    np.testing.assert_array_equal(xyz[idx].min(axis=0), xyz.min(axis=0))
    np.testing.assert_array_equal(xyz[idx].max(axis=0), xyz.max(axis=0))


def test_features_of_a_dwell_and_a_budget_smaller_than_the_features() -> None:
    z = np.array([0, 1, 2, 2, 2, 1, 0, 0, 1], dtype=float)
    xyz = np.column_stack([np.zeros(9), np.zeros(9), z])
    assert list(feature_indices(xyz)) == [0, 2, 4, 6, 7, 8]  # both ends of each plateau
    rng = np.random.default_rng(1)
    noisy = np.column_stack([rng.normal(size=(100_000, 2)), rng.normal(size=100_000)])  # a turnaround at every point
    idx, _ = decimate_indices(noisy, 1000)
    assert idx.size <= 1000 and idx[-1] == 99_999
    np.testing.assert_array_equal(noisy[idx].max(axis=0), noisy.max(axis=0))
    assert np.array_equal(decimate_indices(xyz, 100)[0], np.arange(9))  # short lines are kept whole


def test_paths_view_data_coarse_copy_for_moving_views() -> None:
    line = helix_line(300_001, 50)
    p = paths_view_data(line, None, 100_000, 100, lod_points=5_000)
    assert p.line_xyz.shape[0] <= 100_000 and p.lod_index.size <= 5_000
    assert np.all(np.diff(p.lod_index) > 0) and p.lod_index[-1] == p.line_index.size - 1
    coarse = p.line_xyz[p.lod_index]
    np.testing.assert_array_equal(coarse.min(axis=0), p.line_xyz.min(axis=0))
    np.testing.assert_array_equal(coarse.max(axis=0), p.line_xyz.max(axis=0))
    # the turnarounds of the source survive both thinnings
    src = line.z[p.line_index[p.lod_index]]
    for c in range(50):
        sel = line.circuit[p.line_index[p.lod_index]] == c
        assert src[sel].max() == line.z[line.circuit == c].max()


# -- the real view (GL) ---------------------------------------------------------------------------
@pytest.fixture
def big_view(qtbot):
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.views.geometry import MandrelViewData
    from winder_gui.views.view3d import MandrelView3D

    view = MandrelView3D()
    qtbot.addWidget(view)
    view.resize(900, 600)
    view.show()
    z = np.linspace(0.0, 1000.0, 100)
    r = np.full(z.size, 50.0)
    th = np.linspace(0.0, 2 * np.pi, 73)
    view.set_data(MandrelViewData(z, r, np.zeros(z.size), (), z[::25], r[::25], np.repeat(z[:, None], 73, axis=1),
                                  r[:, None] * np.cos(th)[None, :], r[:, None] * np.sin(th)[None, :]),
                  reset_camera=True)
    assert view.ensure_backend() == "vtk"
    yield view
    view.close_backend()


@pytest.mark.gl
def test_a_million_points_are_all_shown_at_rest_and_a_coarse_copy_while_moving(big_view, qtbot) -> None:
    from winder_gui.views.view3d import MAX_DISPLAY_POINTS, MAX_FRAMES

    v = big_view
    line = helix_line(N, 120)
    eye = SimpleNamespace(u=np.ones(N - 1), eye_xyz=line.xyz * [1.5, 1.5, 1.0], contact_xyz=line.xyz)
    p = paths_view_data(line, eye, MAX_DISPLAY_POINTS, MAX_FRAMES)
    v.set_paths(p)
    # at rest: every source point, in order, lifted off the surface by p.lift (VTK keeps float32)
    shown = v.shown_path_points()
    assert shown.shape == (N, 3) and not v.lod_active
    drawn = v.plotter.actors["paths"].mapper.GetDataSetInput()  # what VTK rendered last
    assert drawn.GetNumberOfPoints() == N and drawn.GetNumberOfCells() == N - 1
    np.testing.assert_allclose(drawn.GetBounds(), v.path_mesh("paths").bounds, rtol=1e-7)
    lifted = line.xyz * np.array([(50.0 + p.lift) / 50.0] * 2 + [1.0])
    expected = to_view(lifted)
    np.testing.assert_allclose(shown, expected, rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(shown.min(axis=0), expected.min(axis=0), atol=1e-4)
    np.testing.assert_allclose(shown.max(axis=0), expected.max(axis=0), atol=1e-4)
    assert shown[:, 0].min() == 0.0 and shown[:, 0].max() == pytest.approx(1000.0)
    np.testing.assert_allclose(np.hypot(shown[:, 1], shown[:, 2]), 50.0 + p.lift, rtol=1e-6)
    # the colours are the source's circuit numbers
    c = np.asarray(v.path_mesh("paths").point_data["c"])
    np.testing.assert_array_equal(c, line.circuit)
    # a mouse drag (Qt events -> VTK's interactor style, which raises the desired update rate): the coarse copy
    from PySide6.QtCore import QPoint, Qt
    from PySide6.QtTest import QTest

    g = v.gl_widget
    at = QPoint(g.width() // 2, g.height() // 2)
    cam0 = np.array(v.plotter.camera.position)
    QTest.mousePress(g, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, at)
    for k in range(1, 4):
        QTest.mouseMove(g, at + QPoint(15 * k, 4 * k))
        qtbot.wait(1)
        coarse = v.shown_path_points()
        assert v.lod_active and coarse.shape[0] <= LOD_POINTS
        assert not v.plotter.actors["paths"].GetVisibility() and v.plotter.actors["paths_lod"].GetVisibility()
    np.testing.assert_allclose(coarse.min(axis=0), expected.min(axis=0), atol=1e-4)  # same bounds
    np.testing.assert_allclose(coarse.max(axis=0), expected.max(axis=0), atol=1e-4)
    QTest.mouseRelease(g, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, at + QPoint(45, 12))
    qtbot.wait(1)
    assert not np.allclose(v.plotter.camera.position, cam0)  # it did rotate
    assert not v.lod_active and v.plotter.actors["paths"].GetVisibility()  # at rest: the full line again
    assert not v.plotter.actors["paths_lod"].GetVisibility()
    # playing draws the coarse copy, pausing the full one
    v.play()
    v.set_frame(10)
    qtbot.waitUntil(lambda: v.lod_active, timeout=5000)  # the next paint renders it
    v.pause()
    assert not v.lod_active and v.shown_path_points().shape[0] == N
    # while the engine computes, the coarse copy (a full frame would hold the GUI thread ~0.25 s)
    v.set_busy(True)
    qtbot.waitUntil(lambda: v.lod_active, timeout=5000)
    assert v.plotter.actors["paths_lod"].GetVisibility() and not v.plotter.actors["paths"].GetVisibility()
    v.set_busy(False)
    qtbot.waitUntil(lambda: not v.lod_active, timeout=5000)
    assert v.shown_path_points().shape[0] == N
    # another colour: both copies re-coloured with the source's values
    v.set_colour_by("λ [–]")
    np.testing.assert_allclose(np.asarray(v.path_mesh("paths").point_data["c"]), line.lam, rtol=1e-6, atol=1e-9)
    lod_c = np.asarray(v.path_mesh("paths_lod").point_data["c"])
    np.testing.assert_allclose(lod_c, line.lam[p.line_index[p.lod_index]], rtol=1e-6, atol=1e-9)
    # the eye and fibre follow the frame without new actors
    eye_actor = v.plotter.actors["eye"]
    v.set_frame(500)
    e, ct = v.eye_at_frame()
    assert v.plotter.actors["eye"] is eye_actor
    np.testing.assert_allclose(v.actor_points("fibre")[[0, -1]], [ct, e], rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(v.actor_points("eye").mean(axis=0), e, atol=0.5)
    np.testing.assert_allclose(v.actor_points("eye_path"), v.trail(), rtol=1e-5, atol=1e-3)


def _rgb(img) -> np.ndarray:
    """(h, w * 3) bytes of an RGB888 QImage, copied (the QImage's buffer goes with it)."""
    rows = np.frombuffer(img.constBits(), np.uint8).reshape(img.height(), img.bytesPerLine())
    return rows[:, : 3 * img.width()].copy()


def _on_screen(v) -> np.ndarray:
    """The 3D widget's pixels as the X server shows them (RGB), not a new render."""
    from PySide6.QtCore import QPoint
    from PySide6.QtGui import QGuiApplication, QImage

    g = v.gl_widget
    at = g.mapTo(v.window(), QPoint(0, 0))
    img = QGuiApplication.primaryScreen().grabWindow(v.window().winId()).toImage()
    img = img.copy(at.x(), at.y(), g.width(), g.height()).convertToFormat(QImage.Format.Format_RGB888)
    return _rgb(img)


def _rendered(v) -> np.ndarray:
    """A new render of the scene (RGB)."""
    from PySide6.QtGui import QImage

    img = v.render_image().convertToFormat(QImage.Format.Format_RGB888)
    return _rgb(img)


@pytest.mark.gl
def test_one_render_per_frame_and_the_window_shows_the_current_picture(big_view, qtbot) -> None:
    """pyvistaqt's paint renders again after every render; the view's widget paints by blitting the frame just
    rendered: one VTK render per camera step (counted as render-window EndEvents), and still no stale picture."""
    from PySide6.QtCore import QPoint, Qt
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QWidget

    v = big_view
    line = helix_line(50_000, 20)
    eye = SimpleNamespace(u=np.ones(49_999), eye_xyz=line.xyz * [1.5, 1.5, 1.0], contact_xyz=line.xyz)
    v.set_paths(paths_view_data(line, eye, 1_000_000, 1000, lod_points=5_000))
    qtbot.wait(50)
    pl = v.plotter
    renders = [0]
    pl.render_window.AddObserver("EndEvent", lambda *_: renders.__setitem__(0, renders[0] + 1))

    def step(action) -> int:
        """Renders done by ``action`` and the Qt paint it causes (waits for that paint)."""
        r0, b0, p0 = renders[0], pl.blit_only_paints, pl.paint_renders
        action()
        qtbot.waitUntil(lambda: pl.blit_only_paints + pl.paint_renders > b0 + p0, timeout=5000)
        qtbot.wait(20)  # a second paint would come now
        return renders[0] - r0

    assert step(pl.render) == 1
    assert step(lambda: v.set_frame(20)) == 1  # a scrub step: the eye moves, one render
    g = v.gl_widget
    at = QPoint(g.width() // 2, g.height() // 2)
    nb = Qt.KeyboardModifier.NoModifier
    QTest.mousePress(g, Qt.MouseButton.LeftButton, nb, at)
    for k in range(1, 5):
        p0 = pl.paint_renders
        assert step(lambda k=k: QTest.mouseMove(g, at + QPoint(12 * k, 3 * k))) == 1
        assert pl.paint_renders == p0 and v.lod_active  # the paint only blitted the coarse frame just rendered
    assert step(lambda: QTest.mouseRelease(g, Qt.MouseButton.LeftButton, nb, at + QPoint(48, 12))) == 1
    assert not v.lod_active
    np.testing.assert_array_equal(_on_screen(v), _rendered(v))
    qtbot.wait(20)
    # the scene changed after the last render and before the paint (pyvista does that): the paint renders
    before = _on_screen(v)

    def render_then_turn() -> None:
        pl.render()
        pl.camera.azimuth += 40.0

    p0 = pl.paint_renders
    assert step(render_then_turn) == 2 and pl.paint_renders == p0 + 1
    now = _on_screen(v)
    assert np.abs(now.astype(int) - before).mean() > 1.0  # it did turn on screen
    np.testing.assert_array_equal(now, _rendered(v))
    # a resize and an exposure after another window covered the view: the current picture, not black or stale
    v.resize(700, 450)
    qtbot.waitUntil(lambda: _on_screen(v).shape == _rendered(v).shape, timeout=5000)
    qtbot.wait(50)
    np.testing.assert_array_equal(_on_screen(v), _rendered(v))
    cover = QWidget()
    qtbot.addWidget(cover)
    cover.setStyleSheet("background: black")
    cover.setGeometry(v.window().geometry())
    cover.show()
    cover.raise_()
    qtbot.wait(100)
    cover.hide()
    v.window().raise_()
    qtbot.wait(100)
    shown = _on_screen(v)
    assert shown.mean() > 100  # not black: the view's background is light
    np.testing.assert_array_equal(shown, _rendered(v))
