"""Export = screen (issue 15, point 4): the NC program, its preview and its export always describe the
job as displayed.  Any edit after a run makes them out of date (greyed, labelled) and export is refused,
with the reason in the status bar, until the run finishes; the exported program equals, byte for byte,
the program ``winder run`` writes for the saved job."""

from __future__ import annotations

import pytest
from gui_helpers import close_window, shown_window

pytestmark = pytest.mark.usefixtures("qapp")


def _export_enabled(w) -> bool:
    return w.actions["export_nc"].isEnabled() and w.nc_panel.export_button.isEnabled()


@pytest.fixture
def pipe_run(qtbot, examples_dir, tmp_path):
    # the single helical line of the pipe example (its [[layer]] stack is wound by the laminate run)
    text = (examples_dir / "pipe.toml").read_text()
    (tmp_path / "pipe.toml").write_text(text[: text.index("# The laminate")] if "# The laminate" in text else text)
    w = shown_window(qtbot, tmp_path / "pipe.toml")
    w.auto_run = False
    assert w.run_pipeline_now()
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.result.nc_text and _export_enabled(w) and not w.doc.is_stale()
    yield w
    close_window(w)


def _different(text: str) -> str:
    """A value unlike ``text`` that a user might type (numbers scaled, blanks filled)."""
    try:
        return format(float(text) * 1.1 + 1.0, ".6g")
    except ValueError:
        return "1" if not text.strip() else text + "x"


def _check_refused(w, where: str, tmp_path) -> None:
    assert not w.actions["export_nc"].isEnabled(), where
    assert not w.nc_panel.export_button.isEnabled(), where
    assert w.export_block_reason(), where
    target = tmp_path / "stale.ngc"
    assert not w.export_nc(target, force=True), where
    assert "Export disabled" in w.status_msg.text(), where
    assert w.wait_idle(pipeline=False) and not target.exists(), where


def test_every_field_edit_after_a_run_disables_export(pipe_run, tmp_path) -> None:
    w = pipe_run
    edited = 0
    # the section panels: every field, typed as a user would; re-typing the old value makes the
    # results current again (the job equals the job of the run)
    for key, panel in w.section_panels.items():
        w.go_to_step(key)
        for name, row in panel.rows.items():
            ed = row.editor
            if hasattr(ed, "currentText"):
                old = ed.currentText()
                others = [ed.itemText(i) for i in range(ed.count()) if ed.itemText(i) != old]
                if not others:
                    continue
                new = others[0]
            else:
                old = ed.text()
                new = _different(old)
            panel.set_value(name, new)
            _check_refused(w, f"{name}: {old!r} -> {new!r}", tmp_path)
            if panel.errors() == "":
                assert w.nc_panel.stale.isVisible() or not w.nc_panel.isVisible(), name
                assert not w.nc_panel.preview.isEnabled(), name
            panel.set_value(name, old)
            assert w.wait_idle(pipeline=False)
            assert w.job == w.doc.result_job and _export_enabled(w), f"{name}: back to {old!r}"
            edited += 1
    # the mandrel fields (the candidate mandrel is built in the worker)
    w.go_to_step("mandrel")
    mp = w.mandrel_panel
    kind = mp.current_kind()
    for (k, key), row in list(mp.rows.items()):
        if k != kind or hasattr(row.editor, "currentText"):
            continue
        old = row.editor.text()
        mp.set_value(key, _different(old))
        _check_refused(w, f"mandrel {key} (pending)", tmp_path)  # before the build: an edit is pending
        assert w.wait_idle(pipeline=False)
        _check_refused(w, f"mandrel {key}", tmp_path)
        mp.set_value(key, old)
        assert w.wait_idle(pipeline=False)
        assert _export_enabled(w), f"mandrel {key}: back to {old!r}"
        edited += 1
    assert edited >= 20


def test_invalid_radius_after_a_run_refuses_export(pipe_run, tmp_path) -> None:
    """The report of issue 15: run pipe.toml, type -70 into the radius: Run and Export are disabled."""
    w = pipe_run
    w.go_to_step("mandrel")
    w.mandrel_panel.set_value("radius_mm", -70)
    assert w.wait_idle(pipeline=False)
    assert not w.actions["run"].isEnabled()
    _check_refused(w, "radius -70", tmp_path)
    assert "invalid" in w.export_block_reason()
    # Ctrl+Shift+E goes through the same refusal (no file dialog)
    w.actions["export_nc"].setEnabled(True)  # as if a stale enable slipped through: the command refuses
    w.action_export_nc()
    assert "Export disabled" in w.status_msg.text()


def test_edit_marks_results_stale_until_the_run_finishes(pipe_run) -> None:
    w = pipe_run
    w.go_to_step("nc")
    w.payout_panel.set_value("payout.clearance_mm", w.job.payout.clearance_mm + 3)
    assert w.doc.is_stale() and w.stale_label.isVisible() and w.nc_panel.stale.isVisible()
    assert not w.nc_panel.preview.isEnabled()
    assert w.run_pipeline_now()
    assert w.doc.is_stale()  # while it runs
    assert w.wait_idle(180000) and w.last_error == ""
    assert not w.doc.is_stale() and not w.stale_label.isVisible() and not w.nc_panel.stale.isVisible()
    assert w.nc_panel.preview.isEnabled() and _export_enabled(w)


def test_export_equals_winder_run_byte_for_byte(pipe_run, tmp_path) -> None:
    """The program exported from the window equals what ``winder run`` writes for the saved job."""
    from engine.cli import main as cli_main

    w = pipe_run
    w.payout_panel.set_value("payout.clearance_mm", w.job.payout.clearance_mm + 5)  # an edit, then run
    assert w.run_pipeline_now() and w.wait_idle(180000) and w.last_error == ""
    saved = tmp_path / "edited.toml"
    assert w.save_job(saved)
    assert _export_enabled(w)  # saving does not change the job
    gui_nc = tmp_path / "gui.ngc"
    assert w.export_nc(gui_nc, force=True)
    assert w.wait_idle()
    cli_nc = tmp_path / "cli.ngc"
    assert cli_main(["run", str(saved), "-o", str(cli_nc), "--force", "--quiet"]) == 0
    assert gui_nc.read_bytes() == cli_nc.read_bytes()


def test_report_export_describes_the_run_on_screen(pipe_run, tmp_path) -> None:
    """File -> Export report writes the run's report (its numbers); refused once the job changed."""
    w = pipe_run
    assert w.actions["export_report"].isEnabled()
    out = tmp_path / "report.html"
    assert w.export_report(out)
    assert w.wait_idle() and w.last_error == ""
    text = out.read_text("utf-8")
    rep = w.result.report()
    assert f"{rep['program_time_s']:.2f} s" in text and text.count("<svg") >= 5
    assert "Wrote the job report" in w.status_msg.text()
    # the coverage tab shows the map of the run (bands of true width), with its percentages
    cov = w.coverage_plot.coverage
    assert cov is not None and cov.band_width_mm == w.job.band.width_mm
    assert f"covered {100 * cov.covered_fraction:.1f} %" in w.coverage_plot.message.text()
    w.payout_panel.set_value("payout.clearance_mm", w.job.payout.clearance_mm + 1)
    assert not w.actions["export_report"].isEnabled()
    late = tmp_path / "late.pdf"
    assert not w.export_report(late)
    assert w.wait_idle(pipeline=False) and not late.exists()
    assert "Export disabled" in w.status_msg.text()


def test_machine_step_edits_after_a_run_disable_export(pipe_run, tmp_path) -> None:
    """The Machine step's own editors (not section rows): every [machine.setup] field, every limit cell of
    every axis, the template, the dialect and the controller profile - each edit after a run disables
    export until it is undone (typed back or picked back)."""
    from winder_gui.panels.machine_panel import DEFAULT_CONTROLLER, LIMIT_COLUMNS

    w = pipe_run
    w.go_to_step("machine")
    mp = w.machine_panel
    edited = 0

    def back(where: str) -> None:
        assert w.wait_idle(pipeline=False)
        assert w.job == w.doc.result_job and _export_enabled(w), f"{where}: back"

    for key, ed in mp.setup_edits.items():
        old = ed.text()
        ed.setText(_different(old) if old else "7")
        mp._on_edited()
        _check_refused(w, f"setup {key}", tmp_path)
        ed.setText(old)
        mp._on_edited()
        back(f"setup {key}")
        edited += 1
    for row in mp.axes_rows():
        for key, _h in LIMIT_COLUMNS:
            old = row[key]
            mp.set_cell(row["name"], key, _different(old) if old else "5000")
            _check_refused(w, f"axis {row['name']} {key}", tmp_path)
            mp.set_cell(row["name"], key, old)
            back(f"axis {row['name']} {key}")
            edited += 1
    # the combos, picked as a user does (activated)
    for combo, handler in ((mp.post_combo, mp._on_post), (mp.controller_combo, mp._on_edited)):
        old = combo.currentText()
        other = next(combo.itemText(i) for i in range(combo.count()) if combo.itemText(i) != old)
        combo.setCurrentText(other)
        handler()
        _check_refused(w, f"{combo.objectName()} {old} -> {other}", tmp_path)
        combo.setCurrentText(old)
        handler()
        if combo is mp.post_combo:   # the profile list follows the dialect: pick the job's back too
            mp.controller_combo.setCurrentText(w.doc.result_job.post.controller or DEFAULT_CONTROLLER)
            mp._on_edited()
        back(combo.objectName())
        edited += 1
    old = mp.template_combo.currentText()
    mp.select_template("lathe4")
    _check_refused(w, "template lathe2 -> lathe4", tmp_path)
    w.undo_stack.undo()
    back("template")
    assert edited >= 13 + 2 * len(LIMIT_COLUMNS) and old == "lathe2"
