"""Tools → Slot forming dialog (winder_gui/dialogs/slotting.py), offscreen with pytest-qt."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pyqtgraph as pg
import pytest

from engine.slotting import SlotSetup, slot_table, table_csv
from winder_gui.dialogs import slotting as dlg_mod
from winder_gui.dialogs.slotting import SlotDialog, parse_inputs


@pytest.fixture
def dialog(qtbot) -> SlotDialog:
    d = SlotDialog()
    qtbot.addWidget(d)
    assert d.wait_idle()
    yield d
    d.wait_idle()


def _curves(plot: pg.PlotWidget) -> list[pg.PlotDataItem]:
    return [it for it in plot.getPlotItem().listDataItems() if isinstance(it, pg.PlotDataItem)]


def test_opens_with_the_papers_case_computed(dialog: SlotDialog) -> None:
    """The defaults are Table 2 (ρ = 22, R_u = −95, i = −2, l = 2…20, [Δ] = 0.005)."""
    assert dialog.study is not None
    expected = slot_table(np.arange(2.0, 20.5, 2.0), SlotSetup(22.0, -95.0, -2.0, 0.005))
    t = dialog.table
    assert t.rowCount() == 10
    for n, row in enumerate(expected.rows):
        assert float(t.item(n, 0).text()) == pytest.approx(row.l)
        assert float(t.item(n, 1).text()) == pytest.approx(row.A, abs=1e-4)
        assert int(t.item(n, 5).text()) == row.iterations
        assert t.item(n, 7).text() == "iteration"
    assert dialog.compute_button.isEnabled() and dialog.export_button.isEnabled()
    assert "down-cut" in dialog.mode_label.text()
    assert "i1 = R_u/R_d = -4.3182" in dialog.reduced_label.text()
    # three plots: 5 A(i) curves, 7 error histories, the path S with the bore circle and slot ends
    assert len(_curves(dialog.plot_ai)) == 5
    assert len(_curves(dialog.plot_err)) == 7
    assert len(_curves(dialog.plot_path)) >= 3


def test_compute_runs_in_a_worker_thread(dialog: SlotDialog, qtbot, monkeypatch) -> None:
    threads: list[threading.Thread] = []
    real = dlg_mod.slot_study

    def spy(*args, **kwargs):
        threads.append(threading.current_thread())
        return real(*args, **kwargs)

    monkeypatch.setattr(dlg_mod, "slot_study", spy)
    dialog.set_inputs(ratio=-1)
    with qtbot.waitSignal(dialog.computed, timeout=10000):
        dialog.compute()
    assert threads and threads[0] is not threading.main_thread()
    assert float(dialog.table.item(9, 1).text()) == pytest.approx(112.603, abs=6e-4)  # Table 3, l = 20


@pytest.mark.parametrize(
    "field, text, fragment",
    [
        ("rho", "abc", "not a number"),
        ("rho", "-5", "forming radius"),
        ("tool_radius", "0", "tool radius"),
        ("tol", "2", "[Δ]"),
        ("lengths", "2:20", "FROM:TO:STEP"),
        ("lengths", "0:20:2", "slot length"),
        ("max_iter", "2.5", "iteration budget"),
        ("curve_ratios", "-4:4:0", "step"),
        ("focus_length", "1, 2", "one slot length"),
    ],
)
def test_bad_input_inline_message_disables_buttons(dialog: SlotDialog, field: str, text: str,
                                                   fragment: str) -> None:
    dialog.set_inputs(**{field: text})
    assert not dialog.error_label.isHidden()
    assert fragment in dialog.error_label.text()
    assert not dialog.compute_button.isEnabled() and not dialog.export_button.isEnabled()
    dialog.compute()  # a no-op, never a crash
    assert not dialog.is_busy()
    dialog.set_inputs(**{field: dialog_default(field)})
    assert dialog.error_label.isHidden() and dialog.compute_button.isEnabled()
    # the shown results are stale until recomputed
    assert not dialog.export_button.isEnabled()
    dialog.compute()
    assert dialog.wait_idle() and dialog.export_button.isEnabled()


def dialog_default(field: str) -> str:
    return {k: d for k, _, d, _ in dlg_mod._FIELDS}[field]


def test_unreachable_and_fallback_rows_are_reported(dialog: SlotDialog) -> None:
    dialog.set_inputs(rho=60, tool_radius=25, ratio=0.5, lengths="20, 60", focus_length=80)
    dialog.compute()
    assert dialog.wait_idle()
    status = dialog.status_label.text()
    assert "bracketing solver" in status and "cannot be reached" in status
    assert dialog.table.item(0, 7).text() == "fallback"
    assert dialog.table.item(1, 1).text() == "—"
    assert "cannot be reached" in dialog.table.item(1, 8).text()
    assert "cannot be reached" in dialog.plot_path.getPlotItem().titleLabel.text
    assert "≥ 1" in dialog.mode_label.text()


def test_engine_failure_is_shown_not_raised(dialog: SlotDialog, monkeypatch) -> None:
    def boom(*args, **kwargs):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(dlg_mod, "slot_study", boom)
    dialog.compute()
    assert dialog.wait_idle()
    assert "failed unexpectedly" in dialog.error_label.text() and "kaboom" in dialog.error_label.text()


def test_export_csv_atomic(dialog: SlotDialog, tmp_path: Path) -> None:
    out = tmp_path / "slots.csv"
    assert dialog.export_csv(str(out))
    assert dialog.study is not None
    assert out.read_text(encoding="utf-8") == table_csv(dialog.study.table)
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind
    assert not dialog.export_csv(str(tmp_path / "no-such-dir" / "x.csv"))
    assert "cannot write" in dialog.error_label.text()


def test_paper_formula_choice(dialog: SlotDialog) -> None:
    dialog.set_inputs(a_formula="paper", ratio=0)
    dialog.compute()
    assert dialog.wait_idle()
    assert dialog.study is not None
    row = dialog.study.table.rows[-1]
    assert row.A == row.A_paper and float(dialog.table.item(9, 1).text()) == pytest.approx(row.A_paper, abs=1e-4)
    # the path S shows what the printed closure really cuts: 18.06 mm instead of 20 mm
    assert "slot 18.06" in dialog.plot_path.getPlotItem().titleLabel.text


def test_parse_inputs_defaults() -> None:
    inp = parse_inputs({k: d for k, _, d, _ in dlg_mod._FIELDS})
    assert inp.setup == SlotSetup(22.0, -95.0, -2.0, 0.005, None, 100, "exact")
    assert inp.lengths == pytest.approx(np.arange(2.0, 20.5, 2.0))
    assert inp.focus_length == 20.0 and math.isclose(inp.curve_ratios[-1], 4.0)


