"""The laminate in the window (issue 14, point 6): the layer table of the Winding step, a layered run in
the worker, the selected layer in 3D and in the laminate plots, and the joined program's export.

Everything goes through the real window (offscreen): the table's buttons and model (the same calls a
click, a check box, an in-place rename or a drag-and-drop make), the run controller's worker, the export
command.  The figures in the table are compared with :meth:`engine.laminate.LaminateResult.layup` of
the window's own result and with an independent ``run_laminate`` of the saved job; the exported program
with ``winder run`` of the saved job, byte for byte.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gui_helpers import close_window, shown_window
from PySide6.QtCore import Qt

from engine.job import HelicalLayer, HoopLayer, PolarLayer, SkipLayer, load_job

pytestmark = pytest.mark.usefixtures("qapp")

JOB = """\
schema_version = 2
name = "Small pipe laminate"

[mandrel]
kind = "pipe"
radius_mm = 40.0
length_mm = 300.0

[band]
width_mm = 10.0
thickness_mm = 0.4
friction = 0.15

[winding]
mode = "geodesic"
dwell_deg = [180.0, 180.0]
points_per_pass = 400

[[winding.angles]]
z_mm = 150.0
angle_deg = 55.0

[payout]
law = "parallel"

[machine]
template = "lathe2"

[post]
post = "linuxcnc"

[machine.axes.X]
max = 1800.0

[[layer]]
kind = "hoop"
name = "inner hoop"

[[layer]]
kind = "helical"
name = "helical 55"

[[layer]]
kind = "hoop"
name = "outer hoop"
terminal = true
"""


@pytest.fixture
def job_file(tmp_path):
    p = tmp_path / "lam3.toml"
    p.write_text(JOB, encoding="utf-8")
    return p


@pytest.fixture
def win(qtbot, job_file):
    w = shown_window(qtbot, job_file)
    w.auto_run = False
    w.go_to_step("winding")
    yield w
    close_window(w)


@pytest.fixture
def ran(win):
    assert win.run_pipeline_now()
    assert win.wait_idle(180000) and win.last_error == "", win.last_error
    return win


def _kinds(w) -> list[str]:
    return [lay.kind for lay in w.job.layers]


def _names(w) -> list[str]:
    return [lay.name for lay in w.job.layers]


def _cell(w, row: int, key: str) -> str:
    from winder_gui.panels.layers_panel import COL

    return w.layers_panel.model.index(row, COL[key]).data()


# --------------------------------------------------------------------------------------------------
def test_table_shows_the_job_layers(win) -> None:
    p = win.layers_panel
    assert p.model.rowCount() == 3
    assert [_cell(win, r, "name") for r in range(3)] == ["inner hoop", "helical 55", "outer hoop"]
    assert [_cell(win, r, "kind") for r in range(3)] == ["hoop", "helical", "hoop"]
    assert "terminal" in _cell(win, 2, "definition")
    assert _cell(win, 0, "time_s") == ""  # not run yet


def test_add_duplicate_delete_reorder_disable_change_the_job_and_undo(win) -> None:
    p = win.layers_panel
    stack = win.undo_stack
    jobs = [win.job]

    p.select_layer(0)
    p.add_layer("polar")  # after the selected layer
    assert _kinds(win) == ["hoop", "polar", "helical", "hoop"]
    assert isinstance(win.job.layers[1], PolarLayer) and p.selected_layer() == 1
    jobs.append(win.job)

    p.add_layer("skip")
    assert _kinds(win) == ["hoop", "polar", "skip", "helical", "hoop"]
    assert isinstance(win.job.layers[2], SkipLayer)
    jobs.append(win.job)

    p.select_layer(3)
    p.duplicate_layer()
    assert _names(win) == ["inner hoop", "", "", "helical 55", "helical 55 copy", "outer hoop"]
    assert win.job.layers[4].model_dump(exclude={"name"}) == win.job.layers[3].model_dump(exclude={"name"})
    jobs.append(win.job)

    p.delete_layer(2)  # the skip
    assert _kinds(win) == ["hoop", "polar", "helical", "helical", "hoop"]
    jobs.append(win.job)

    # reorder by drag and drop: the model's mime data of row 0 dropped before row 3
    m = p.model
    data = m.mimeData([m.index(0, 1)])
    m.dropMimeData(data, Qt.DropAction.MoveAction, 3, 0, m.index(-1, -1))
    assert _names(win) == ["", "helical 55", "inner hoop", "helical 55 copy", "outer hoop"]
    jobs.append(win.job)
    # dropped onto a row (no row given): before that row
    data = m.mimeData([m.index(4, 1)])
    m.dropMimeData(data, Qt.DropAction.MoveAction, -1, -1, m.index(0, 1))
    assert _names(win) == ["outer hoop", "", "helical 55", "inner hoop", "helical 55 copy"]
    jobs.append(win.job)
    p.move_layer(0, 4)  # the ▼ / ▲ buttons
    assert _names(win) == ["", "helical 55", "inner hoop", "helical 55 copy", "outer hoop"]
    jobs.append(win.job)

    # enable/disable by the check box, rename in place
    m.setData(m.index(2, 0), Qt.CheckState.Unchecked.value, Qt.ItemDataRole.CheckStateRole)
    assert not win.job.layers[2].enabled and [i for i, _ in win.job.active_layers] == [0, 1, 3, 4]
    jobs.append(win.job)
    m.setData(m.index(0, 1), "polar 1", Qt.ItemDataRole.EditRole)
    assert win.job.layers[0].name == "polar 1"
    assert _cell(win, 0, "name") == "polar 1"
    jobs.append(win.job)
    assert win.dirty and not win.job.is_single_line

    # every step is one undo entry: undo walks back through the same jobs, redo forward again
    for expected in reversed(jobs[:-1]):
        stack.undo()
        assert win.wait_idle(pipeline=False)
        assert win.job == expected
        assert [lay.kind for lay in p.job.layers] == [lay.kind for lay in expected.layers]  # the table follows
    for expected in jobs[1:]:
        stack.redo()
        assert win.job == expected


def test_last_layer_cannot_be_deleted(qtbot, tmp_path) -> None:
    w = shown_window(qtbot)  # the default job: one helical layer (a single line)
    try:
        assert w.job.is_single_line and w.layers_panel.model.rowCount() == 1
        w.layers_panel.delete_layer(0)
        assert len(w.job.layers) == 1 and "at least one layer" in w.layers_panel.status.text()
        assert not w.layers_panel.del_button.isEnabled()
    finally:
        close_window(w)


def test_layer_fields_edit_the_layer_and_bad_values_block_run(win) -> None:
    p = win.layers_panel
    p.select_layer(0)
    assert "overlap" in p.editors and "passes" in p.editors and "z_range_mm.0" in p.editors
    p.set_value("overlap", "0.25")
    p.set_value("passes", "3")
    lay = win.job.layers[0]
    assert isinstance(lay, HoopLayer) and lay.overlap == 0.25 and lay.passes == 3
    p.set_value("z_range_mm.0", "20")  # one end only: not applied, shown at the field, Run disabled
    assert win.job.layers[0].z_range_mm is None
    assert "both ends" in p.error_labels["z_range_mm.1"].text()
    assert not win.actions["run"].isEnabled() and "layer 1" in win.run_block_reason()
    p.set_value("z_range_mm.1", "280")
    assert win.job.layers[0].z_range_mm == (20.0, 280.0) and win.actions["run"].isEnabled()
    p.set_value("overlap", "1.5")  # out of range: the model's message
    assert win.job.layers[0].overlap == 0.25 and p.errors()
    p.set_value("overlap", "0.25")
    assert not p.errors()
    p.set_value("band.width_mm", "12")
    assert win.job.layers[0].band.width_mm == 12.0
    p.set_value("band.width_mm", "")
    assert win.job.layers[0].band.width_mm is None  # blank: inherited from [band]

    p.select_layer(1)
    assert "angle_deg" in p.editors and "pattern_p" in p.editors and "mode" in p.editors
    p.set_value("angle_deg", "45")
    assert p.editor("mode").currentText() == "(inherited)"
    p.set_value("mode", "geodesic")
    p.set_value("pattern_p", "7")
    lay = win.job.layers[1]
    assert isinstance(lay, HelicalLayer) and lay.angle_deg == 45.0 and lay.mode == "geodesic" and lay.pattern_p == 7
    p.set_value("mode", "(inherited)")
    assert win.job.layers[1].mode is None
    p.set_value("angle_deg", "95")
    assert win.job.layers[1].angle_deg == 45.0 and p.errors()
    p.set_value("angle_deg", "45")

    # the kind: helical -> polar keeps the line's fields, -> skip keeps the name
    p.kind_combo.setCurrentText("polar")
    p._on_kind()
    assert isinstance(win.job.layers[1], PolarLayer) and win.job.layers[1].angle_deg == 45.0
    p.kind_combo.setCurrentText("skip")
    p._on_kind()
    assert isinstance(win.job.layers[1], SkipLayer) and win.job.layers[1].name == "helical 55"
    p.set_value("angle_deg", "30")
    assert win.job.layers[1].angle_deg == 30.0


def test_run_fills_the_table_with_the_layup(ran) -> None:
    from engine.laminate import LaminateResult, run_laminate

    w = ran
    res = w.result
    assert isinstance(res, LaminateResult) and len(res.layers) == 3
    layup = res.layup()
    for row, f in enumerate(layup["layers"]):
        assert w.layers_panel.model.figures_of(row)["time_s"] == f["time_s"]
        assert w.layers_panel.model.figures_of(row)["fibre_length_m"] == f["fibre_length_m"]
        assert _cell(w, row, "time_s") == f"{f['time_s']:.2f}"
        assert _cell(w, row, "fibre_length_m") == f"{f['fibre_length_m']:.2f}"
        assert _cell(w, row, "thickness_cyl_mm") == f"{f['thickness_cyl_mm']:.3f}"
    assert f"{layup['total']['program_time_s']:.1f} s" in w.layers_panel.totals.text()
    # independent: the engine run outside the window on the same job gives the same figures
    ref = run_laminate(load_job(w.job_path), w.job_path).layup()
    for a, b in zip(ref["layers"], layup["layers"], strict=True):
        for key in ("time_s", "fibre_length_m", "fibre_mass_kg", "thickness_cyl_mm"):
            assert a[key] == pytest.approx(b[key], rel=1e-12)
    # the NC page shows the joined program
    assert res.nc_text and "layer 2 helical 55" in res.nc_text
    assert f"{res.blocks.total:.2f} s" in w.nc_panel.summary.text()


def test_selecting_a_layer_shows_its_surface_line_and_plots(ran) -> None:
    w = ran
    res = w.result
    p = w.layers_panel
    seen = {}
    for i in (0, 1, 2):
        p.select_layer(i)
        lr = res.layer(i)
        assert w.laminate.shown_layer == i
        d = w.view3d.data  # the layer's own grown mandrel
        z, r = lr.surface.sample(600)
        assert np.allclose(d.z, z) and np.allclose(d.r, r)
        assert w.view3d.paths.n_line == lr.result.line.z.size  # its line
        line = lr.result.line  # its single-line plots: β(z) of its first circuit
        bz, bb = w.winding_plots.curve_data("beta")
        sl = line.circuit_slice(0)
        assert np.array_equal(bz, line.z[sl]) and np.allclose(bb, np.degrees(line.beta[sl]))
        assert w.wait_idle(180000)  # its coverage map (computed on first show), of its own line and band
        cov = w.coverage_plot.coverage
        assert cov is w.laminate.coverage_of(i) and cov.band_width_mm == line.band_width_mm
        lp = w.laminate_plot
        assert lp.selected == i
        assert lp.selected_pen_width(f"boundary {i + 1}") > max(lp.selected_pen_width(f"boundary {k + 1}")
                                                                for k in range(3) if k != i)
        seen[i] = float(np.max(d.r))
    # each layer is wound on the surface the previous ones grew: the radius on the cylinder grows by the
    # thickness of the layers below
    t = [res.layer(i).figures["thickness_cyl_mm"] for i in range(3)]
    assert seen[1] == pytest.approx(seen[0] + t[0], abs=2e-3)
    assert seen[2] == pytest.approx(seen[1] + t[1], abs=2e-3)
    # the cross-section: bare mandrel + each layer's outer boundary, the engine's arrays (thinned)
    lp = w.laminate_plot
    for i in range(3):
        th = res.layer(i).thickness
        x, y = lp.curve_data(f"boundary {i + 1}")
        assert np.allclose(np.interp(x, th.z_out, th.r_out), y, atol=1e-9)
        x, y = lp.curve_data(f"thickness {i + 1}")
        assert np.allclose(np.interp(x, th.z, th.t), y, atol=1e-9)
    x, y = lp.curve_data("angle 2")
    assert 50.0 < float(np.median(y)) < 60.0  # the ±55° layer
    x, y = lp.curve_data("angle 1")
    assert float(np.median(y)) > 85.0  # a hoop
    assert w.plot_tabs.currentWidget() is lp  # the Winding step of a layered job shows the laminate
    lp.buildup.setChecked(True)  # build-up: height above the mandrel
    x, y = lp.curve_data("boundary 3")
    assert float(np.max(y)) == pytest.approx(sum(t), abs=0.02)
    # the legend (mandrel + one entry per layer) sits beside the cross-section, never over its data
    assert len(lp.legend.items) == 1 + 3
    assert [lab.text.split()[0] for _s, lab in lp.legend.items] == ["mandrel", "1", "2", "3"]
    lp.resize(1000, 700)
    from PySide6.QtWidgets import QApplication
    QApplication.processEvents()
    legend = lp.legend.sceneBoundingRect()
    data = lp.plots["section"].getViewBox().sceneBoundingRect()
    assert legend.width() > 20 and data.width() > 300 and not legend.intersects(data)
    assert legend.left() >= data.right() and legend.top() < data.bottom()


def test_edit_of_the_last_layer_reuses_the_others(ran) -> None:
    w = ran
    first = w.result
    p = w.layers_panel
    p.select_layer(2)
    p.set_value("terminal", False)
    p.set_value("passes", "2")
    # the figures of the edited layer are blanked at once, the others still describe their layers
    assert _cell(w, 2, "time_s") == "" and _cell(w, 0, "time_s") != "" and _cell(w, 1, "time_s") != ""
    assert w.doc.is_stale() and not w.actions["export_nc"].isEnabled()
    assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == ""
    res = w.result
    assert res.reused == (0, 1)
    assert res.layer(0).result is first.layer(0).result and res.layer(1).result is first.layer(1).result
    assert res.layer(2).figures["thickness_cyl_mm"] == pytest.approx(2 * first.layer(2).figures["thickness_cyl_mm"],
                                                                     rel=1e-3)
    assert _cell(w, 2, "time_s") == f"{res.layer(2).figures['time_s']:.2f}"
    assert "re-used layers: 1, 2" in w.status_msg.text()


def test_disabled_layer_is_not_wound(ran) -> None:
    w = ran
    w.layers_panel.set_enabled(1, False)
    assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == ""
    assert [lr.index for lr in w.result.layers] == [0, 2]
    assert _cell(w, 1, "time_s") == "off" and _cell(w, 2, "time_s") != ""
    assert "layer 2 " not in w.result.nc_text
    w.layers_panel.select_layer(1)  # nothing to show in 3D for it: the view keeps the last layer shown
    assert w.laminate.shown_layer in (0, 2)


def test_back_to_a_single_line_clears_the_laminate(ran) -> None:
    w = ran
    p = w.layers_panel
    for i in (2, 0):
        p.delete_layer(i)
    assert [lay.kind for lay in w.job.layers] == ["helical"]
    p.select_layer(0)
    p.set_value("name", "")
    assert w.job.is_single_line
    assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == ""
    assert not hasattr(w.result, "layup")  # the single-line pipeline's result
    assert w.laminate.output is None and not w.laminate_plot.has_data() and p.totals.text() == ""
    assert np.allclose(w.view3d.data.r, w.view_data.r)  # the bare mandrel again
    assert w.view3d.paths.n_line == w.result.line.z.size


def test_cancel_keeps_no_partial_layer_as_the_job_result(win) -> None:
    assert win.run_pipeline_now()
    win.cancel_run()
    assert win.wait_idle(180000)
    assert win.result is None  # a layer's partial single-line result is never taken for the job's
    assert not win.actions["export_nc"].isEnabled()


def test_layer_error_from_the_engine_is_shown_at_the_layer(win) -> None:
    p = win.layers_panel
    p.select_layer(0)
    p.set_value("z_range_mm.0", "-50")
    p.set_value("z_range_mm.1", "100")  # outside the mandrel (0..300): the engine says so
    assert win.job.layers[0].z_range_mm == (-50.0, 100.0)
    p.select_layer(2)
    win.run_pipeline_now()
    assert win.wait_idle(60000)
    assert "z range" in win.last_error and "layer 1" in win.last_error
    assert p.selected_layer() == 0 and "outside" in p.error_labels["z_range_mm.0"].text()


def test_export_equals_winder_run_byte_for_byte(ran, tmp_path) -> None:
    from engine.cli import main as cli_main

    w = ran
    p = w.layers_panel
    p.select_layer(1)
    p.duplicate_layer()  # an edit of the laminate, then run
    assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == ""
    assert len(w.result.layers) == 4
    saved = tmp_path / "edited.toml"
    assert w.save_job(saved)
    assert [lay.name for lay in load_job(saved).layers] == _names(w)
    gui_nc = tmp_path / "gui.ngc"
    assert w.export_nc(gui_nc, force=True)
    assert w.wait_idle(180000)
    cli_nc = tmp_path / "cli.ngc"
    assert cli_main(["run", str(saved), "-o", str(cli_nc), "--force", "--quiet"]) == 0
    assert gui_nc.read_bytes() == cli_nc.read_bytes()
    assert "(layer 3 helical 55 copy [helical]" in gui_nc.read_text()


def test_report_export_of_the_laminate_is_the_runs(ran, tmp_path) -> None:
    """File -> Export report of a layered run: the layup table and every layer's figures, the numbers of
    the run's report (LaminateResult.report)."""
    w = ran
    out = tmp_path / "report.html"
    assert w.export_report(out)
    assert w.wait_idle(180000) and w.last_error == ""
    text = out.read_text("utf-8")
    rep = w.result.report()
    assert f"{rep['program_time_s']:.2f} s" in text and f"{rep['fibre_length_mm'] / 1000.0:.3f} m" in text
    for row in rep["layers"]:
        assert f"<td>{float(row['time_s']):.2f}</td>" in text
    assert "Layer 2 (helical 55): winding line" in text and "Layer 3 (outer hoop): coverage map" in text


EXAMPLE_JOBS = sorted(p for p in (Path(__file__).resolve().parents[1] / "resources" / "examples").glob("*.toml")
                      if "[[layer]]" in p.read_text("utf-8"))


@pytest.mark.parametrize("example", EXAMPLE_JOBS, ids=lambda p: p.stem)
def test_every_layered_example_in_the_window(qtbot, tmp_path, example) -> None:
    """Each shipped laminate: run in the worker, every layer shown on its own surface with its own
    single-line plots and payout-law comparison, the joined program's axes, export = the program."""
    w = shown_window(qtbot, example)
    try:
        job = load_job(example)
        assert w.job == job and not job.is_single_line
        assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == "", w.last_error
        res = w.result
        assert [lr.index for lr in res.layers] == [i for i, _ in job.active_layers]
        for lr in res.layers:
            if lr.result is None:
                continue
            w.layers_panel.select_layer(lr.index)
            assert w.wait_idle(180000)
            assert w.laminate.shown_result() is lr.result
            assert w.view3d.paths.n_line == lr.result.line.z.size
            z, r = lr.surface.sample(600)
            assert np.allclose(w.view3d.data.r, r)
            x, y = w.eye_plot.curve_data("eye")
            np.testing.assert_array_equal(x, lr.result.eye_circuit.Z)
            assert w.laws is not None and w.laws[lr.result.eye_circuit.law] is lr.result.eye_circuit
            assert w.pull_plot.has_data()
        # the axes plot shows the joined program (layers and transitions)
        b = res.blocks
        k = 0
        ax = res.machine.axes[k]
        x, y = w.axes_plot.curve_data(f"{ax.name} position")
        np.testing.assert_array_equal(y, b.q[:, k])
        assert x[-1] == pytest.approx(b.total)
        assert f"{b.total:.2f} s" in w.nc_panel.summary.text()
        out = tmp_path / f"{example.stem}{res.extension}"
        assert w.export_nc(out, force=True) and w.wait_idle(180000)
        assert out.read_bytes() == res.nc_text.encode()
        # export = screen = `winder run` of the shipped file, byte for byte (issue 15), written without --force
        from engine.cli import main as cli_main

        cli_nc = tmp_path / f"cli{res.extension}"
        assert cli_main(["run", str(example), "-o", str(cli_nc), "--quiet"]) == 0
        assert out.read_bytes() == cli_nc.read_bytes()
    finally:
        close_window(w, 120000)


def test_layered_run_reports_progress_per_layer(job_file) -> None:
    """The worker task's progress names the layer it works on, in winding order, and ends at 1."""
    from engine.state import RecordingState
    from winder_gui.laminate_tasks import laminate_task

    st = RecordingState()
    out = laminate_task(load_job(job_file), job_file, None, state=st)
    msgs = [m for _, m in st.progress_calls if m.startswith("layer ")]
    firsts = [m.split(":")[0] for m in msgs]
    seen = list(dict.fromkeys(firsts))
    assert seen == ["layer 1/3 inner hoop", "layer 2/3 helical 55", "layer 3/3 outer hoop"]
    assert all(0.0 <= f <= 1.0 for f in st.fractions) and st.fractions[-1] == 1.0
    assert st.partials == []  # a layer's own single-line result is never published as the job's
    assert [v.index for v in out.views] == [0, 1, 2]


def _other_value(ed) -> object:
    """A value unlike the editor's, as a user would type or pick it."""
    from PySide6.QtWidgets import QCheckBox, QComboBox

    if isinstance(ed, QCheckBox):
        return not ed.isChecked()
    if isinstance(ed, QComboBox):
        others = [ed.itemText(i) for i in range(ed.count()) if ed.itemText(i) != ed.currentText()]
        return others[0] if others else None
    text = ed.text()
    try:
        return format(float(text) * 1.1 + 1.0, ".6g")
    except ValueError:
        return "1" if not text.strip() else text + "x"


def _old_value(ed) -> object:
    from PySide6.QtWidgets import QCheckBox, QComboBox

    if isinstance(ed, QCheckBox):
        return ed.isChecked()
    return ed.currentText() if isinstance(ed, QComboBox) else ed.text()


def _export_refused(w, where: str, tmp_path) -> None:
    assert not w.actions["export_nc"].isEnabled() and not w.nc_panel.export_button.isEnabled(), where
    assert not w.actions["export_report"].isEnabled(), where
    assert w.export_block_reason(), where
    target = tmp_path / "stale.ngc"
    assert not w.export_nc(target, force=True), where
    assert "Export disabled" in w.status_msg.text(), where
    assert w.wait_idle(pipeline=False) and not target.exists(), where


def test_every_layer_field_edit_after_a_run_disables_export(ran, tmp_path) -> None:
    """Export = screen for a laminate (issue 15): after a run, every field of every layer, typed as a user
    would (a valid or an invalid value), and every layer-table operation disables Export NC and Export
    report (refused with the reason in the status bar, nothing written); typing the old value back or
    undoing makes the run current again."""
    w = ran
    p = w.layers_panel
    assert w.actions["export_nc"].isEnabled()
    edited = 0
    for i in range(len(w.job.layers)):
        p.select_layer(i)
        for key in list(p.editors):
            ed = p.editor(key)
            old, new = _old_value(ed), _other_value(ed)
            if new is None:
                continue
            p.set_value(key, new)
            _export_refused(w, f"layer {i + 1} {key}: {old!r} -> {new!r}", tmp_path)
            p.set_value(key, old)
            assert w.wait_idle(pipeline=False)
            assert not p.errors() and w.job == w.doc.result_job, f"layer {i + 1} {key}: back to {old!r}"
            assert w.actions["export_nc"].isEnabled(), f"layer {i + 1} {key}: back to {old!r}"
            edited += 1
    assert edited >= 15
    # the table's operations are edits too
    for op in (lambda: p.duplicate_layer(0), lambda: p.add_layer("hoop"), lambda: p.move_layer(0, 1)):
        op()
        _export_refused(w, "layer table", tmp_path)
        w.undo_stack.undo()
        assert w.wait_idle(pipeline=False)
        assert w.job == w.doc.result_job and w.actions["export_nc"].isEnabled()
