"""The job's supports (shafts, chuck, tailstock of [machine.setup]) in the real 3D view (issue 15) -
needs OpenGL: run under xvfb with QT_QPA_PLATFORM=xcb (see tests/test_gui_gl.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.job import build_mandrel, load_job
from engine.machine_setup import support_obstacles

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]


def test_supports_are_drawn_where_the_set_up_puts_them(qtbot) -> None:
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.main_window import MainWindow

    path = ROOT / "resources/examples/pressure_vessel.toml"
    w = MainWindow(path)
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        job = load_job(path)
        obs = support_obstacles(build_mandrel(job), job.machine.setup)
        w.view3d.set_supports([(o.name, o.z0, o.z1, o.radius) for o in obs])
        for o in obs:
            actor = w.view3d.plotter.actors[f"support:{o.name}"]
            pts = np.asarray(actor.mapper.dataset.points)
            # the view frame's x axis is the mandrel axis: the cylinder spans z0..z1 at radius r
            assert pts[:, 0].min() == pytest.approx(o.z0, abs=1e-3) and pts[:, 0].max() == pytest.approx(o.z1, abs=1e-3)
            assert np.hypot(pts[:, 1], pts[:, 2]).max() == pytest.approx(o.radius, rel=1e-3)
        w.view3d.set_supports([])
        assert not [n for n in w.view3d.plotter.actors if str(n).startswith("support:")]
    finally:
        w.close()
