"""The real 3D view (pyvistaqt/VTK) — needs OpenGL: run under xvfb with QT_QPA_PLATFORM=xcb.

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m pytest -m gl tests/test_gui_gl.py

Screenshots go to $WINDER_SCREENSHOTS (e.g. ``WINDER_SCREENSHOTS=docs/screenshots`` to refresh the
README's pictures), else to a temporary folder, so a test run never changes the working tree.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from engine.job import build_mandrel, load_job

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
SHOTS_DIR = Path(os.environ.get("WINDER_SCREENSHOTS") or tempfile.mkdtemp(prefix="winder-shots-"))
SCREENSHOT = SHOTS_DIR / "main_window.png"


@pytest.fixture
def gl_window(qtbot):
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.main_window import MainWindow

    w = MainWindow(ROOT / "resources/examples/pressure_vessel.toml")
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
    yield w
    w.close()


def test_mandrel_in_view_when_a_job_opens(gl_window, qtbot) -> None:
    """The first framing comes before the GL widget is laid out (0 x 0): it waits for the widget's size,
    so the whole mandrel is in view on opening, not only after a run."""
    v = gl_window.view3d
    pts = v.scene_points()
    assert pts.shape[0] > 0
    qtbot.waitUntil(lambda: not getattr(v, "_frame_pending", False), timeout=10000)
    qtbot.wait(100)
    assert min(v.plotter.render_window.GetSize()) >= 100
    assert v.points_in_view(pts[:: max(1, pts.shape[0] // 500)]).all()


def _radius_and_axis(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return points[:, 0], np.hypot(points[:, 1], points[:, 2])


def test_3d_view_shows_the_revolved_mandrel(gl_window, qtbot) -> None:
    w = gl_window
    assert w.view3d.backend == "vtk"
    pts = w.view3d.mesh_points()
    assert pts is not None
    job = load_job(ROOT / "resources/examples/pressure_vessel.toml")
    m = build_mandrel(job)
    x, rad = _radius_and_axis(pts)
    # the surface is the generatrix revolved about the x axis: radius at every point = r(z)
    assert x.min() == pytest.approx(m.z_min, abs=1e-4) and x.max() == pytest.approx(m.z_max, abs=1e-4)
    np.testing.assert_allclose(rad, m.r(x), atol=1e-3)  # VTK stores float32 points
    # angles cover the full turn
    ang = np.degrees(np.arctan2(pts[:, 2], pts[:, 1])) % 360.0
    steps = np.unique(np.round(ang[rad > 1.0]) % 360.0)
    assert len(steps) == 72 and np.diff(steps).max() == pytest.approx(5.0)

    # an edit updates the 3D surface too
    w.mandrel_panel.set_value("radius_mm", 120)
    assert w.wait_idle()
    x, rad = _radius_and_axis(w.view3d.mesh_points())
    assert rad.max() == pytest.approx(120.0)

    # screenshot for the docs (the VTK widget is drawn by GL: compose it into the window grab)
    w.mandrel_panel.set_value("radius_mm", 100)
    assert w.wait_idle()
    qtbot.wait(300)
    img = w.screenshot()
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    assert img.save(str(SCREENSHOT))
    assert img.width() >= 1000 and img.height() >= 600
    # the 3D area holds the rendered scene: a smooth background gradient at the top, the mandrel in the middle
    from PySide6.QtCore import QPoint

    o = w.view3d.gl_widget.mapTo(w, QPoint(0, 0))
    vw, vh = w.view3d.gl_widget.width(), w.view3d.gl_widget.height()
    top = [img.pixelColor(o.x() + vw - 20 - 40 * k, o.y() + 6) for k in range(5)]
    assert max(c.red() for c in top) - min(c.red() for c in top) <= 3  # no GL garbage
    assert all(c.blue() > c.red() for c in top)  # the bluish-grey background
    mid = img.pixelColor(o.x() + vw // 2, o.y() + vh // 2)
    assert abs(mid.red() - top[0].red()) + abs(mid.green() - top[0].green()) > 20  # the mandrel, not background


STEP_SHOTS = SHOTS_DIR


def test_workflow_3d_paths_and_step_screenshots(qtbot) -> None:
    """Run the vessel, check the drawn paths/eye/fibre against the engine, grab each step."""
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.main_window import MainWindow
    from winder_gui.views.geometry import to_view

    w = MainWindow(ROOT / "resources/examples/pressure_vessel.toml")
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.resize(1500, 940)
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        assert w.view3d.backend == "vtk"
        assert w.run_pipeline_now()
        assert w.wait_idle(300000) and w.last_error == ""
        w.compute_timelaw()
        assert w.wait_idle(300000) and w.last_error == ""
        v = w.view3d
        p = v.paths
        # framed after the run: the (grown) mandrel and the whole eye path of the layer shown inside the view
        assert v.points_in_view(v.scene_points()[::20]).all()
        np.testing.assert_allclose(v.actor_points("paths"), p.line_xyz, rtol=1e-5, atol=1e-3)  # float32 in VTK
        # the example is a laminate: the 3D view shows the selected layer's own single-line result
        shown = w.laminate.shown_result() if hasattr(w.result, "layup") else w.result
        assert shown is not None and p.n_line == shown.line.z.size
        eye = shown.eye
        v.set_frame(100)
        e, c = v.eye_at_frame()
        np.testing.assert_array_equal(e, to_view(eye.eye_xyz[p.frame_index[100:101]])[0])
        fib = v.actor_points("fibre")
        np.testing.assert_allclose(fib[[0, -1]], [c, e], rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(v.actor_points("eye_path"), v.trail(), rtol=1e-5, atol=1e-3)
        sphere = v.actor_points("eye")
        np.testing.assert_allclose(sphere.mean(axis=0), e, atol=1e-2 * max(1.0, float(np.abs(e).max())))
        v.set_colour_by("winding angle β [deg]")
        sc = np.asarray(v.plotter.actors["paths"].mapper.dataset.point_data["c"])
        np.testing.assert_allclose(sc, np.degrees(shown.line.beta[p.line_index]), rtol=1e-6)
        v.set_frame(p.frame_index.size // 3)
        STEP_SHOTS.mkdir(parents=True, exist_ok=True)
        for i, key in enumerate(("mandrel", "winding", "payout", "machine", "timelaw", "nc")):
            w.go_to_step(key)
            if key == "payout":
                w.plot_tabs.setCurrentWidget(w.pull_plot)
            qtbot.wait(400)
            img = w.screenshot()
            assert img.save(str(STEP_SHOTS / f"step{i + 1}_{key}.png"))
        w.plot_tabs.setCurrentWidget(w.coverage_plot)
        qtbot.wait(300)
        assert w.screenshot().save(str(STEP_SHOTS / "coverage.png"))
        w.plot_tabs.setCurrentWidget(w.eye_plot)
        qtbot.wait(300)
        assert w.screenshot().save(str(STEP_SHOTS / "eye_path.png"))
    finally:
        w.wait_idle(60000)
        w.close()


def test_each_layer_on_its_own_grown_surface(qtbot) -> None:
    """The laminate: selecting a layer draws the surface it was wound on (the mandrel grown by the layers
    before it) and its line lying on that surface; screenshot of the laminate tab."""
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.main_window import MainWindow

    w = MainWindow(ROOT / "resources/examples/pipe.toml")
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.resize(1500, 940)
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        assert w.view3d.backend == "vtk"
        assert w.run_pipeline_now() and w.wait_idle(300000) and w.last_error == ""
        res = w.result
        w.go_to_step("winding")
        radii = []
        for lr in res.layers:
            w.layers_panel.select_layer(lr.index)
            qtbot.wait(100)
            x, rad = _radius_and_axis(w.view3d.mesh_points())
            np.testing.assert_allclose(rad, lr.surface.r(x), atol=2e-3)  # its own grown mandrel (float32)
            pts = w.view3d.actor_points("paths")
            lx, lrad = _radius_and_axis(pts)
            p = w.view3d.paths
            np.testing.assert_allclose(lrad, lr.surface.r(lx) + p.lift, atol=2e-3)  # its line on it
            radii.append(float(rad.max()))
        assert radii == sorted(radii) and radii[-1] > radii[0]  # the surface grows layer by layer
        assert w.plot_tabs.currentWidget() is w.laminate_plot
        qtbot.wait(300)
        STEP_SHOTS.mkdir(parents=True, exist_ok=True)
        assert w.screenshot().save(str(STEP_SHOTS / "laminate.png"))
    finally:
        w.wait_idle(60000)
        w.close()
