"""GUI tests of the main window (pytest-qt, offscreen): open each example, edit, save, reload.

Assertions are on data: the job document, the plotted curves, the panel's messages.  The real 3D
view is tested in ``test_gui_gl.py`` (marker ``gl``, under xvfb).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from gui_helpers import close_window, shown_window
from PySide6.QtCore import QEvent, QPoint, QPointF, Qt
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import QApplication, QMessageBox

from engine import __version__
from engine.job import PointsSpec, VesselSpec, build_mandrel, load_job
from winder_gui.main_window import MainWindow

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted(
    p for p in (ROOT / "resources" / "examples").glob("*.toml") if "mandrel" in tomllib.loads(p.read_text("utf-8"))
)  # every example job (files there without a [mandrel] table are inputs of other tools)


@pytest.fixture
def window(qtbot):
    w = shown_window(qtbot)
    yield w
    close_window(w)


def _open(w: MainWindow, path: Path) -> None:
    w.open_job(path)
    assert w.wait_idle()


def _curve(w: MainWindow) -> tuple[np.ndarray, np.ndarray]:
    return w.plot.curve_data()


# ------------------------------------------------------------------------------------------------
def test_new_window_shows_default_job(window) -> None:
    w = window
    assert w.job.name == "untitled" and w.job_path is None and not w.dirty
    assert "untitled" in w.windowTitle() and "*" not in w.windowTitle()
    # default job: hemispherical vessel R 100, cylinder 300, poles 30 (engine.job.default_job)
    z, r = _curve(w)
    assert r.max() == pytest.approx(100.0)
    cyl = (z > 1.0) & (z < 299.0)
    np.testing.assert_allclose(r[cyl], 100.0, atol=1e-9)
    dome = z < 0
    np.testing.assert_allclose(r[dome], np.sqrt(100.0**2 - z[dome] ** 2), rtol=1e-9)  # the hemisphere
    assert r[0] == pytest.approx(30.0) and r[-1] == pytest.approx(30.0)
    assert w.steps.available() == ["mandrel", "winding", "payout", "machine", "timelaw", "nc"]
    assert w.steps.current_step() == "mandrel"
    menus = {a.text().replace("&", "") for m in (w.menu_file, w.menu_tools, w.menu_help) for a in m.actions()}
    for name in ("New", "Open…", "Save", "Save As…", "Import generatrix…", "Export mandrel…", "Quit",
                 "Turning optimiser…", "Slot forming…", "About winder"):
        assert name in menus
    assert w.view3d.backend == "placeholder"  # offscreen: no VTK (pyvistaqt#351)


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.stem)
def test_example_load_edit_save_reload(window, tmp_path, example: Path) -> None:
    w = window
    _open(w, example)
    assert w.last_error == ""
    expected_job = load_job(example)
    assert w.job == expected_job and w.job_path == example and not w.dirty
    assert expected_job.name in w.windowTitle()

    # the plot shows this job's mandrel, sampled independently here
    z, r = _curve(w)
    m = build_mandrel(expected_job, example)
    assert z[0] == pytest.approx(m.z_min) and z[-1] == pytest.approx(m.z_max)
    np.testing.assert_allclose(r, m.r(z), rtol=1e-12)
    assert w.view_data is not None
    assert [tuple(zn) for zn in w.view_data.concave] == [(zn.z_from, zn.z_to) for zn in m.concave_zones()]
    assert w.mandrel_panel.current_kind() == expected_job.mandrel.kind

    # drag a handle up by 5 mm: the template becomes a sketch through the moved point
    hz, hr = w.plot.editor.committed_points()
    i = len(hz) // 2
    assert w.plot.editor.move_point(i, hz[i], hr[i] + 5.0) is None
    assert w.wait_idle()
    spec = w.job.mandrel
    assert isinstance(spec, PointsSpec)
    assert spec.z_mm[i] == pytest.approx(hz[i]) and spec.r_mm[i] == pytest.approx(hr[i] + 5.0)
    np.testing.assert_allclose(spec.r_mm[:i], hr[:i])
    z2, r2 = _curve(w)
    assert float(w.mandrel.r(hz[i])) == pytest.approx(hr[i] + 5.0, abs=1e-9)  # the spline interpolates it
    np.testing.assert_allclose(r2, w.mandrel.r(z2), rtol=1e-12)  # and the plot shows that spline
    assert np.interp(hz[i], z2, r2) == pytest.approx(hr[i] + 5.0, abs=0.05)
    assert w.dirty and "*" in w.windowTitle()
    assert '"points"' in w.status_msg.text()
    assert w.mandrel_panel.current_kind() == "points"
    assert w.job.band == expected_job.band and w.job.winding == expected_job.winding  # the rest is untouched

    # save and reload
    out = tmp_path / "edited.toml"
    assert w.save_job(out)
    assert not w.dirty and "*" not in w.windowTitle() and w.job_path == out
    assert load_job(out) == w.job
    saved_curve = _curve(w)
    _open(w, example)
    assert w.job == expected_job
    _open(w, out)
    assert w.job == load_job(out) and not w.dirty
    np.testing.assert_allclose(_curve(w)[1], saved_curve[1], rtol=1e-12)


def test_template_field_edit_updates_job_and_views(window, qtbot) -> None:
    w = window
    _open(w, ROOT / "resources/examples/pressure_vessel.toml")
    panel = w.mandrel_panel
    assert panel.editor("radius_mm").isEnabled()
    assert panel.editor("pole_radius_mm.1").text() == "40"
    with qtbot.waitSignal(w.mandrel_updated, timeout=10000):
        panel.set_value("radius_mm", 120)
    assert w.job.mandrel == load_job(ROOT / "resources/examples/pressure_vessel.toml").mandrel.model_copy(
        update={"radius_mm": 120.0})
    z, r = _curve(w)
    assert r.max() == pytest.approx(120.0)
    assert w.dirty

    # typing an invalid value: a message at the field, nothing applied
    before = w.job
    panel.editor("cylinder_length_mm").setText("abc")
    panel._on_edited("vessel")
    assert "not a number" in panel.error_text("cylinder_length_mm")
    panel.set_value("pole_radius_mm.0", 130)
    assert "smaller than the radius" in panel.error_text("pole_radius_mm.0")
    assert not w.ctl.edit_timer.isActive()
    assert w.job == before

    # a value only the engine rejects (isotensoid pole below 2 % of R): message at the field, job kept
    panel.set_value("cylinder_length_mm", 300)
    panel.set_value("pole_radius_mm.0", 1.0)
    assert w.wait_idle()
    assert "isotensoid" in panel.error_text("pole_radius_mm.0")
    assert w.job == before
    assert "Not applied" in w.status_msg.text()


def test_edits_are_debounced(window, qtbot) -> None:
    w = window
    builds: list[object] = []
    w.mandrel_updated.connect(builds.append)
    for rad in (101, 102, 103, 104, 105):
        w.mandrel_panel.set_value("radius_mm", rad)
    assert w.ctl.edit_timer.isActive() and not w.runner.is_busy()  # nothing built on the GUI thread yet
    qtbot.waitUntil(lambda: len(builds) == 1, timeout=10000)
    assert w.wait_idle()
    assert len(builds) == 1 and w.job.mandrel.radius_mm == 105.0


def test_kind_change_enables_its_fields(window) -> None:
    w = window
    panel = w.mandrel_panel
    panel.kind_combo.setCurrentIndex(panel.kind_combo.findData("cone"))
    panel._on_kind_activated(panel.kind_combo.currentIndex())
    assert panel.editor("r0_mm", "cone").isEnabled()
    assert not panel.editor("radius_mm", "vessel").isEnabled()
    assert w.wait_idle()
    assert w.job.mandrel.kind == "cone"
    z, r = _curve(w)
    spec = w.job.mandrel
    np.testing.assert_allclose(r, spec.r0_mm + (spec.r1_mm - spec.r0_mm) * z / spec.length_mm, rtol=1e-12)
    panel.set_value("r1_mm", 20)
    assert w.wait_idle()
    assert w.job.mandrel.r1_mm == 20.0 and _curve(w)[1][-1] == pytest.approx(20.0)
    # dome ratio fields follow the dome kind
    panel.kind_combo.setCurrentIndex(panel.kind_combo.findData("vessel"))
    panel._on_kind_activated(panel.kind_combo.currentIndex())
    assert w.wait_idle()
    assert not panel.editor("dome_ratio.0").isEnabled()
    panel.set_value("dome.0", "ellipse")
    assert panel.editor("dome_ratio.0").isEnabled()
    assert w.wait_idle()
    assert w.job.mandrel.dome == ("ellipse", "hemisphere")


def test_invalid_point_edits_are_red_and_not_applied(window) -> None:
    w = window
    ed = w.plot.editor
    hz, hr = ed.committed_points()
    before = w.job
    # while dragging: the bad point turns red and the message shows
    msg = ed.move_point(3, hz[1] - 1.0, hr[3], finish=False)
    assert msg is not None and "z must increase" in msg
    assert ed._bad is not None and w.plot.message_label.isVisible()
    assert "z must increase" in w.plot.message_label.text()
    # released there: not applied, the points go back
    assert ed.move_point(3, hz[1] - 1.0, hr[3]) is not None
    np.testing.assert_array_equal(ed.current_points()[0], hz)
    assert "Not applied" in w.plot.message_label.text()
    assert ed.move_point(5, hz[5], -2.0) is not None
    assert "radius must be > 0" in w.plot.message_label.text()
    assert w.wait_idle()
    assert w.job == before and not w.dirty


def test_add_and_delete_points(window) -> None:
    w = window
    _open(w, ROOT / "resources/examples/pipe.toml")
    ed = w.plot.editor
    w.mandrel_panel.kind_combo.setCurrentIndex(w.mandrel_panel.kind_combo.findData("points"))
    w.mandrel_panel._on_kind_activated(0)
    assert w.wait_idle()
    assert w.job.mandrel.kind == "points"
    n = len(w.job.mandrel.z_mm)
    z0, z1 = w.job.mandrel.z_mm[2], w.job.mandrel.z_mm[3]
    assert ed.add_point(0.5 * (z0 + z1), 80.0) is None
    assert w.wait_idle()
    assert len(w.job.mandrel.z_mm) == n + 1 and w.job.mandrel.r_mm[3] == 80.0
    assert ed.delete_point(3) is None
    assert w.wait_idle()
    assert len(w.job.mandrel.z_mm) == n
    # down to 4 points is fine, 3 is refused
    while len(ed.committed_points()[0]) > 4:
        assert ed.delete_point(1) is None
    assert w.wait_idle() and len(w.job.mandrel.z_mm) == 4
    assert ed.delete_point(1) is not None
    assert w.wait_idle() and len(w.job.mandrel.z_mm) == 4


def _scene_to_widget(w: MainWindow, z: float, r: float) -> QPoint:
    vb = w.plot.plot_r.getViewBox()
    scene = vb.mapViewToScene(QPointF(z, r))
    return w.plot.graphics.mapFromScene(scene)


def _mouse(w: MainWindow, kind: QEvent.Type, pos: QPoint, button: Qt.MouseButton, buttons: Qt.MouseButton) -> None:
    """Deliver one mouse event to the plot's viewport (as the window system would)."""
    vp = w.plot.graphics.viewport()
    p = QPointF(pos)
    QApplication.sendEvent(vp, QMouseEvent(kind, p, vp.mapToGlobal(p), button, buttons, Qt.KeyboardModifier.NoModifier))


LEFT, RIGHT, NONE = Qt.MouseButton.LeftButton, Qt.MouseButton.RightButton, Qt.MouseButton.NoButton


def _click(w: MainWindow, pos: QPoint, button: Qt.MouseButton, double: bool = False) -> None:
    _mouse(w, QEvent.Type.MouseButtonPress, pos, button, button)
    _mouse(w, QEvent.Type.MouseButtonRelease, pos, button, NONE)
    if double:
        _mouse(w, QEvent.Type.MouseButtonDblClick, pos, button, button)
        _mouse(w, QEvent.Type.MouseButtonRelease, pos, button, NONE)


def test_mouse_edits_on_the_plot(window, qtbot) -> None:
    w = window
    qtbot.wait(20)
    ed = w.plot.editor
    hz, hr = ed.committed_points()
    # right-click a point: deleted (the template becomes a sketch)
    i = len(hz) // 2
    _click(w, _scene_to_widget(w, hz[i], hr[i]), RIGHT)
    assert w.wait_idle()
    assert isinstance(w.job.mandrel, PointsSpec) and len(w.job.mandrel.z_mm) == len(hz) - 1
    assert hz[i] not in w.job.mandrel.z_mm
    # double-click empty space: a point is added there
    zn = 0.5 * (hz[i] + hz[i + 1])
    _click(w, _scene_to_widget(w, zn, 80.0), LEFT, double=True)
    assert w.wait_idle()
    spec = w.job.mandrel
    assert len(spec.z_mm) == len(hz)
    k = int(np.argmin(np.abs(np.asarray(spec.z_mm) - zn)))
    assert spec.z_mm[k] == pytest.approx(zn, abs=2.0) and spec.r_mm[k] == pytest.approx(80.0, abs=1.0)
    # click selects it, the Delete key removes it
    _click(w, _scene_to_widget(w, spec.z_mm[k], spec.r_mm[k]), LEFT)
    assert ed.selected_index == k
    w.plot.graphics.setFocus()
    qtbot.keyClick(w.plot.graphics, Qt.Key.Key_Delete)
    assert w.wait_idle()
    assert len(w.job.mandrel.z_mm) == len(hz) - 1 and spec.z_mm[k] not in w.job.mandrel.z_mm


def test_mouse_drag_moves_a_point(window, qtbot) -> None:
    w = window
    qtbot.wait(20)
    hz, hr = w.plot.editor.committed_points()
    i = len(hz) // 2
    a = _scene_to_widget(w, hz[i], hr[i])
    b = _scene_to_widget(w, hz[i], hr[i] - 20.0)
    _mouse(w, QEvent.Type.MouseButtonPress, a, LEFT, LEFT)
    for t in np.linspace(0.0, 1.0, 6)[1:]:
        time.sleep(0.03)  # pyqtgraph drops mouse moves that come faster than the screen refresh
        _mouse(w, QEvent.Type.MouseMove, QPoint(a.x(), int(round(a.y() + t * (b.y() - a.y())))), NONE, LEFT)
    _mouse(w, QEvent.Type.MouseButtonRelease, b, LEFT, NONE)
    assert w.wait_idle()
    spec = w.job.mandrel
    assert isinstance(spec, PointsSpec)
    assert spec.z_mm[i] == pytest.approx(hz[i], abs=1.0)
    assert spec.r_mm[i] == pytest.approx(hr[i] - 20.0, abs=1.0)
    assert '"points"' in w.status_msg.text()


# ------------------------------------------------------------------------------------------------
BAD_JOBS = {
    "missing_field": ("schema_version = 1\nname = 'x'\n[mandrel]\nkind = 'pipe'\nlength_mm = 100.0\n",
                      "mandrel.radius_mm", "Line: 3"),
    "mistyped_field": ("schema_version = 1\nname = 'x'\n[mandrel]\nkind = 'pipe'\nradius_mmm = 5.0\n"
                       "length_mm = 100.0\n", "mandrel.radius_mmm", "Line: 5"),
    "bad_value": ("schema_version = 1\n[mandrel]\nkind = 'pipe'\nradius_mm = -5.0\nlength_mm = 100.0\n",
                  "mandrel.radius_mm", "Line: 4"),
    "not_toml": ("schema_version = 1\n[mandrel\nkind = 'pipe'\n", "", "Line: 2"),
    "engine_rejects": ("[mandrel]\nkind = 'vessel'\nradius_mm = 100.0\ncylinder_length_mm = 100.0\n"
                       "dome = 'isotensoid'\npole_radius_mm = 1.0\n", "mandrel.pole_radius_mm", "Line: 6"),
}


@pytest.mark.parametrize("case", sorted(BAD_JOBS))
def test_bad_job_file_shows_place_and_keeps_job(window, tmp_path, case: str) -> None:
    w = window
    _open(w, ROOT / "resources/examples/pipe.toml")
    w.mandrel_panel.set_value("radius_mm", 80)  # unsaved work
    assert w.wait_idle() and w.dirty
    before, before_curve, title = w.job, _curve(w), w.windowTitle()
    text, field, line = BAD_JOBS[case]
    bad = tmp_path / f"{case}.toml"
    bad.write_text(text, encoding="utf-8")
    _open(w, bad)
    assert w.error_box is not None and w.error_box.isVisible()
    shown = w.error_box.text()
    assert str(bad) in shown and line in shown and (not field or f"Field: {field}" in shown)
    assert "Traceback" not in shown
    assert w.job == before and w.dirty and w.windowTitle() == title
    np.testing.assert_array_equal(_curve(w)[1], before_curve[1])
    assert w.mandrel_panel.editor("radius_mm").text() == "80"
    assert bad.read_text(encoding="utf-8") == text  # never rewritten


def test_missing_job_file(window, tmp_path) -> None:
    w = window
    before = w.job
    _open(w, tmp_path / "nope.toml")
    assert "file not found" in w.error_box.text() and "nope.toml" in w.error_box.text()
    assert w.job == before


def test_bad_import_keeps_job(window, tmp_path) -> None:
    w = window
    before = w.job
    csv = tmp_path / "profile.csv"
    csv.write_text("z,r\n0,50\n10,52\n5,53\n20,50\n30,48\n", encoding="utf-8")
    w.import_generatrix(csv)
    assert w.wait_idle()
    shown = w.error_box.text()
    assert "profile.csv" in shown and "Line: 4" in shown
    assert w.job == before and not w.dirty
    w.error_box.close()
    w.import_generatrix(tmp_path / "profile.xyz")
    assert ".csv" in w.error_box.text() and w.job == before


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("empty.csv", b""),
        ("text.csv", b"z,r\n0,50\n10,abc\n20,50\n30,50\n"),
        ("garbage.dxf", b"this is not a drawing\n"),
        ("garbage.step", b"ISO-10303-21;\nnot really\n"),
        ("binary.csv", bytes(range(256))),
    ],
)
def test_bad_profile_files_show_a_dialog(window, tmp_path, name: str, content: bytes) -> None:
    w = window
    _open(w, ROOT / "resources/examples/bottle.toml")
    before, curve = w.job, _curve(w)[1]
    f = tmp_path / name
    f.write_bytes(content)
    w.import_generatrix(f)
    assert w.wait_idle(60000)
    shown = w.error_box.text()
    assert name in shown and "Traceback" not in shown and "Internal error" not in shown
    assert w.job == before and not w.dirty
    np.testing.assert_array_equal(_curve(w)[1], curve)
    assert w.mandrel_panel.current_kind() == "bottle"
    assert f.read_bytes() == content


def test_good_import_then_save_keeps_relative_path(window, tmp_path) -> None:
    w = window
    csv = tmp_path / "data" / "profile.csv"
    csv.parent.mkdir()
    zs = np.linspace(0.0, 200.0, 21)
    rs = 50.0 + 10.0 * np.sin(zs / 200.0 * np.pi)
    csv.write_text("z,r\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(zs, rs)), encoding="utf-8")
    w.import_generatrix(csv)
    assert w.wait_idle() and w.last_error == ""
    assert w.job.mandrel.kind == "file" and w.dirty
    z, r = _curve(w)
    np.testing.assert_allclose(np.interp(zs, z, r), rs, atol=1e-9)
    out = tmp_path / "jobs" / "job.toml"
    out.parent.mkdir()
    assert w.save_job(out)
    assert load_job(out).mandrel.path == "../data/profile.csv"
    _open(w, out)
    assert w.last_error == "" and w.job.mandrel.path == "../data/profile.csv"
    np.testing.assert_allclose(_curve(w)[1], r, rtol=1e-12)


def test_failed_save_reports_and_keeps_dirty(window, tmp_path) -> None:
    w = window
    w.mandrel_panel.set_value("radius_mm", 90)
    assert w.wait_idle() and w.dirty
    target = tmp_path / "no_such_dir" / "job.toml"
    assert not w.save_job(target)
    assert not target.exists() and w.dirty and w.error_box is not None
    assert "job.toml" in w.error_box.text() or "no_such_dir" in w.error_box.text()
    assert list(tmp_path.iterdir()) == []  # no half-written file anywhere


def test_close_prompt(window, monkeypatch) -> None:
    w = window
    w.mandrel_panel.set_value("radius_mm", 90)
    assert w.wait_idle() and w.dirty
    asked: list[str] = []

    def cancel(*args, **kwargs):
        asked.append(args[1])
        return QMessageBox.StandardButton.Cancel

    monkeypatch.setattr(QMessageBox, "question", cancel)
    w.confirm_discard = True
    assert not w.close()
    assert asked == ["Unsaved changes"] and w.isVisible()
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.StandardButton.Discard)
    assert w.close()


def test_env_var_skips_prompt(qtbot, monkeypatch) -> None:
    monkeypatch.setenv("WINDER_NO_PROMPT", "1")
    w = MainWindow()
    qtbot.addWidget(w)
    assert w.wait_idle()
    assert not w.confirm_discard
    w.set_dirty(True)
    assert w.close()


def test_tools_and_about(window) -> None:
    w = window
    assert w.open_tool("x", "winder_gui.dialogs.no_such_dialog", "NoDialog") is None
    assert "NoDialog could not be loaded" in w.error_box.text()
    w.error_box.close()
    w.actions["about"].trigger()
    assert __version__ in w.dialogs["about"].text()


def test_export_mandrel(window, tmp_path) -> None:
    w = window
    out = tmp_path / "m.stl"
    w.export_mandrel(out)
    assert w.wait_idle(120000)
    assert w.last_error == "" and out.stat().st_size > 1000
    assert str(out) in w.status_msg.text()


def test_offscreen_placeholder_tracks_data(window) -> None:
    w = window
    assert w.view3d.backend == "placeholder"
    assert w.view3d.data is w.view_data
    assert "601" in w.view3d._label.text() or "×" in w.view3d._label.text()


def test_selftest_launch() -> None:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", WINDER_QUIT_WHEN_SHOWN="ready")
    proc = subprocess.run([sys.executable, "-m", "engine", "resources/examples/pressure_vessel.toml"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "window shown after" in proc.stderr and "mandrel shown after" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_vessel_spec_round_trip_through_panel(window) -> None:
    w = window
    spec = VesselSpec(radius_mm=80.0, cylinder_length_mm=0.0, dome=("hemisphere", "ellipse"), dome_ratio=(1.0, 0.5),
                      pole_radius_mm=(10.0, 20.0))
    w.mandrel_panel.set_spec(spec)
    w.mandrel_panel.set_value("radius_mm", 80.0)
    assert w.wait_idle()
    assert w.job.mandrel == spec
