"""Screens an engineer reads all day: every step of every machine template at 1280×800 and 1920×1080.

For each template (pipe.toml on it; robot_cell with the csv post, the only one that addresses its
axes), after a run: no label, button or field overlaps another (bounding boxes of the visible
widgets, clipped by their scroll areas), the machine schematic's labels do not overlap, every plot's
data area is at least :data:`winder_gui.views.plots.MIN_PLOT_PX` high, and the eye trajectory and the
mandrel lie inside the 3D viewport.  Needs a real display: run under xvfb-run with QT_QPA_PLATFORM=xcb.

Screenshots go to $WINDER_SCREENSHOTS/screens (else a temporary folder): one per template, size and step.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
SHOTS_DIR = Path(os.environ.get("WINDER_SCREENSHOTS") or tempfile.mkdtemp(prefix="winder-screens-")) / "screens"
TEMPLATES = ("lathe2", "lathe3", "lathe4", "gantry6", "robot_cell")
SIZES = ((1280, 800), (1920, 1080))
STEPS = ("mandrel", "winding", "payout", "machine", "timelaw", "nc")


def _visible_rect(w, top):
    """``w``'s rectangle in ``top``'s coordinates, clipped by every ancestor (scroll areas); None if hidden."""
    from PySide6.QtCore import QPoint, QRect

    if not w.isVisibleTo(top) or w.width() <= 0 or w.height() <= 0:
        return None
    r = QRect(w.mapTo(top, QPoint(0, 0)), w.size())
    p = w.parentWidget()
    while p is not None and p is not top:
        r = r.intersected(QRect(p.mapTo(top, QPoint(0, 0)), p.size()))
        p = p.parentWidget()
    return r if r.width() > 1 and r.height() > 1 else None


def overlapping_widgets(top) -> list[tuple[str, str]]:
    """Pairs of visible labels/buttons/fields of ``top`` whose boxes overlap (none is inside the other's
    widget tree; item views' own editors are not counted)."""
    from PySide6.QtWidgets import (
        QAbstractButton,
        QAbstractItemView,
        QAbstractSpinBox,
        QComboBox,
        QLabel,
        QLineEdit,
    )

    kinds = (QLabel, QAbstractButton, QLineEdit, QComboBox, QAbstractSpinBox)
    items = []
    for w in top.findChildren(QWidget_base()):
        if not isinstance(w, kinds):
            continue
        if isinstance(w, QLabel) and not (w.text() or w.pixmap() is not None and not w.pixmap().isNull()):
            continue
        p, skip = w.parentWidget(), False
        while p is not None:
            if isinstance(p, QAbstractItemView | QComboBox | QAbstractSpinBox):
                skip = True  # a cell editor, a combo's own line edit
                break
            p = p.parentWidget()
        if skip:
            continue
        r = _visible_rect(w, top)
        if r is not None:
            items.append((w, r))
    bad = []
    for i, (a, ra) in enumerate(items):
        for b, rb in items[i + 1:]:
            if a.isAncestorOf(b) or b.isAncestorOf(a):
                continue
            x = ra.intersected(rb)
            if x.width() > 1 and x.height() > 1:
                bad.append((_name(a), _name(b)))
    return bad


def QWidget_base():  # noqa: N802 - a class
    from PySide6.QtWidgets import QWidget

    return QWidget


def _name(w) -> str:
    text = getattr(w, "text", lambda: "")()
    return f"{type(w).__name__}({w.objectName() or text[:30]!r})"


def short_plots(page, least: float) -> list[tuple[str, float]]:
    """Plots of ``page`` whose data area is lower than ``least`` px."""
    out = []
    for name, p in page.plots.items():
        if p.isVisible() and p in page.glw.ci.items:
            h = p.getViewBox().sceneBoundingRect().height()
            if h < least:
                out.append((name, h))
    return out


@pytest.fixture(scope="module")
def qt_display(qapp):
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    return qapp


@pytest.mark.parametrize("template", TEMPLATES)
def test_every_step_is_readable(qt_display, qtbot, template, tmp_path) -> None:
    from winder_gui.main_window import MainWindow
    from winder_gui.views.plots import MIN_PLOT_PX

    w = MainWindow(ROOT / "resources/examples/pipe.toml")
    w.confirm_discard = False
    w.auto_run = False
    qtbot.addWidget(w)
    w.resize(*SIZES[0])
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        if template != w.job.machine.template:
            w.machine_panel.select_template(template)
            assert w.wait_idle()
        if template == "robot_cell":
            w.machine_panel.post_combo.setCurrentText("csv")
            w.machine_panel._on_edited()
        assert w.run_pipeline_now()
        assert w.wait_idle(300000) and w.last_error == "", w.last_error
        problems: list[str] = []
        for size in SIZES:
            w.resize(*size)
            qtbot.wait(200)
            v = w.view3d
            if v.backend == "vtk":
                mandrel = v.scene_points()
                assert v.points_in_view(mandrel).all(), f"{template} {size}: part of the scene outside the 3D view"
                assert v.points_in_view(v.paths.eye_xyz[:: max(1, v.paths.eye_xyz.shape[0] // 400)]).all()
            for step in STEPS:
                w.go_to_step(step)
                qtbot.wait(150)
                for a, b in overlapping_widgets(w):
                    problems.append(f"{size} {step}: {a} overlaps {b}")
                page = w.plot_tabs.currentWidget()
                if hasattr(page, "glw"):
                    for name, h in short_plots(page, MIN_PLOT_PX):
                        problems.append(f"{size} {step}: plot {name} is {h:.0f} px high")
                if step == "machine":
                    rects = list(w.machine_panel.schematic.label_rects.items())
                    for i, (ta, ra) in enumerate(rects):
                        for tb, rb in rects[i + 1:]:
                            if ra.intersects(rb):
                                problems.append(f"{size} schematic: {ta!r} overlaps {tb!r}")
                SHOTS_DIR.mkdir(parents=True, exist_ok=True)
                assert w.screenshot().save(str(SHOTS_DIR / f"{template}_{size[0]}x{size[1]}_{step}.png"))
            for i in range(w.plot_tabs.count()):
                w.plot_tabs.setCurrentIndex(i)
                qtbot.wait(60)
                page = w.plot_tabs.currentWidget()
                if hasattr(page, "glw"):
                    for name, h in short_plots(page, MIN_PLOT_PX):
                        problems.append(f"{size} tab {w.plot_tabs.tabText(i)}: plot {name} is {h:.0f} px high")
        assert not problems, "\n".join(problems)
    finally:
        w.close()


def test_label_placement_keeps_labels_apart() -> None:
    """place_labels: many labels on one point end up without overlaps, inside the bounds."""
    from winder_gui.views.machine_schematic import place_labels

    anchors = [(100.0, 80.0)] * 8 + [(5.0, 5.0), (290.0, 190.0)]
    sizes = [(60.0, 14.0)] * 10
    rects = place_labels(anchors, sizes, [(95.0, 75.0, 10.0, 10.0)], (300.0, 200.0))
    for i, a in enumerate(rects):
        assert 0 <= a[0] and a[0] + a[2] <= 300 and 0 <= a[1] and a[1] + a[3] <= 200
        assert not (a[0] < 105 and 95 < a[0] + a[2] and a[1] < 85 and 75 < a[1] + a[3])  # clear of the obstacle
        for b in rects[i + 1:]:
            assert not (a[0] < b[0] + b[2] and b[0] < a[0] + a[2] and a[1] < b[1] + b[3] and b[1] < a[1] + a[3])
    # the first label sits right next to its point
    assert np.hypot(rects[0][0] - 100.0, rects[0][1] + 7.0 - 80.0) < 20.0


def test_scrubbing_shows_the_band_laid_up_to_that_time(qt_display, qtbot) -> None:
    """The band of true width is drawn up to the scrubbed time: the band's mesh holds exactly the quads
    wound by then; at the end the whole band, at 0 none."""
    from winder_gui.main_window import MainWindow

    w = MainWindow(ROOT / "resources/examples/pipe.toml")
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.resize(*SIZES[0])
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        assert w.run_pipeline_now() and w.wait_idle(300000) and w.last_error == ""
        v = w.view3d
        band = v.paths.band
        assert band is not None and band.width_mm == w.job.band.width_mm
        assert v.band_quads == band.m - 1  # a new program is shown at its end: the whole band
        for frac in (0.0, 0.37, 0.8):
            t = frac * v.timeline.total_s
            v.set_time(t)
            k = band.quads_until(t)
            assert v.band_quads == k
            a = v.plotter.actors["band"]
            drawn = a.mapper.GetInput().GetNumberOfCells() if a.GetVisibility() else 0
            assert drawn == k == v.band_cells(), (frac, drawn, k)
            # the eye is where the program is at that time
            assert v.timeline.times[v.frame] <= t + 1e-9
        v.set_camera("axis")
        assert v.points_in_view(v.scene_points()[::50]).all()
        v.set_camera("side")
        assert v.points_in_view(v.scene_points()[::50]).all()
        SHOTS_DIR.mkdir(parents=True, exist_ok=True)
        w.screenshot().save(str(SHOTS_DIR / "band_scrubbed.png"))
    finally:
        w.close()


def test_laminate_plays_on_through_its_layers_and_jumps_to_a_layer(qt_display, qtbot) -> None:
    """A layered job (the pipe example: hoop, helical, hoop): the 3D view's layer chooser lists the wound
    layers; a jump shows that layer from its start, the read-out in the whole program's time; played at
    the highest speed the program goes on from layer to layer to the end of the last one, each layer's
    surface, eye path and band framed in the viewport."""
    from winder_gui.main_window import MainWindow
    from winder_gui.views.playback import SPEEDS

    w = MainWindow(ROOT / "resources/examples/pipe.toml")
    w.confirm_discard = False
    w.auto_run = False
    qtbot.addWidget(w)
    w.resize(*SIZES[0])
    w.show()
    try:
        assert w.wait_idle()
        qtbot.waitUntil(lambda: w.view3d.backend != "pending", timeout=30000)
        assert w.run_pipeline_now() and w.wait_idle(300000) and w.last_error == ""
        v, res = w.view3d, w.result
        wound = [lr for lr in res.layers if lr.result is not None and lr.result.line is not None]
        assert [i for i, _l, _t in v.layers] == [lr.index for lr in wound]
        assert [t for _i, _l, t in v.layers] == [lr.t0 for lr in wound]
        assert v.layer_combo.isVisible() and v.layer_combo.count() == len(wound)
        assert v.program_total_s == res.blocks.total
        last = wound[-1]
        v.layer_combo.activated.emit(len(wound) - 1)  # the user picks the last layer
        assert v.layer_index == last.index == w.laminate.shown_layer
        assert w.layers_panel.selected_layer() == last.index and v.time_s == 0.0
        assert v.paths is w.laminate.output.view(last.index).paths
        assert v.frame_label.text().startswith(f"t {last.t0:.1f} / {res.blocks.total:.1f} s")
        v.jump_to_layer(wound[0].index)
        assert v.layer_index == wound[0].index and v.time_s == 0.0 and v.band_quads == 0
        # every layer's scene was made ahead: going from layer to layer swaps kept actors, makes none
        assert v.scene_count("paths") == len(wound) and v.scene_count("surface") == len(wound)
        first = {n: v.plotter.actors[n] for n in ("paths", "band", "mandrel")}
        seen: list[int] = []
        v.layer_requested.connect(seen.append)
        v.set_speed(max(SPEEDS))
        v.play()
        qtbot.waitUntil(lambda: not v.is_playing(), timeout=120000)
        assert seen == [lr.index for lr in wound[1:]]  # on through every layer in winding order
        assert v.layer_index == last.index and v.time_s == v.timeline.total_s
        assert abs(v.program_time_s() - (last.t0 + v.timeline.total_s)) < 1e-9
        assert v.band_quads == v.paths.band.m - 1  # the last layer's band laid whole
        assert v.scene_count("paths") == len(wound)
        v.jump_to_layer(wound[0].index)
        assert all(v.plotter.actors[n] is a for n, a in first.items())
        assert v.plotter.actors["paths"].mapper.GetInput().GetNumberOfPoints() == v.paths.line_xyz.shape[0]
        for lr in wound:  # each layer's surface and eye path framed after a jump
            v.jump_to_layer(lr.index)
            v.frame_all()
            assert v.points_in_view(v.scene_points()[::40]).all(), lr.name
    finally:
        w.close()
