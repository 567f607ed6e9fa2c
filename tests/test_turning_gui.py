"""Tools → Turning optimiser dialog: it computes in a worker, shows the optimum and redraws the plot."""

from __future__ import annotations

import math

import pytest

from engine.turning import example_case_path, optimise
from winder_gui.dialogs.turning import TurningDialog


@pytest.fixture
def dialog(qtbot):
    d = TurningDialog()
    qtbot.addWidget(d)
    with qtbot.waitSignal(d.computed, timeout=10000):
        d.flush()
    yield d
    d.done(0)


def _wait(qtbot, d: TurningDialog, action) -> dict:
    with qtbot.waitSignal(d.computed, timeout=10000) as blocker:
        action()
        d.flush()
    return blocker.args[0]


def _optimum_on_plot(d: TurningDialog) -> tuple[float, float]:
    xs, ys = d.optimum_item.getOriginalDataset()  # linear n, S (getData() is log10 here)
    assert len(xs) == 1
    return float(xs[0]), float(ys[0])


def test_opens_on_the_paper_case(dialog: TurningDialog) -> None:
    res = dialog.result
    assert res.n_rpm == pytest.approx(411.38, abs=0.01) and res.feed_mm_rev == pytest.approx(0.8)
    assert "411.38 rpm" in dialog.summary.text()
    n, s = _optimum_on_plot(dialog)
    assert (n, s) == pytest.approx((res.n_rpm, res.feed_mm_rev))
    assert dialog.region_items  # the feasible region is shaded
    assert {"tool_life", "power", "roughness", "s_min", "s_max", "n_min", "n_max"} <= set(dialog.curves)
    xo, yo = dialog.objective_item.getOriginalDataset()
    assert xo[0] * yo[0] == pytest.approx(res.n_rpm * res.feed_mm_rev)  # n S = const through the optimum


def test_changing_the_material_updates_optimum_and_plot(dialog: TurningDialog, qtbot) -> None:
    before = dialog.result
    old_tool_life = [tuple(c.getOriginalDataset()[0]) for c in dialog.curves["tool_life"]]

    def change() -> None:
        dialog._set_combo(dialog.material, "steel45")
        dialog._set_combo(dialog.tool, "T15K6")

    out = _wait(qtbot, dialog, change)
    assert out["error"] is None
    res = dialog.result
    assert dialog.edits["sigma_b_mpa"].text() == "600"  # filled from materials.toml
    assert res.n_rpm != pytest.approx(before.n_rpm)
    # the same case computed directly agrees with what the dialog shows
    direct = optimise(dialog._case)
    assert res.n_rpm == pytest.approx(direct.n_rpm) and res.feed_mm_rev == pytest.approx(direct.feed_mm_rev)
    assert f"{res.n_rpm:.2f} rpm" in dialog.summary.text()
    assert _optimum_on_plot(dialog) == pytest.approx((res.n_rpm, res.feed_mm_rev))
    assert [tuple(c.getOriginalDataset()[0]) for c in dialog.curves["tool_life"]] != old_tool_life
    # the table shows the slack of every enabled row
    status = [dialog.table.item(i, 9).text() for i in range(dialog.table.rowCount())]
    assert status.count("ACTIVE") == len(res.active)


def test_bad_input_shows_an_inline_message(dialog: TurningDialog, qtbot) -> None:
    dialog.edits["depth_mm"].setText("-1")
    assert dialog.field_errors["depth_mm"].isVisibleTo(dialog)
    assert "positive" in dialog.field_errors["depth_mm"].text()
    assert "depth_mm" in dialog.message.text()
    dialog.edits["depth_mm"].setText("abc")
    assert "not a number" in dialog.field_errors["depth_mm"].text()
    dialog.edits["s_min_mm_rev"].setText("5")
    dialog.edits["depth_mm"].setText("1.5")
    assert "inverted" in dialog.message.text()
    out = _wait(qtbot, dialog, lambda: dialog.edits["s_min_mm_rev"].setText("0.1"))
    assert out["error"] is None and not dialog.field_errors["depth_mm"].isVisibleTo(dialog)


def test_infeasible_setup_names_the_conflict(dialog: TurningDialog, qtbot) -> None:
    out = _wait(qtbot, dialog, lambda: dialog.edits["rz_um"].setText("1"))
    assert out["result"] is None and out["error"] is not None
    assert "conflicts with" in dialog.message.text() and "roughness" in dialog.message.text()
    xs = dialog.optimum_item.getOriginalDataset()[0]
    assert xs is None or len(xs) == 0  # no optimum marked
    assert "roughness" in dialog.curves  # the lines are still drawn


def test_expert_mode_and_user_row(dialog: TurningDialog, qtbot) -> None:
    _wait(qtbot, dialog, lambda: dialog.load_case_file(str(example_case_path("paper_expert"))))
    assert dialog.current_mode() == "expert"
    assert dialog.result.n_rpm == pytest.approx(967.78, rel=1e-3)
    assert dialog.result.feed_mm_rev == pytest.approx(1.35, rel=1e-3)
    out = _wait(qtbot, dialog, dialog.add_user_row)  # n S <= 2000 does not bind (n S = 1306)
    assert out["result"].n_rpm == pytest.approx(967.78, rel=1e-3)
    row = dialog.table.rowCount() - 1
    _wait(qtbot, dialog, lambda: dialog.table.item(row, 5).setText(f"{math.log(1000.0):.9f}"))
    assert dialog.result.n_rpm * dialog.result.feed_mm_rev == pytest.approx(1000.0, rel=1e-6)
    assert "user1" in dialog.result.active


def test_switching_a_row_off(dialog: TurningDialog, qtbot) -> None:
    from PySide6.QtCore import Qt

    idx = [dialog.table.item(i, 2).text() for i in range(dialog.table.rowCount())].index("(8) surface roughness")
    _wait(qtbot, dialog, lambda: dialog.table.item(idx, 0).setCheckState(Qt.CheckState.Unchecked))
    assert "roughness" in dialog.result.disabled
    assert dialog.result.feed_mm_rev > 0.8


def test_missing_tool_factor_is_shown_not_raised(dialog: TurningDialog, qtbot) -> None:
    out = _wait(qtbot, dialog, lambda: dialog._set_combo(dialog.tool, "T15K6"))  # no K_uv for T15K6 on grey iron
    assert out["result"] is None
    assert "speed.toml" in dialog.message.text() and "T15K6" in dialog.message.text()
    xs = dialog.optimum_item.getOriginalDataset()[0]
    assert xs is None or len(xs) == 0
    out = _wait(qtbot, dialog, lambda: dialog._set_combo(dialog.tool, "VK8"))
    assert out["result"] is not None and dialog.message.text() == ""


def test_rows_to_expert_keeps_the_optimum(dialog: TurningDialog, qtbot) -> None:
    before = dialog.result
    _wait(qtbot, dialog, dialog.rows_to_expert)
    assert dialog.current_mode() == "expert"
    assert not dialog.edits["depth_mm"].isEnabled() and dialog.edits["diameter_mm"].isEnabled()
    assert dialog.result.n_rpm == pytest.approx(before.n_rpm, rel=1e-9)
    assert dialog.result.feed_mm_rev == pytest.approx(before.feed_mm_rev, rel=1e-9)
