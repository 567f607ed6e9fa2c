"""GUI: the sketch of exact segments (issue 17 point 1): Convert to sketch, the segment table, errors.

Assertions are on the job's data: a template converts to its exact segments (same generatrix), a
typed cell changes the job (undoably), a bad cell never reaches the job and blocks Run with the
reason, and a geometric error of the built sketch comes back to the segment's cell.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gui_helpers import close_window, shown_window

from engine.job import SegmentsSpec, build_mandrel
from winder_gui.panels.segments_table import C_CORNER, C_CZ, C_FILLET, C_R, C_Z

ROOT = Path(__file__).resolve().parents[1]


def test_convert_to_sketch_gives_the_exact_segments_and_edits_them(qtbot) -> None:
    w = shown_window(qtbot, ROOT / "resources/examples/pressure_vessel.toml")
    try:
        panel = w.mandrel_panel
        template = build_mandrel(w.job)
        assert panel.convert_button.isVisibleTo(panel)
        panel.convert_button.click()
        assert w.wait_idle()
        spec = w.job.mandrel
        assert isinstance(spec, SegmentsSpec) and panel.current_kind() == "segments"
        assert [s.type for s in spec.segments] == ["isotensoid", "line", "isotensoid"]
        t = panel.segments_table
        assert t.isVisibleTo(panel) and t.table.rowCount() == 3 and not panel.convert_button.isVisibleTo(panel)
        z = np.linspace(template.z_min, template.z_max, 5001)
        assert np.abs(w.mandrel.r(z) - template.r(z)).max() < 1e-9  # exact, not a sampled spline
        # a longer cylinder: type the line's end z; the right dome follows
        t.set_cell(1, C_Z, "400")
        assert w.wait_idle()
        assert w.job.mandrel.segments[1].to_mm == (400.0, 100.0)
        assert abs(w.mandrel.z_max - (template.z_max + 100.0)) < 1e-9
        assert w.actions["run"].isEnabled()
        # a bad cell: red, never applied, Run blocked with the reason
        before = w.job
        t.set_cell(1, C_R, "abc")
        assert w.wait_idle() and w.job == before
        assert "not a number" in t.message and not w.actions["run"].isEnabled()
        assert "not a number" in w.run_block_reason()
        t.set_cell(1, C_R, "100")
        assert w.wait_idle() and w.actions["run"].isEnabled()
        # undo goes back to the template
        w.undo_stack.undo()
        assert w.wait_idle()
        w.undo_stack.undo()
        assert w.wait_idle()
        assert w.job.mandrel.kind == "vessel"
    finally:
        close_window(w)


def test_geometric_error_comes_back_to_its_cell_and_corner_fillet(qtbot, tmp_path) -> None:
    from engine.job import load_job

    job = load_job(ROOT / "resources/examples/pipe.toml").replace(mandrel={
        "kind": "segments", "start_mm": [0.0, 75.0],
        "segments": [{"type": "line", "to_mm": [800.0, 75.0]},
                     {"type": "line", "to_mm": [1000.0, 60.0], "corner": True, "fillet_mm": 50.0}]})
    p = tmp_path / "seg.toml"
    p.write_text(job.to_toml(), "utf-8")
    w = shown_window(qtbot, p)
    try:
        t = w.mandrel_panel.segments_table
        assert [s.kind for s in w.mandrel.segments] == ["line", "arc", "line"]
        assert t.message == "" and w.actions["run"].isEnabled()
        # untick the corner: the lines are not tangent, the build says so at segment 2 and Run is blocked
        before = w.job
        t.set_cell(1, C_CORNER, "0")
        assert w.wait_idle()
        assert "fillet" in t.message  # fillet_mm without a corner
        t.set_cell(1, C_FILLET, "")
        assert w.wait_idle()
        assert "tangent" in t.message and not w.actions["run"].isEnabled()
        assert "tangent" in w.run_block_reason()
        assert t.table.item(1, C_CORNER).background() != t.table.item(0, C_CORNER).background()
        t.set_cell(1, C_CORNER, "1")
        t.set_cell(1, C_FILLET, "50")
        assert w.wait_idle()
        assert w.job == before and t.message == "" and w.actions["run"].isEnabled()
        # an arc whose end is not on its circle: the message lands on the segment's cell
        t.set_type(1, "arc")
        t.set_cell(1, C_CZ, "800")
        t.set_cell(1, 4, "0")  # centre r
        assert w.wait_idle()
        assert "is not on the" in t.message and not w.actions["run"].isEnabled()
        item = t.table.item(1, C_Z)
        assert "is not on the" in item.toolTip()
    finally:
        close_window(w)


def test_plot_drags_the_joints_of_a_sketch_with_snap(qtbot, tmp_path) -> None:
    from engine.job import load_job

    job = load_job(ROOT / "resources/examples/pipe.toml").replace(mandrel={
        "kind": "segments", "start_mm": [0.0, 60.0],
        "segments": [{"type": "line", "to_mm": [800.0, 75.0]},
                     {"type": "line", "to_mm": [1000.0, 60.0], "corner": True, "fillet_mm": 50.0}]})
    p = tmp_path / "seg.toml"
    p.write_text(job.to_toml(), "utf-8")
    w = shown_window(qtbot, p)
    try:
        ed = w.plot.editor
        assert ed.segment_mode
        z, r = ed.committed_points()
        assert list(z) == [0.0, 800.0, 1000.0] and list(r) == [60.0, 75.0, 60.0]  # start + two ends: 3 joints
        w.plot.set_snap(True, 0.5)
        assert ed.move_point(1, 700.2, 80.1) is None
        assert w.wait_idle()
        segs = w.job.mandrel.segments
        assert segs[0].to_mm == (700.0, 80.0) and segs[1].corner and segs[1].fillet_mm == 50.0  # snapped, kept
        assert w.mandrel_panel.segments_table.table.item(0, 1).text() == "700"  # the table follows
        # the same snap grid rounds what is typed into the table
        w.mandrel_panel.segments_table.set_cell(0, C_Z, "650.3")
        assert w.wait_idle()
        assert w.job.mandrel.segments[0].to_mm == (650.5, 80.0)
        w.plot.set_snap(False)
        w.mandrel_panel.segments_table.set_cell(0, C_Z, "700")
        assert w.wait_idle()
        assert [s.kind for s in w.mandrel.segments] == ["line", "arc", "line"]
        # adding or removing a joint on the plot is refused (segments are added in the table)
        before = w.job
        assert ed.add_point(900.0, 70.0) is not None
        assert ed.delete_point(1) is not None
        assert w.wait_idle() and w.job == before
        # z must increase
        assert ed.move_point(1, 1200.0, 70.0) is not None
        assert w.wait_idle() and w.job == before
    finally:
        close_window(w)


def test_csv_import_offers_smoothing_and_shows_the_deviation(qtbot, tmp_path) -> None:
    from engine.job import FileSpec, load_job

    rng = np.random.default_rng(5)
    z = np.linspace(0.0, 600.0, 61)
    r = 75.0 + rng.normal(0.0, 0.02, z.size)
    (tmp_path / "measured.csv").write_text("z,r\n" + "\n".join(f"{float(a)!r},{float(b)!r}" for a, b in zip(z, r)))
    job = load_job(ROOT / "resources/examples/pipe.toml").replace(mandrel=FileSpec(path="measured.csv"))
    p = tmp_path / "csvjob.toml"
    p.write_text(job.to_toml(), "utf-8")
    w = shown_window(qtbot, p)
    try:
        panel = w.mandrel_panel
        assert panel.current_kind() == "file" and panel.file_info.text() == ""
        panel.set_value("smoothing_mm", 0.05)
        assert w.wait_idle()
        assert w.job.mandrel.smoothing_mm == 0.05
        info = panel.file_info.text()
        assert "smoothed within 0.05 mm" in info and "max deviation" in info
        dev = w.mandrel.meta["smoothing"]["max_deviation_mm"]
        assert dev <= 0.05 and np.abs(w.mandrel.r(z) - r).max() == pytest.approx(dev)
        panel.set_value("smoothing_mm", "")  # back to the interpolating spline
        assert w.wait_idle()
        assert w.job.mandrel.smoothing_mm is None and panel.file_info.text() == ""
        panel.set_value("smoothing_mm", "-1")
        assert w.wait_idle() and "must be" in panel.error_text("smoothing_mm")
    finally:
        close_window(w)
