"""The real 3D view (pyvistaqt/VTK) — needs OpenGL: run under xvfb with QT_QPA_PLATFORM=xcb.

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m pytest -m gl tests/test_gui_gl.py

Also saves a screenshot of the main window to docs/screenshots/main_window.png.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.job import build_mandrel, load_job

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
SCREENSHOT = ROOT / "docs" / "screenshots" / "main_window.png"


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

    o = w.view3d.mapTo(w, QPoint(0, 0))
    vw, vh = w.view3d.width(), w.view3d.height()
    top = [img.pixelColor(o.x() + vw - 20 - 40 * k, o.y() + 6) for k in range(5)]
    assert max(c.red() for c in top) - min(c.red() for c in top) <= 3  # no GL garbage
    assert all(c.blue() > c.red() for c in top)  # the bluish-grey background
    mid = img.pixelColor(o.x() + vw // 2, o.y() + vh // 2)
    assert abs(mid.red() - top[0].red()) + abs(mid.green() - top[0].green()) > 20  # the mandrel, not background
