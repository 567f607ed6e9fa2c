"""GUI tests of the sketched generatrix (issue 9, point 2): numeric table and snap (pytest-qt, offscreen).

The table and the r(z) plot edit the same job: a typed cell changes the job's points (undoably),
a point dragged on the plot shows in the table, the snap puts points on the grid, a pasted block
fills rows, and a bad cell is red with a message, blocks Run with the reason and never reaches the
job.  Assertions are on the job's data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gui_helpers import close_window, shown_window
from PySide6.QtCore import QEvent, QPointF, Qt
from PySide6.QtGui import QGuiApplication, QMouseEvent
from PySide6.QtWidgets import QAbstractItemView, QApplication

from engine.job import PointsSpec, load_job
from winder_gui.main_window import MainWindow
from winder_gui.panels.points_table import check_table, parse_block
from winder_gui.views.profile_plot import ProfilePlot, snap_to_grid

ROOT = Path(__file__).resolve().parents[1]
Z0 = [0.0, 200.0, 400.0, 600.0, 800.0, 1000.0]
R0 = [70.0, 75.0, 75.0, 75.0, 75.0, 70.0]
LEFT, NONE = Qt.MouseButton.LeftButton, Qt.MouseButton.NoButton


@pytest.fixture
def sketch_job(tmp_path) -> Path:
    job = load_job(ROOT / "resources/examples/pipe.toml").replace(mandrel=PointsSpec(z_mm=Z0, r_mm=R0))
    p = tmp_path / "sketch.toml"
    p.write_text(job.to_toml(), "utf-8")
    return p


@pytest.fixture
def window(qtbot, sketch_job):
    w = shown_window(qtbot, sketch_job)
    w.go_to_step("mandrel")
    yield w
    close_window(w)


def _table_values(w: MainWindow) -> tuple[np.ndarray, np.ndarray]:
    vals = w.mandrel_panel.points_table.values()
    assert vals is not None
    return vals


def _shown(w: MainWindow, row: int, col: int) -> str:
    return w.mandrel_panel.points_table.table.item(row, col).text()


def _job_points(w: MainWindow) -> tuple[list[float], list[float]]:
    spec = w.job.mandrel
    assert isinstance(spec, PointsSpec)
    return list(spec.z_mm), list(spec.r_mm)


# ------------------------------------------------------------------------------------------------
def test_table_shows_the_sketch(window) -> None:
    w = window
    panel = w.mandrel_panel
    assert panel.current_kind() == "points"
    assert panel.points_table.isVisibleTo(panel) and not panel.convert_button.isVisibleTo(panel)
    z, r = _table_values(w)
    assert list(z) == Z0 and list(r) == R0
    assert [_shown(w, i, 0) for i in range(6)] == ["0", "200", "400", "600", "800", "1000"]
    assert w.actions["run"].isEnabled() and w.run_block_reason() == ""


def test_typed_cell_changes_the_job_and_undo_restores_it(window, qtbot) -> None:
    w = window
    t = w.mandrel_panel.points_table
    # typed with the keyboard: select the cell, type, Enter
    w.activateWindow()
    t.table.setFocus()
    t.table.setCurrentCell(2, 1)
    qtbot.keyClick(t.table, "8")  # any key starts editing the current cell
    editor = QApplication.focusWidget()
    assert editor is not t.table
    qtbot.keyClicks(editor, "2,5")  # a decimal comma is accepted
    qtbot.keyClick(editor, Qt.Key.Key_Return)
    qtbot.waitUntil(lambda: t.table.state() != QAbstractItemView.State.EditingState)  # the commit is queued
    assert w.wait_idle()
    assert _job_points(w) == (Z0, [70.0, 75.0, 82.5, 75.0, 75.0, 70.0])
    np.testing.assert_array_equal(w.plot.editor.committed_points()[1], [70.0, 75.0, 82.5, 75.0, 75.0, 70.0])
    assert _shown(w, 2, 1) == "82.5"
    # through the API: z of a point
    t.set_cell(3, 0, "550")
    assert w.wait_idle()
    assert _job_points(w)[0] == [0.0, 200.0, 400.0, 550.0, 800.0, 1000.0]
    # undo twice: the job and the table are back
    w.undo_stack.undo()
    assert w.wait_idle()
    assert _job_points(w)[0][3] == 600.0 and _shown(w, 3, 0) == "600"
    w.undo_stack.undo()
    assert w.wait_idle()
    assert _job_points(w) == (Z0, R0)
    assert list(_table_values(w)[1]) == R0
    w.undo_stack.redo()
    assert w.wait_idle()
    assert _job_points(w)[1][2] == 82.5 and _shown(w, 2, 1) == "82.5"


def test_untouched_cells_keep_exact_values(window) -> None:
    """Cells show 4 decimals, but editing one point never rounds the others."""
    w = window
    t = w.mandrel_panel.points_table
    t.set_cell(1, 1, "75.123456789")
    assert w.wait_idle()
    assert _shown(w, 1, 1) == "75.1235"
    assert _job_points(w)[1][1] == 75.123456789
    t.set_cell(4, 1, "76")
    assert w.wait_idle()
    assert _job_points(w)[1] == [70.0, 75.123456789, 75.0, 75.0, 76.0, 70.0]


def test_drag_on_the_plot_updates_the_table(window) -> None:
    w = window
    ed = w.plot.editor
    # during a drag (attached): the table follows live, the job does not change yet
    assert ed.move_point(2, 410.0, 90.0, finish=False) is None
    assert _shown(w, 2, 0) == "410" and _shown(w, 2, 1) == "90"
    assert _job_points(w) == (Z0, R0)
    # released: applied, and the table shows the job's points
    assert ed.move_point(2, 410.0, 90.0) is None
    assert w.wait_idle()
    assert _job_points(w)[1][2] == 90.0 and _job_points(w)[0][2] == 410.0
    z, r = _table_values(w)
    assert list(z) == _job_points(w)[0] and list(r) == _job_points(w)[1]
    # an added point becomes a new row
    assert ed.add_point(500.0, 80.0) is None
    assert w.wait_idle()
    assert w.mandrel_panel.points_table.table.rowCount() == 7
    assert _shown(w, 3, 0) == "500" and _shown(w, 3, 1) == "80"
    # a click on a point selects its row, a row selects its point
    ed.selected.emit(4)
    assert w.mandrel_panel.points_table.table.currentRow() == 4
    w.mandrel_panel.points_table.table.setCurrentCell(1, 0)
    assert ed.selected_index == 1


def test_rows_in_concave_zones_are_marked(window) -> None:
    w = window
    t = w.mandrel_panel.points_table
    t.set_cell(2, 1, "40")  # a waist at z = 400: concave around it
    assert w.wait_idle()
    zones = w.view_data.concave
    assert any(a <= 400.0 <= b for a, b in zones)
    z = _job_points(w)[0]
    expect = [i for i, v in enumerate(z) if any(a <= v <= b for a, b in zones)]
    assert 2 in expect and t.concave_rows() == expect
    head = t.table.verticalHeaderItem(2)
    assert "◐" in head.text() and "concave zone" in head.toolTip()
    assert "◐" not in t.table.verticalHeaderItem(0).text() or 0 in expect


def test_table_follows_the_job_without_attach(qtbot, sketch_job) -> None:
    """Without the live link, an applied plot edit still reaches the table (through the job)."""
    w = MainWindow(sketch_job)
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    assert w.plot.editor.move_point(1, 200.0, 66.0) is None
    assert w.wait_idle()
    assert _shown(w, 1, 1) == "66"
    w.close()


def test_snap_puts_points_on_the_grid(window, tmp_path) -> None:
    w = window
    ed = w.plot.editor
    w.plot.set_snap(True, 5.0)
    assert w.plot.snap_step == 5.0 and "5 mm grid" in w.plot.hint_label.text()
    assert ed.add_point(333.3, 51.7) is None
    assert w.wait_idle()
    z, r = _job_points(w)
    assert 335.0 in z and r[z.index(335.0)] == 50.0
    for v in (*z, *r):
        assert v == pytest.approx(5.0 * round(v / 5.0), abs=1e-9)
    # a drag lands on the grid too
    assert ed.move_point(1, 187.9, 58.6) is None
    assert w.wait_idle()
    assert _job_points(w)[0][1] == 190.0 and _job_points(w)[1][1] == 60.0
    # r snaps to a neighbour's r within a few pixels (even off the grid)
    w.mandrel_panel.points_table.set_cell(3, 1, "72.3")  # row 3 is the point after the added one
    assert w.wait_idle()
    px = w.plot.plot_r.getViewBox().viewPixelSize()[1]
    assert ed.move_point(4, 600.0, 72.3 - 2.0 * px) is None  # the other neighbour (75) is farther
    assert w.wait_idle()
    assert _job_points(w)[1][4] == 72.3
    # decimal steps give exact decimals
    assert snap_to_grid(0.30000001, 0.1) == 0.3 and snap_to_grid(-7.4, 2.5) == -7.5
    # snap off: points land where they are put
    w.plot.set_snap(False)
    assert "grid" not in w.plot.hint_label.text()
    assert ed.add_point(901.3, 71.7) is None
    assert w.wait_idle()
    assert 901.3 in _job_points(w)[0]
    # persisted: a new plot starts with the last step, snap off
    w.plot.set_snap(True, 2.5)
    fresh = ProfilePlot()
    assert fresh.snap_check.isChecked() and fresh.snap_step == 2.5
    fresh.deleteLater()


def test_snap_with_the_mouse(window, qtbot) -> None:
    """A double-click on the plot adds a point on the grid (the scene path, not only the API)."""
    w = window
    qtbot.wait(20)
    w.plot.set_snap(True, 5.0)
    vb = w.plot.plot_r.getViewBox()
    pos = w.plot.graphics.mapFromScene(vb.mapViewToScene(QPointF(510.4, 54.6)))
    vp = w.plot.graphics.viewport()
    for kind, buttons in ((QEvent.Type.MouseButtonPress, LEFT), (QEvent.Type.MouseButtonRelease, NONE),
                          (QEvent.Type.MouseButtonDblClick, LEFT), (QEvent.Type.MouseButtonRelease, NONE)):
        p = QPointF(pos)
        ev = QMouseEvent(kind, p, vp.mapToGlobal(p), LEFT, buttons, Qt.KeyboardModifier.NoModifier)
        QApplication.sendEvent(vp, ev)
    assert w.wait_idle()
    z, r = _job_points(w)
    assert len(z) == 7
    k = int(np.argmin(np.abs(np.asarray(z) - 510.4)))
    assert z[k] == 510.0 and r[k] == 55.0  # grid points nearest the click (a pixel is ~1 mm here)
    assert _shown(w, k, 0) == "510"


def test_paste_a_block(window, qtbot) -> None:
    w = window
    t = w.mandrel_panel.points_table
    # 3x2 from a spreadsheet (tabs, decimal comma) into rows 2..4
    assert t.paste("100\t61\n150\t62,5\n250\t63\n", row=1, col=0) == 3
    assert w.wait_idle()
    assert _job_points(w) == ([0.0, 100.0, 150.0, 250.0, 800.0, 1000.0], [70.0, 61.0, 62.5, 63.0, 75.0, 70.0])
    # from the clipboard with Ctrl+V, comma separated with a header, past the end: rows are appended
    QGuiApplication.clipboard().setText("z,r\n1100,60\n1200,50\n")
    t.table.setFocus()
    t.table.setCurrentCell(5, 0)
    qtbot.keyClick(t.table, Qt.Key.Key_V, Qt.KeyboardModifier.ControlModifier)
    assert w.wait_idle()
    assert _job_points(w)[0] == [0.0, 100.0, 150.0, 250.0, 800.0, 1100.0, 1200.0]
    assert _job_points(w)[1][-2:] == [60.0, 50.0]
    # one column fills the current column only
    assert t.paste("64 65", row=2, col=1) == 1  # blanks split fields: 2 columns -> z=64 is not after 100
    assert "row 3, z" in w.run_block_reason()
    t.set_cell(2, 0, "150")
    assert w.wait_idle()
    assert _job_points(w)[1][2] == 65.0
    assert t.paste("66\n67", row=2, col=1) == 2
    assert w.wait_idle()
    assert _job_points(w)[1][2:4] == [66.0, 67.0]
    # nothing numeric: a message, nothing changes
    before = w.job
    assert t.paste("hello", row=0, col=0) == 0
    assert "Nothing to paste" in t.message_label.text()
    assert w.wait_idle() and w.job == before


@pytest.mark.parametrize(
    ("row", "col", "text", "expect"),
    [
        (2, 1, "abc", "not a number"),
        (2, 1, "", "a value is required"),
        (2, 1, "-3", "r must be > 0"),
        (2, 1, "0", "r must be > 0"),
        (3, 0, "400", "z must increase"),
        (3, 0, "150", "z must increase"),
        (1, 0, "nan", "not a finite number"),
    ],
)
def test_invalid_cells_are_red_not_applied_and_block_run(window, row, col, text, expect) -> None:
    w = window
    t = w.mandrel_panel.points_table
    before = w.job
    t.set_cell(row, col, text)
    # at the cell: red, with the message as tooltip; the message under the table
    assert expect in t.cell_problem(row, col)
    item = t.table.item(row, col)
    assert item.background().color().red() == 255 and item.background().color().green() < 255
    assert expect in item.toolTip()
    assert t.message_label.isVisibleTo(t) and expect in t.message_label.text()
    assert f"row {row + 1}, {'zr'[col]}" in t.message_label.text()
    # Run is disabled with the reason, and the job never got the value
    assert not w.actions["run"].isEnabled()
    assert expect in w.run_block_reason() and "sketch table" in w.run_block_reason()
    assert w.wait_idle()
    assert w.job == before and not w.dirty
    np.testing.assert_array_equal(w.plot.editor.committed_points()[0], Z0)
    # the message is not shown twice (table + panel status)
    assert not w.mandrel_panel.status.isVisibleTo(w.mandrel_panel)
    # fixed: applied, Run enabled again
    t.set_cell(row, col, "77" if col == 1 else str(Z0[row] + 1.0))
    assert t.cell_problem(row, col) == "" and not t.message_label.isVisibleTo(t)
    assert w.actions["run"].isEnabled() and w.run_block_reason() == ""
    assert w.wait_idle()
    assert w.job != before and t.table.item(row, col).toolTip() == ""


def test_a_closed_pole_may_have_r_zero_at_an_end(window) -> None:
    w = window
    w.mandrel_panel.points_table.set_cell(0, 1, "0")
    assert w.wait_idle()
    assert _job_points(w)[1][0] == 0.0 and w.run_block_reason() == ""


def test_add_insert_delete_rows(window, qtbot) -> None:
    w = window
    t = w.mandrel_panel.points_table
    t.add_button.click()
    assert w.wait_idle()
    assert _job_points(w) == ([*Z0, 1200.0], [*R0, 70.0])
    t.table.setCurrentCell(1, 0)
    t.insert_button.click()  # midway between rows 2 and 3
    assert w.wait_idle()
    z, r = _job_points(w)
    assert z[2] == 300.0 and r[2] == 75.0 and len(z) == 8
    # Delete key on the selected rows (not while editing a cell)
    t.table.setFocus()
    t.table.clearSelection()
    t.table.setCurrentCell(2, 0)
    t.table.selectRow(2)
    qtbot.keyClick(t.table, Qt.Key.Key_Delete)
    assert w.wait_idle()
    assert _job_points(w) == ([*Z0, 1200.0], [*R0, 70.0])
    t.table.clearSelection()
    t.table.setCurrentCell(6, 1)
    t.delete_button.click()
    assert w.wait_idle()
    assert _job_points(w) == (Z0, R0)
    # down to 4 is fine, fewer is refused with a message and nothing changes
    t.delete_rows([1, 2])
    assert w.wait_idle()
    assert _job_points(w) == ([0.0, 600.0, 800.0, 1000.0], [70.0, 75.0, 75.0, 70.0])
    before = w.job
    t.delete_rows([1])
    assert "at least 4 points" in t.message_label.text() and t.table.rowCount() == 4
    assert w.wait_idle() and w.job == before and w.actions["run"].isEnabled()


def test_template_offers_convert_to_sketch(qtbot) -> None:
    w = MainWindow(ROOT / "resources/examples/pressure_vessel.toml")
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    panel = w.mandrel_panel
    assert panel.current_kind() == "vessel"
    assert panel.convert_button.isVisibleTo(panel) and not panel.points_table.isVisibleTo(panel)
    from engine.job import build_mandrel

    template = build_mandrel(w.job)
    # "Sketched points" in the kind selector samples the template (Convert to sketch gives exact segments:
    # tests/test_gui_segments.py)
    panel.kind_combo.setCurrentIndex(panel.kind_combo.findData("points"))
    panel.kind_combo.activated.emit(panel.kind_combo.currentIndex())
    assert w.wait_idle()
    assert panel.current_kind() == "points" and panel.points_table.isVisibleTo(panel)
    z, r = _job_points(w)
    assert len(z) >= 4 and list(_table_values(w)[0]) == z
    # the sketch goes through the template's curve at its points, and its spline stays within
    # 0.01 mm of the template between them
    np.testing.assert_allclose(r, template.r(np.asarray(z)), atol=1e-9)
    from engine.mandrel import Mandrel

    zz = np.linspace(z[0], z[-1], 20001)
    assert np.max(np.abs(Mandrel.from_points(z, r).r(zz) - template.r(zz))) < 0.012 and len(z) > 20
    w.undo_stack.undo()
    assert w.wait_idle()
    assert w.job.mandrel.kind == "vessel" and panel.convert_button.isVisibleTo(panel)
    w.close()


# ------------------------------------------------------------------------------------------------
def test_parse_block() -> None:
    assert parse_block("z [mm]\tr [mm]\n1,5\t2\n\n3\t4,25\r\n") == [["1,5", "2"], ["3", "4,25"]]
    assert parse_block("1, 2\n3 4\n5;6") == [["1", "2"], ["3", "4"], ["5", "6"]]
    assert parse_block("  \n") == []
    # blanks and decimal commas in one line: the blanks separate, the commas are decimal
    assert parse_block("12,5 80\n13,5  81,25\n") == [["12,5", "80"], ["13,5", "81,25"]]
    assert parse_block("1, 2\n3, 4") == [["1", "2"], ["3", "4"]]
    # a mistyped first data row is kept (and reported in its cell), not dropped as a header
    assert parse_block("x1,2\n3,4") == [["x1", "2"], ["3", "4"]]


def test_check_table_cells() -> None:
    z, r, probs = check_table([("0", "0"), ("1", "2"), ("2", "3"), ("3", "0")])
    assert probs == {} and list(r) == [0.0, 2.0, 3.0, 0.0]
    z, r, probs = check_table([("0", "1"), ("x", "2"), ("2", "3")])
    assert z is None and set(probs) == {(1, 0), (-1, -1)}
    _, _, probs = check_table([("0", "1"), ("2", "2"), ("1", "3"), ("3", "4")])
    assert set(probs) == {(2, 0)}  # only the row that goes back, not the next one
