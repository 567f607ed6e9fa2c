"""GUI tests of the whole winding workflow (issue 9), pytest-qt, offscreen.

Open → edit the mandrel → run → cancel → re-run → every plot → export NC → save and reopen, on the
pipe example (fast) in detail and once on every example.  Assertions are on the data shown: each
plot item holds the engine result's arrays, and independent checks (closed forms, the job file)
say that those arrays are the right ones.

This is the single-line workflow: the examples are laminates (schema 2), so each is used here as its
first helical layer folded into ``[winding]`` and ``[band]`` (:func:`single_line`); the laminate in the
window is tested in test_gui_layers.py.
"""

from __future__ import annotations

import atexit
import csv
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest
from gui_helpers import close_window, shown_window
from PySide6.QtWidgets import QMessageBox

from engine.job import build_mandrel, effective_band, effective_winding, load_job, save_job
from winder_gui.main_window import AUTOSAVE_HEADER, MainWindow, autosave_origin
from winder_gui.views.geometry import to_view
from winder_gui.views.view3d import MAX_FRAMES, TRAIL_FRAMES
from winder_gui.views.view3d_playback import SLIDER_STEPS_PER_S

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"
JOBS = sorted(p for p in EXAMPLES.glob("*.toml") if "mandrel" in tomllib.loads(p.read_text("utf-8")))


def single_line(example: Path, folder: Path) -> Path:
    """``example`` as a single-line job in ``folder``: its first helical (else polar) layer, with the
    values it inherits or overrides, as the job's ``[winding]`` and ``[band]`` and its only layer."""
    job = load_job(example)
    if not job.is_single_line:
        layers = [lay for _, lay in job.active_layers]
        lay = next((x for x in layers if x.kind == "helical"), None) or next(x for x in layers if x.kind == "polar")
        win = effective_winding(job, lay, build_mandrel(job, example))
        job = job.replace(winding=win.model_dump(), band=effective_band(job, lay).model_dump(),
                          layers=[{"kind": "helical"}])
        assert job.is_single_line
    out = folder / example.name
    folder.mkdir(parents=True, exist_ok=True)
    save_job(job, out)
    return out


_SINGLE = Path(tempfile.mkdtemp(prefix="winder-single-line-"))
atexit.register(shutil.rmtree, _SINGLE, True)
PIPE = single_line(EXAMPLES / "pipe.toml", _SINGLE)


def _window(qtbot, path: Path | None = PIPE) -> MainWindow:
    return shown_window(qtbot, path)


def _close(w: MainWindow) -> None:
    close_window(w, 120000)


@pytest.fixture
def pipe_window(qtbot):
    w = _window(qtbot)
    yield w
    _close(w)


def _run(w: MainWindow) -> None:
    assert w.run_pipeline_now()
    assert w.wait_idle(180000)
    assert w.last_error == "", w.last_error


def _check_views(w: MainWindow) -> None:
    """Every plot, the 3D view and the NC panel show the arrays of ``w.result``."""
    res = w.result
    line, eye1, eye, blocks = res.line, res.eye_circuit, res.eye, res.blocks
    # winding: β, C, λ of the first circuit
    sl = line.circuit_slice(0)
    x, y = w.winding_plots.curve_data("beta")
    np.testing.assert_array_equal(x, line.z[sl])
    np.testing.assert_allclose(y, np.degrees(line.beta[sl]), rtol=1e-15)
    x, y = w.winding_plots.curve_data("C")
    np.testing.assert_array_equal(y, line.C[sl])
    np.testing.assert_allclose(y, line.r[sl] * np.sin(line.beta[sl]), rtol=1e-9, atol=1e-9)  # Clairaut
    _, y = w.winding_plots.curve_data("lam")
    np.testing.assert_array_equal(y, line.lam[sl])
    # eye path Z-R and the mandrel under it
    x, y = w.eye_plot.curve_data("eye")
    np.testing.assert_array_equal(x, eye1.Z)
    np.testing.assert_array_equal(y, eye1.R)
    x, y = w.eye_plot.curve_data("mandrel")
    np.testing.assert_allclose(y, res.mandrel.r(x))
    # pull speed of each law, the job's law being the pipeline's own
    assert w.laws is not None and eye1.law in w.laws
    assert w.laws[eye1.law] is eye1
    for law, e in w.laws.items():
        if isinstance(e, str):
            continue
        x, y = w.pull_plot.curve_data(law)
        np.testing.assert_array_equal(x, e.x_mid)
        np.testing.assert_array_equal(y, e.u)
        # u = dλ/dx of the pulled length, differenced independently
        np.testing.assert_allclose(e.u, np.diff(e.lam_pulled) / np.diff(e.x), rtol=1e-6, atol=1e-9)
    # axes against the program time
    t = np.concatenate([[0.0], np.cumsum(blocks.time)])
    for k, ax in enumerate(res.machine.axes):
        x, y = w.axes_plot.curve_data(f"{ax.name} position")
        np.testing.assert_allclose(x, t)
        np.testing.assert_array_equal(y, blocks.q[:, k])
        x, y = w.axes_plot.curve_data(f"{ax.name} speed")
        np.testing.assert_allclose(y[::2], blocks.delta[:, k] / blocks.time)
        np.testing.assert_allclose(x[::2], t[:-1])
    assert x[-1] == pytest.approx(blocks.total)
    # coverage map: (z, v mod 360°) of the line, broken where v wraps
    x, y = w.coverage_plot.curve_data("coverage")
    step = w.coverage_plot.stride
    ok = np.isfinite(x)
    cov = w.coverage_plot.coverage  # the centre lines on the map's axis: the meridian length m(z)
    np.testing.assert_allclose(x[ok], cov.to_map(line.z[::step]) if cov is not None else line.z[::step], atol=1e-9)
    np.testing.assert_allclose(y[ok], np.mod(np.degrees(line.v[::step]), 360.0))
    # 3D view (placeholder offscreen: the same data, drawn under GL)
    p = w.view3d.paths
    assert p is not None and p.n_line == line.z.size
    np.testing.assert_allclose(np.hypot(p.line_xyz[:, 1], p.line_xyz[:, 2]), line.r[p.line_index] + p.lift, rtol=1e-9)
    np.testing.assert_array_equal(p.line_xyz[:, 0], line.z[p.line_index])
    w.view3d.set_frame(7)
    e_at, c_at = w.view3d.eye_at_frame()
    np.testing.assert_array_equal(e_at, to_view(eye.eye_xyz[p.frame_index[7:8]])[0])
    np.testing.assert_array_equal(c_at, to_view(eye.contact_xyz[p.frame_index[7:8]])[0])
    # NC panel: summary with the program time, the program's first lines, the warnings
    assert f"{blocks.total:.2f} s" in w.nc_panel.summary.text()
    head = w.nc_panel.preview.toPlainText().split("\n")
    assert head[:50] == res.nc_text.splitlines()[:50]
    shown = [w.nc_panel.warnings.item(i).text() for i in range(w.nc_panel.warnings.count())]
    assert shown == (w.run_warnings or ["none"])
    for page in (w.winding_plots, w.eye_plot, w.pull_plot, w.axes_plot, w.coverage_plot):
        assert page.has_data() and page.export_button.isEnabled()


# ------------------------------------------------------------------------------------------------
def test_steps_pages_and_units(pipe_window) -> None:
    w = pipe_window
    assert w.steps.available() == ["mandrel", "winding", "payout", "machine", "timelaw", "nc"]
    for key in ("winding", "payout", "machine", "timelaw", "nc"):
        w.go_to_step(key)
        assert w.properties.currentIndex() == w.step_pages[key]
    # every numeric field says its unit
    for panel in w.section_panels.values():
        for row in panel.rows.values():
            if row.spec.kind in ("float", "int", "angles"):
                assert "[" in row.spec.label and "]" in row.spec.label, row.spec.label
    # the job's values are shown, angles in degrees as the job stores them
    job = load_job(PIPE)
    assert w.winding_panel.editor("winding.dwell_deg.0").text() == "180"
    assert w.winding_panel.editor("winding.angles").text() == "500:55"
    assert w.payout_panel.editor("payout.law").currentText() == job.payout.law
    assert w.machine_panel.template_combo.currentText() == "lathe2"
    menus = {a.text().replace("&", "") for a in w.menuBar().actions()}
    assert {"File", "Edit", "Run", "View", "Tools", "Help"} <= menus
    assert w.actions["run"].shortcut().toString() == "F5"
    assert w.actions["undo"].shortcut().toString() == "Ctrl+Z"
    w.actions["shortcuts"].trigger()
    text = w.dialogs["shortcuts"].text()
    for keys, what in (("F5", "Run pipeline"), ("Ctrl+Z", "Undo"), ("Esc", "Cancel"), ("Space", "Play / pause"),
                       ("Ctrl+3", "3 Payout"), ("Ctrl+Shift+E", "Export NC program")):
        assert f"<b>{keys}" in text and what in text, (keys, what)
    w.dialogs["shortcuts"].close()


def test_pipe_workflow(pipe_window, tmp_path, monkeypatch) -> None:
    w = pipe_window
    w.payout_panel.set_value("payout.law", "parallel")  # the example uses min-range; this test checks R
    assert w.wait_idle() and w.job.payout.law == "parallel"
    # edit the mandrel, then run
    w.mandrel_panel.set_value("radius_mm", 70)
    assert w.wait_idle()
    assert w.job.mandrel.radius_mm == 70.0 and w.dirty
    _run(w)
    res = w.result
    assert res.job == w.job and res.nc_text
    np.testing.assert_allclose(res.line.r, 70.0)  # the edited mandrel was wound
    # parallel law: the eye runs at R = r_max + clearance (PayoutSpec default), independent of the engine
    np.testing.assert_allclose(w.eye_plot.curve_data("eye")[1], 70.0 + w.job.payout.clearance_mm, rtol=1e-9)
    _check_views(w)

    # a payout edit re-runs only the stages downstream of it (debounced auto re-run)
    w.payout_panel.set_value("payout.clearance_mm", 25)
    assert w.job.payout.clearance_mm == 25.0
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.result.reused[:2] == ("mandrel", "winding") and "payout" not in w.result.reused
    np.testing.assert_allclose(w.eye_plot.curve_data("eye")[1], 95.0, rtol=1e-9)
    _check_views(w)

    # the time-law method is read by the blocks stage only: the stages before it are re-used
    assert w.job.timelaw.method == "tube"  # the default: the time law sets the block times
    w.timelaw_panel.set_value("timelaw.method", "blocks")
    assert w.job.timelaw.method == "blocks"
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.result.reused == ("mandrel", "winding", "payout", "axes")
    assert "(17)/(18)" in w.timelaw_panel.program_label.text()
    _check_views(w)
    w.timelaw_panel.set_value("timelaw.method", "tube")
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.result.reused == ("mandrel", "winding", "payout", "axes")
    if isinstance(getattr(w.result, "timelaw", None), dict):
        assert "tube law" in w.timelaw_panel.program_label.text()

    # the progress bar went through the stages up to 100 %
    assert w.progress_bar.value() == 1000 and not w.progress_bar.isVisible()

    # edits in quick succession while a run is in flight: the last edit's run supersedes the others
    assert w.run_pipeline_now()
    w.payout_panel.set_value("payout.clearance_mm", 24)
    w.payout_panel.set_value("payout.clearance_mm", 26)
    w.payout_panel.set_value("payout.clearance_mm", 25)
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.result.job == w.job and w.result.job.payout.clearance_mm == 25.0
    np.testing.assert_allclose(w.eye_plot.curve_data("eye")[1], 95.0, rtol=1e-9)

    # cancel a run in flight: the window is idle at once and keeps the finished stages
    before = w.result
    w.winding_panel.set_value("winding.dwell_deg.1", 170)
    w.ctl.run_timer.stop()
    assert w.run_pipeline_now()
    assert w.pipe_runner.is_busy() and w.cancel_button.isVisible()
    w.cancel_button.click()
    assert not w.pipe_runner.is_busy() and not w.cancel_button.isVisible()
    assert "Cancelled" in w.status_msg.text()
    assert w.pipe_runner.wait(30000)
    assert w.result is before or w.result.line is not None
    # re-run: the new dwell is wound
    _run(w)
    assert w.result.job.winding.dwell_deg == (180.0, 170.0)
    _check_views(w)

    # undo / redo of job edits
    assert w.undo_stack.canUndo()
    w.undo_stack.undo()
    assert w.wait_idle(180000)
    assert w.job.winding.dwell_deg == (180.0, 180.0)
    assert w.winding_panel.editor("winding.dwell_deg.1").text() == "180"
    w.undo_stack.redo()
    assert w.wait_idle(180000)
    assert w.job.winding.dwell_deg == (180.0, 170.0)

    # export NC
    out = tmp_path / "pipe.ngc"
    assert w.export_nc(out, force=False if not w.run_violations else True)
    assert w.wait_idle()
    assert out.read_text() == w.result.nc_text
    assert str(out) in w.status_msg.text()

    # a program that violates a limit asks "write anyway?" (a carriage range that cannot fit is refused
    # before any work by the set-up pre-check; a chuck wider than the eye's radius is found along the path)
    w.machine_panel.setup_edits["chuck_radius_mm"].setText("170")
    w.machine_panel._on_edited()
    assert w.job.machine.setup.chuck_radius_mm == 170.0
    assert w.wait_idle(180000)
    if w.doc.is_stale():
        _run(w)
    assert w.run_violations and any(v.kind == "clearance" for v in w.run_violations)
    asked: list[str] = []
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: asked.append(a[1]) or QMessageBox.StandardButton.No)
    bad = tmp_path / "bad.ngc"
    assert not w.export_nc(bad)
    assert asked == ["Write anyway?"] and not bad.exists()
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.StandardButton.Yes)
    assert w.export_nc(bad)
    assert w.wait_idle() and bad.read_text() == w.result.nc_text

    # save and reopen
    saved = tmp_path / "pipe_edited.toml"
    assert w.save_job(saved)
    job = w.job
    w.open_job(saved)
    assert w.wait_idle()
    assert w.job == job == load_job(saved) and not w.dirty
    assert w.result is None and not w.winding_plots.has_data()  # a new document starts without results
    assert str(saved.resolve()) in w.recent_files()


def test_bad_input_disables_run(pipe_window) -> None:
    w = pipe_window
    assert w.actions["run"].isEnabled() and w.nc_panel.run_button.isEnabled()
    w.payout_panel.set_value("payout.clearance_mm", "abc")
    assert w.payout_panel.error_text("payout.clearance_mm") == "not a number: 'abc'"
    assert not w.actions["run"].isEnabled() and not w.nc_panel.run_button.isEnabled()
    assert "Clearance [mm]: not a number" in w.nc_panel.run_reason.text()
    assert not w.run_pipeline_now() and "Run disabled" in w.status_msg.text()
    assert w.job.payout.clearance_mm == 20.0  # the job keeps its valid value
    w.payout_panel.set_value("payout.clearance_mm", "-3")
    assert "greater than or equal to 0" in w.payout_panel.error_text("payout.clearance_mm")
    w.payout_panel.set_value("payout.clearance_mm", "22")
    assert w.payout_panel.error_text("payout.clearance_mm") == "" and w.actions["run"].isEnabled()
    # pair fields, integer fields, angle lists
    w.winding_panel.set_value("winding.pole_c_mm.0", "10")
    assert "both values" in w.winding_panel.error_text("winding.pole_c_mm.1")
    w.winding_panel.set_value("winding.pole_c_mm.0", "")
    w.winding_panel.set_value("winding.points_per_pass", "2.5")
    assert "whole number" in w.winding_panel.error_text("winding.points_per_pass")
    w.winding_panel.set_value("winding.points_per_pass", "2000")
    w.winding_panel.set_value("winding.angles", "500:95")
    assert "less than 90" in w.winding_panel.error_text("winding.angles")
    assert not w.actions["run"].isEnabled()
    w.winding_panel.set_value("winding.angles", "500:50")
    assert w.job.winding.angles[0].angle_deg == 50.0 and w.actions["run"].isEnabled()
    # a mandrel field
    w.mandrel_panel.set_value("radius_mm", "-5")
    assert not w.actions["run"].isEnabled() and "radius_mm" in w.nc_panel.run_reason.text()
    w.mandrel_panel.set_value("radius_mm", "75")
    assert w.wait_idle() and w.actions["run"].isEnabled()
    # machine limits table
    w.machine_panel.set_cell("X", "max_speed", "fast")
    assert "not a number" in w.machine_panel.table_error.text() and not w.actions["run"].isEnabled()
    w.machine_panel.set_cell("X", "max_speed", "")
    assert w.actions["run"].isEnabled() and w.machine_panel.table_error.isHidden()


@pytest.mark.parametrize("text", ["", "abc", "nan", "1e999", "-1", "1,5:"])
def test_any_text_in_any_field_never_crashes(pipe_window, text: str) -> None:
    """Every field takes any text: either the job takes a valid value or the field shows why not and Run is off."""
    w = pipe_window
    for key, panel in w.section_panels.items():
        for name in list(panel.rows):
            if panel.rows[name].spec.kind == "choice":
                continue
            before = w.job
            panel.set_value(name, text)
            msg = panel.error_text(name) or panel.status.text()
            if msg:
                assert not w.actions["run"].isEnabled() and w.run_block_reason(), (name, text)
                assert w.job == before  # nothing invalid reaches the job
            panel.set_job(w.job)  # back to the job's values
            panel._on_edited()
            assert panel.errors() == "", (key, name, panel.errors())
    for kind_key in [k for (kind, k) in w.mandrel_panel.rows if kind == "pipe"]:
        w.mandrel_panel.set_value(kind_key, text)
        assert w.wait_idle()
        if w.mandrel_panel.error_text(kind_key):
            assert not w.actions["run"].isEnabled()
        w.mandrel_panel.set_spec(w.job.mandrel)
        w.mandrel_panel.set_value(kind_key, getattr(w.job.mandrel, kind_key))
        assert w.wait_idle() and w.actions["run"].isEnabled()
    assert w.error_box is None


def test_machine_template_axes_and_post(pipe_window) -> None:
    from engine.kinematics import load_machine
    from engine.post import list_posts

    w = pipe_window
    mp = w.machine_panel
    rows = mp.axes_rows()
    lathe2 = load_machine("lathe2")
    assert [r["name"] for r in rows] == list(lathe2.axis_names)
    assert rows[1]["max"] == "1800"  # the job's override of the template's 1200
    assert rows[1]["max_speed"] == format(lathe2.axes[1].max_speed, ".10g")
    mp.select_template("lathe4")
    lathe4 = load_machine("lathe4")
    assert w.job.machine.template == "lathe4" and w.job.machine.axes == {}
    assert [(r["name"], r["type"], r["units"]) for r in mp.axes_rows()] == [
        (a.name, a.type, a.units) for a in lathe4.axes]
    name = lathe4.axes[0].name
    mp.set_cell(name, "max_accel", "123")
    assert w.job.machine.axes[name].max_accel == 123.0
    mp.set_cell(name, "max_accel", "")
    assert name not in w.job.machine.axes
    # only the dialects and profiles that can address lathe4's axes (engine.machine_setup.compatible_posts)
    from engine.machine_setup import compatible_posts

    pairs = compatible_posts(lathe4)
    assert sorted(mp.post_combo.itemText(i) for i in range(mp.post_combo.count())) == sorted({p for p, _ in pairs})
    assert set(list_posts()) == {p for p, _ in pairs}           # every dialect can write lathe4
    post = mp.post_combo.currentText()
    assert [mp.controller_combo.itemText(i) for i in range(1, mp.controller_combo.count())] == [
        c for p, c in pairs if p == post]
    assert "linuxcnc_robot" not in [mp.controller_combo.itemText(i) for i in range(mp.controller_combo.count())]
    mp.post_combo.setCurrentText("fanuc")
    mp._on_post()                      # as when the user picks it: the controller list follows the dialect
    assert w.job.post.post == "fanuc"
    mp.controller_combo.setCurrentText("fanuc")
    mp._on_edited()
    assert w.job.post.controller == "fanuc"
    w.undo_stack.undo()
    assert w.job.post.controller is None


def test_time_law_iterations(pipe_window) -> None:
    w = pipe_window
    w.go_to_step("timelaw")
    w.timelaw_panel.compute_button.click()
    assert w.wait_idle(180000) and w.last_error == ""
    r = w.timelaw
    shown = [k for k in w.timelaw_plot.curves if k.startswith("iteration ")]
    assert shown == [f"iteration {log.r}" for log in r.tube.iterations]
    for log in r.tube.iterations:
        x, y = w.timelaw_plot.curve_data(f"iteration {log.r}")
        np.testing.assert_array_equal(x, log.s)
        np.testing.assert_array_equal(y, log.sdot)
    last = r.tube.iterations[-1]
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("tube lower")[1], last.lower)
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("W touches")[0], last.s[np.asarray(last.w_mask, bool)])
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("O touches")[0], last.s[np.asarray(last.o_mask, bool)])
    # the tube and touches of any iteration on demand
    first = r.tube.iterations[0]
    w.timelaw_plot.bounds_of.setValue(first.r)
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("tube upper")[1], first.upper)
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("W touches")[0], first.s[np.asarray(first.w_mask, bool)])
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("O touches")[1],
                                  first.sdot[np.asarray(first.o_mask, bool)])
    for name, law in (("tube", r.tube), ("DP", r.dp), ("TOPP-RA", r.toppra)):
        x, y = w.timelaw_plot.curve_data(f"final {name}")
        np.testing.assert_array_equal(x, law.t)
        np.testing.assert_array_equal(y, law.sdot)
        assert x[-1] == pytest.approx(law.total_time_s) and np.all(np.diff(x) >= 0)
    # TOPP-RA is the time-optimal bound; the tube law cannot beat it, and is close to it
    assert r.toppra.total_time_s <= r.tube.total_time_s * (1 + 1e-3)
    assert r.tube.total_time_s <= r.dp.total_time_s * (1 + 1e-9)
    assert f"{r.tube.total_time_s:.3f} s" in w.timelaw_panel.summary.text()


def test_plot_export_png_svg_csv(pipe_window, tmp_path) -> None:
    w = pipe_window
    _run(w)
    page = w.winding_plots
    png = page.export(tmp_path / "w.png")
    svg = page.export(tmp_path / "w.svg")
    csv_path = page.export(tmp_path / "w.csv")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<svg" in svg.read_text()[:2000]
    rows = list(csv.reader(csv_path.read_text().splitlines()))
    assert rows[0][:2] == ["beta x", "beta y"]
    sl = w.result.line.circuit_slice(0)
    col = np.array([float(r[1]) for r in rows[1:] if r[1] != ""])
    np.testing.assert_array_equal(col, np.degrees(w.result.line.beta[sl]))


def test_animation_play_pause_scrub(pipe_window, qtbot) -> None:
    """The animation runs in machine time: the slider in tenths of a second over the program time,
    speeds ×1…×1000, a jump to a circuit; a new program starts at its end."""
    w = pipe_window
    _run(w)
    v = w.view3d
    n = v.paths.frame_index.size
    total = w.result.blocks.total
    assert 2 <= n <= MAX_FRAMES
    assert v.timeline.total_s == pytest.approx(total, rel=1e-9)  # the frames' times come from the NC blocks
    assert v.slider.maximum() == round(total * SLIDER_STEPS_PER_S)
    assert v.frame == n - 1 and v.time_s == pytest.approx(total)
    assert "s" in v.frame_label.text() and f"{total:.1f}" in v.frame_label.text()
    v.slider.setValue(v.slider.maximum() // 2)
    assert v.time_s == pytest.approx((v.slider.maximum() // 2) / SLIDER_STEPS_PER_S)
    assert v.frame == v.timeline.frame_at(v.time_s)
    assert v.timeline.times[v.frame] <= v.time_s < v.timeline.times[min(v.frame + 1, n - 1)] + 1e-9
    v.set_speed(100)
    t0 = v.time_s
    v.play()
    assert v.is_playing() and v.play_button.text() == "Pause"
    qtbot.waitUntil(lambda: v.time_s > t0 + 5.0, timeout=5000)  # ×100: 5 machine seconds in ~0.05 s
    w.actions["play"].trigger()  # Space toggles
    assert not v.is_playing() and v.play_button.text() == "Play"
    f = v.frame
    qtbot.wait(100)
    assert v.frame == f
    v.jump_to_circuit(3)
    assert v.timeline.circuits[v.frame] == 3 and (v.frame == 0 or v.timeline.circuits[v.frame - 1] != 3)
    for name in ("winding angle β [deg]", "λ [–]", "pull speed u", "circuit"):
        v.set_colour_by(name)
        assert v.colour_scalars().size == v.paths.line_xyz.shape[0]
    v.set_colour_by("winding angle β [deg]")
    np.testing.assert_allclose(v.colour_scalars(), np.degrees(w.result.line.beta[v.paths.line_index]))
    v.set_frame(TRAIL_FRAMES + 5)
    np.testing.assert_array_equal(v.trail(), v.paths.eye_xyz[5:TRAIL_FRAMES + 6])


def test_decimation_keeps_a_million_points_interactive() -> None:
    from types import SimpleNamespace

    from winder_gui.views.geometry import paths_view_data

    n = 1_000_000
    v = np.linspace(0, 400 * np.pi, n)
    z = np.linspace(0, 1000, n)
    r = np.full(n, 50.0)
    line = SimpleNamespace(z=z, r=r, xyz=np.column_stack([r * np.cos(v), r * np.sin(v), z]), beta=np.full(n, 0.5),
                           lam=np.zeros(n), circuit=np.zeros(n, int))
    eye = SimpleNamespace(u=np.ones(n - 1), eye_xyz=line.xyz * [1.5, 1.5, 1], contact_xyz=line.xyz)
    p = paths_view_data(line, eye, 200_000, 1500)
    assert p.line_xyz.shape[0] <= 200_001 and p.line_index[-1] == n - 1 and p.frame_index.size <= 1500
    np.testing.assert_allclose(p.line_xyz[:, 0], z[p.line_index])


# the heartbeat tests (GUI thread never blocked > 100 ms during a run) are in test_gui_heartbeat.py


def test_autosave_and_restore(qtbot, tmp_path) -> None:
    w = _window(qtbot)
    assert w.autosave_now() is None  # nothing to save while clean
    w.payout_panel.set_value("payout.clearance_mm", 31)
    p = w.autosave_now()
    assert p is not None and p.parent == tmp_path / "autosave"
    assert p.read_text().startswith(AUTOSAVE_HEADER + str(PIPE.resolve()))
    assert load_job(p) == w.job
    assert autosave_origin(p) == PIPE.resolve()
    assert not list(p.parent.glob("*.tmp*"))  # written atomically (temp + rename)
    edited = w.job
    # a second session finds it and restores it (unsaved, attached to the original file)
    w2 = _window(qtbot, None)
    assert w2.pending_autosaves() == [p]
    w2.restore_autosave(p)
    assert w2.wait_idle()
    assert w2.job == edited and w2.dirty and w2.job_path == PIPE.resolve()
    # saving drops the copy; so does a deliberate close
    assert w2.save_job(tmp_path / "restored.toml")
    assert not p.exists()
    _close(w2)
    w.set_dirty(False)
    _close(w)


def test_autosave_offered_at_start(qtbot, tmp_path, monkeypatch) -> None:
    w = _window(qtbot)
    w.payout_panel.set_value("payout.clearance_mm", 29)
    p = w.autosave_now()
    edited = w.job
    w2 = _window(qtbot, None)
    asked: list[str] = []
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: asked.append(a[2]) or QMessageBox.StandardButton.Yes)
    w2.offer_autosaves()
    assert w2.wait_idle()
    assert len(asked) == 1 and p.name in asked[0] and str(PIPE.resolve()) in asked[0]
    assert w2.job == edited and w2.dirty
    # "Discard" deletes the copy
    w3 = _window(qtbot, None)
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.StandardButton.Discard)
    w3.offer_autosaves()
    assert not p.exists() and w3.job.name == "untitled"
    for x in (w, w2, w3):
        x.set_dirty(False)
        _close(x)


def test_autosave_survives_a_killed_process(tmp_path) -> None:
    script = textwrap.dedent(f"""
        import os, signal
        from PySide6.QtWidgets import QApplication
        app = QApplication([])
        from winder_gui.main_window import MainWindow
        w = MainWindow({str(PIPE)!r})
        w.show()
        assert w.wait_idle()
        w.payout_panel.set_value("payout.clearance_mm", 33)
        w.autosave_now()
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", WINDER_AUTOSAVE_DIR=str(tmp_path / "auto"),
               WINDER_SETTINGS=str(tmp_path / "s.ini"))
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    (copy,) = (tmp_path / "auto").glob("*.toml")
    assert load_job(copy).payout.clearance_mm == 33.0


def test_settings_and_layout_persist(qtbot, tmp_path) -> None:
    w = _window(qtbot)
    w.plot_tabs.setCurrentIndex(3)
    w.resize(1000, 640)
    size = (w.width(), w.height())
    w.view3d.set_colour_by("λ [–]")
    w.actions["auto_run"].trigger()
    assert not w.auto_run
    _close(w)
    w2 = _window(qtbot, None)
    assert w2.plot_tabs.currentWidget() is w2.plot  # a new window opens on the first step's plot, not the last tab
    assert w2.steps.current_step() == "mandrel"
    assert w2.height() == size[1] == 640  # (the offscreen screen is too narrow to test the width)
    assert w2.view3d.colour_by == "λ [–]" and not w2.auto_run
    assert w2.recent_files() == [str(PIPE.resolve())]
    assert [a.toolTip() for a in w2.menu_recent.actions()] == [str(PIPE.resolve())]
    _close(w2)


def test_unsaved_job_offered_for_saving_on_close(pipe_window, monkeypatch, tmp_path) -> None:
    w = pipe_window
    w.payout_panel.set_value("payout.clearance_mm", 27)
    assert w.dirty
    w.confirm_discard = True
    asked: list[str] = []
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: asked.append(a[1]) or QMessageBox.StandardButton.Save)
    target = tmp_path / "on_close.toml"
    monkeypatch.setattr(w, "_action_save_as", lambda: w.save_job(target))
    w.job_path = None
    assert w.close()
    assert asked == ["Unsaved changes"] and load_job(target).payout.clearance_mm == 27.0


def test_pipeline_error_is_a_readable_dialog(pipe_window) -> None:
    w = pipe_window
    w.machine_panel.template_combo.addItem("no_such_machine")
    w.machine_panel.select_template("no_such_machine")
    assert w.job.machine.template == "no_such_machine"
    assert "no_such_machine" in w.machine_panel.title_label.text()
    assert w.run_pipeline_now()
    assert w.wait_idle(180000)
    assert w.error_box is not None and "Traceback" not in w.error_box.text()
    assert "no_such_machine" in w.error_box.text() and "machine.template" in w.error_box.text()
    assert not w.busy()


@pytest.mark.parametrize("example", [p for p in JOBS if p.name != PIPE.name], ids=lambda p: p.stem)
def test_every_example_end_to_end(qtbot, tmp_path, example: Path) -> None:
    example = single_line(example, tmp_path / "single")
    w = _window(qtbot, example)
    try:
        job0 = load_job(example)
        assert w.job == job0
        # edit the mandrel (a longer cylindrical body), then run everything
        key = {"vessel": "cylinder_length_mm", "bottle": "body_length_mm"}[job0.mandrel.kind]
        w.mandrel_panel.set_value(key, getattr(job0.mandrel, key) + 10.0)
        assert w.wait_idle()
        assert getattr(w.job.mandrel, key) == getattr(job0.mandrel, key) + 10.0
        _run(w)
        assert w.result.job == w.job and w.result.reused == ()
        _check_views(w)
        # cancel a run in flight, re-run: only the NC stage depends on the dialect
        w.machine_panel.post_combo.setCurrentText("fanuc")
        w.machine_panel._on_edited()
        w.ctl.run_timer.stop()
        assert w.run_pipeline_now()
        w.cancel_run()
        assert not w.busy() and "Cancelled" in w.status_msg.text()
        _run(w)
        assert w.result.post_name == "fanuc" and w.result.reused == ("mandrel", "winding", "payout", "axes", "blocks")
        _check_views(w)
        out = tmp_path / f"{example.stem}{w.result.extension}"
        assert w.export_nc(out, force=True)
        assert w.wait_idle() and out.read_bytes() == w.result.nc_text.encode()  # line ends kept (CR LF for fanuc)
        saved = tmp_path / "saved.toml"
        assert w.save_job(saved)
        job = w.job
        w.open_job(example)
        assert w.wait_idle() and w.job == job0
        w.open_job(saved)
        assert w.wait_idle() and w.job == job == load_job(saved) and not w.dirty
    finally:
        _close(w)


def test_selftest_runs_the_pipeline() -> None:
    """``winder --selftest``: the pipe example end to end (full pipeline incl. NC text), exit 0."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    env.pop("WINDER_QUIT_WHEN_SHOWN", None)
    proc = subprocess.run([sys.executable, "-m", "engine", "--selftest"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "pipeline done" in proc.stderr and "blocks" in proc.stderr and "Traceback" not in proc.stderr


def test_selftest_fails_with_exit_1(tmp_path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(PIPE.read_text().replace('template = "lathe2"', 'template = "nope"'))
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    proc = subprocess.run([sys.executable, "-m", "winder_gui.app", "--selftest", str(bad)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "selftest failed" in proc.stderr and "nope" in proc.stderr
