"""The Time law step shows the job's own time laws (issue 9 item 6), pytest-qt, offscreen.

The pipe example runs with ``[timelaw].method = "tube"``; it is a laminate, so the Law chooser offers
the laws of the blocks stage of the layer shown (its helical layer is selected here).  The plotted
iteration curves, tube bounds, W/O touches and the final ṡ(t) must be the arrays of the pipeline's
:class:`engine.timeparam.TimeLaw`; the comparison laws (classical DP and TOPP-RA, computed in the
worker on the same path and limits) bound it independently: TOPP-RA is the time-optimal law, so the
tube law cannot be faster.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from winder_gui.main_window import JobTimeLawResult, MainWindow

ROOT = Path(__file__).resolve().parents[1]
PIPE = ROOT / "resources" / "examples" / "pipe.toml"


@pytest.fixture
def ran(qtbot):
    w = MainWindow(PIPE)
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    if w.job.timelaw.method != "tube":
        w.timelaw_panel.set_value("timelaw.method", "tube")
        assert w.wait_idle()
    assert w.run_pipeline_now()
    assert w.wait_idle(180000) and w.last_error == "", w.last_error
    helical = next(i for i, lay in enumerate(w.job.layers) if lay.kind == "helical")
    w.layers_panel.select_layer(helical)
    assert w.wait_idle(120000)
    res = w.results.law_result()
    assert res is w.result.layer(helical).result and res.timelaw_laws
    yield w
    w.wait_idle(120000)
    w.close()


def _labels(w: MainWindow) -> list[str]:
    c = w.timelaw_plot.law_choice
    return [c.itemText(i) for i in range(c.count())]


def test_chooser_offers_the_job_laws_with_the_main_law_by_default(ran) -> None:
    w, res = ran, ran.results.law_result()
    assert _labels(w) == ["paper example", *[f"job: {lab}" for lab in res.timelaw_labels]]
    assert w.timelaw_plot.selected_law() == res.timelaw_main >= 0
    assert res.timelaw_labels[res.timelaw_main] == "circuit (repeated)"   # the pipe repeats its circuits


def test_job_law_iterations_and_comparison(ran, qtbot) -> None:
    w, res = ran, ran.results.law_result()
    with qtbot.waitSignal(w.timelaw_done, timeout=120000) as sig:
        w.go_to_step("timelaw")                 # the chosen job law is computed on entering the step
    assert w.wait_idle(120000) and w.last_error == ""
    r = sig.args[0]
    assert isinstance(r, JobTimeLawResult) and r is w.job_timelaw
    i = res.timelaw_main
    law = res.timelaw_laws[i]
    assert r.law is law and law.method == "tube" and len(law.iterations) >= 2
    off = res.timelaw_paths[i].iteration_s_offset
    plot = w.timelaw_plot
    assert [k for k in plot.curves if k.startswith("iteration ")] == [f"iteration {g.r}" for g in law.iterations]
    for g in law.iterations:
        x, y = plot.curve_data(f"iteration {g.r}")
        np.testing.assert_array_equal(x, g.s + off)
        np.testing.assert_array_equal(y, g.sdot)
    last = law.iterations[-1]
    np.testing.assert_array_equal(plot.curve_data("tube lower")[1], last.lower)
    np.testing.assert_array_equal(plot.curve_data("tube upper")[1], last.upper)
    np.testing.assert_array_equal(plot.curve_data("W touches")[0], (last.s + off)[np.asarray(last.w_mask, bool)])
    np.testing.assert_array_equal(plot.curve_data("O touches")[1], last.sdot[np.asarray(last.o_mask, bool)])
    first = law.iterations[0]
    plot.bounds_of.setValue(first.r)
    np.testing.assert_array_equal(plot.curve_data("tube lower")[1], first.lower)
    # final ṡ(t): the job's law itself, and the comparison laws on the same path
    x, y = plot.curve_data("final job tube")
    np.testing.assert_array_equal(x, law.t)
    np.testing.assert_array_equal(y, law.sdot)
    s = res.timelaw_paths[i].s
    for name, other in (("DP", r.dp), ("TOPP-RA", r.toppra)):
        x, y = plot.curve_data(f"final {name}")
        np.testing.assert_array_equal(x, other.t)
        np.testing.assert_array_equal(y, other.sdot)
        assert other.s[-1] == pytest.approx(s[-1]) and other.s[-1] == pytest.approx(law.s[-1])
    # independent check: TOPP-RA is the time-optimal bound; the tube law can only be slower (0.5 % grid slack)
    assert r.toppra.total_time_s <= law.total_time_s * 1.005
    assert law.total_time_s <= r.dp.total_time_s * (1 + 1e-9)   # the tube refines the single DP
    text = w.timelaw_panel.summary.text()
    assert f"{law.total_time_s:.3f} s" in text
    # the final sweep's saving, and TOPP-RA's limits between its nodes, are said when they apply
    assert ("the final sweep saved" in text) == (law.sweep_gain_s > 0)
    broken = max(r.toppra.max_accel_ratio, r.toppra.max_speed_ratio) > 1.0 + 1e-6
    assert ("breaks the limits between its nodes" in text) == broken


def test_switch_to_paper_example_and_another_job_law(ran, qtbot) -> None:
    w, res = ran, ran.results.law_result()
    w.go_to_step("timelaw")
    assert w.wait_idle(120000)
    w.timelaw_plot.select_law(-1)                   # the paper example: computed on demand (Compute button)
    with qtbot.waitSignal(w.timelaw_done, timeout=180000):
        w.timelaw_panel.compute_button.click()
    assert w.wait_idle(180000) and w.last_error == ""
    assert w.timelaw is not None and w.timelaw.source.startswith("paper example")
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("final tube")[0], w.timelaw.tube.t)
    k = 0 if res.timelaw_main != 0 else len(res.timelaw_laws) - 1
    with qtbot.waitSignal(w.timelaw_done, timeout=120000) as sig:
        w.timelaw_plot.select_law(k)
    assert w.wait_idle(120000) and w.last_error == ""
    r = sig.args[0]
    assert r.index == k and r.law is res.timelaw_laws[k]
    np.testing.assert_array_equal(w.timelaw_plot.curve_data("final job tube")[1], r.law.sdot)
    g = r.law.iterations[-1]
    np.testing.assert_array_equal(w.timelaw_plot.curve_data(f"iteration {g.r}")[0],
                                  g.s + res.timelaw_paths[k].iteration_s_offset)
    assert r.toppra.total_time_s <= r.law.total_time_s * 1.005


def test_final_sweep_field_sets_the_job(qtbot) -> None:
    """The time law panel's "Final sweep" choice is the job's ``[timelaw] sweep`` (shown, edited, undone)."""
    w = MainWindow(PIPE)
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    ed = w.timelaw_panel.editor("timelaw.sweep")
    assert w.job.timelaw.sweep is True and ed.currentText() == "True"
    w.timelaw_panel.set_value("timelaw.sweep", "False")
    assert w.wait_idle()
    assert w.job.timelaw.sweep is False and w.timelaw_panel.errors() == ""
    w.undo_stack.undo()
    assert w.wait_idle()
    assert w.job.timelaw.sweep is True and w.timelaw_panel.editor("timelaw.sweep").currentText() == "True"
    w.close()
