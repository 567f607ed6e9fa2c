"""The Time law tab: the path speed law ṡ(s) of the chosen method, its iterations and bounds (a page of
:mod:`winder_gui.views.plots`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QSpinBox,
    QWidget,
)

from winder_gui.i18n import tr
from winder_gui.views.plots import (
    MAX_ITERATION_CURVES,
    PlotPage,
)


class TimeLawPlot(PlotPage):
    """The DP tube iterations ṡ(s) with tube bounds and W/O touches; final ṡ(t) vs DP and TOPP-RA.

    The *Law* chooser picks the paper's example or one of the job's own time laws (the blocks stage's
    laws: repeated circuit, first/last circuit ramps, or the whole program); :attr:`law_selected`
    carries -1 for the paper example, else the index in ``PipelineResult.timelaw_laws``.
    """

    title = "time_law"
    PAPER = "paper example"
    law_selected = Signal(int)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        it = self.add_plot("iterations", 0, 0, tr("ṡ [mm/s]"), tr("s [mm]"), title=tr("tube iterations ṡ(s)"))
        # one row of legend entries at the top right, on a light background: the plots are short
        legend = {"offset": (-10, 5), "colCount": 3, "brush": pg.mkBrush(255, 255, 255, 210),
                  "labelTextColor": "#222"}
        it.addLegend(**legend)
        fin = self.add_plot("final", 1, 0, tr("ṡ [mm/s]"), "t [s]", title=tr("final ṡ(t)"))
        fin.addLegend(**legend)
        self.iterations: list[Any] = []
        self.s_offset = 0.0
        """Added to the iteration log's s (mm) to place it on the law's s (the last circuit's ramp)."""
        self.law_choice = QComboBox()
        self.law_choice.setObjectName("timelaw.law")
        self.law_choice.setToolTip(tr("Whose time law to show: the paper's 7-axis example, or one of the laws "
                                   "the pipeline computed for this job's axis path ([timelaw].method tube/dp/toppra)"))
        self.law_choice.addItem(self.PAPER, -1)
        self.law_choice.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self.law_choice.currentIndexChanged.connect(lambda _i: self.law_selected.emit(self.selected_law()))
        self.bounds_of = QSpinBox()
        self.bounds_of.setObjectName("timelaw.bounds_of")
        self.bounds_of.setPrefix(tr("tube of r = "))
        self.bounds_of.setToolTip(tr("Which iteration's tube bounds (dashed) and touches (W: ▲ red, O: ● blue) "
                                  "are marked"))
        self.bounds_of.setEnabled(False)
        self.bounds_of.valueChanged.connect(self.show_iteration)
        # a row of its own above the message: the message wraps and would squeeze the plots
        controls = QHBoxLayout()
        controls.setContentsMargins(4, 2, 4, 2)
        law_label = QLabel(tr("Law:"))
        law_label.setBuddy(self.law_choice)
        controls.addWidget(law_label)
        controls.addWidget(self.law_choice)
        controls.addSpacing(12)
        controls.addWidget(self.bounds_of)
        controls.addStretch(1)
        self.layout().insertLayout(0, controls)

    def set_law_choices(self, labels: list[str] | tuple[str, ...], current: int = -1) -> None:
        """Offer the paper example and the job's laws ``labels`` (as "job: <label>"); select law
        ``current`` (-1 = the paper example) without emitting :attr:`law_selected`."""
        self.law_choice.blockSignals(True)
        self.law_choice.clear()
        self.law_choice.addItem(self.PAPER, -1)
        for i, lab in enumerate(labels):
            self.law_choice.addItem(tr("job: {lab}").format(lab=lab), i)
        self.law_choice.setCurrentIndex(max(self.law_choice.findData(current), 0))
        self.law_choice.blockSignals(False)

    def select_law(self, index: int) -> None:
        """Choose law ``index`` (-1 = the paper example), as the user would (emits :attr:`law_selected`)."""
        self.law_choice.setCurrentIndex(max(self.law_choice.findData(index), 0))

    def selected_law(self) -> int:
        """-1 for the paper example, else the index of the job's law."""
        d = self.law_choice.currentData()
        return -1 if d is None else int(d)

    def show_iteration(self, r: int) -> None:
        """Mark the tube bounds and the W/O touches of iteration ``r`` (1-based, as in the iteration log)."""
        log = next((x for x in self.iterations if x.r == r), None)
        if log is None:
            return
        s = log.s + self.s_offset if self.s_offset else log.s
        self.set_curve("iterations", "tube lower", s, log.lower, "#888", 1.0, True,
                       legend=tr("tube bounds") if "tube lower" not in self.curves else None)
        self.set_curve("iterations", "tube upper", s, log.upper, "#888", 1.0, True)
        for key, mask, sym, col in (("W touches", log.w_mask, "t", "#d62728"),
                                    ("O touches", log.o_mask, "o", "#1f77b4")):
            old = self.curves.pop(key, None)
            if old is not None:
                self.plots["iterations"].removeItem(old)
            m = np.asarray(mask, dtype=bool)
            sc = pg.PlotDataItem(s[m], log.sdot[m], pen=None, symbol=sym, symbolSize=7,
                                 symbolBrush=col, symbolPen=None)
            self.plots["iterations"].addItem(sc)
            self.curves[key] = sc

    def set_laws(self, tube: Any, dp: Any, toppra: Any, source: str, main_name: str = "tube",
                 s_offset: float = 0.0) -> None:
        """Show the tube law's iterations and the three final laws (engine.timeparam.TimeLaw)."""
        for step in self.updates(tube, dp, toppra, source, main_name, s_offset):
            step()

    def updates(self, tube: Any, dp: Any, toppra: Any, source: str, main_name: str = "tube",
                s_offset: float = 0.0) -> list[Any]:
        """Steps of :meth:`set_laws` (a few curves each), to run one per event-loop turn.

        ``tube`` is the law whose iterations are shown (any method), named ``main_name`` in the final
        plot (curve ``"final <main_name>"``); ``s_offset`` (mm) places its iteration log on its s."""
        its = tube.iterations
        n = len(its)
        shown = its if n <= MAX_ITERATION_CURVES else its[:: math.ceil(n / MAX_ITERATION_CURVES)] + [its[-1]]

        def start() -> None:
            self.clear_data()
            self.s_offset = float(s_offset)
            self.plots["iterations"].setTitle(tr("{main_name} iterations ṡ(s)")
                                              .format(main_name=main_name) if main_name != "tube"
                                              else tr("tube iterations ṡ(s)"))

        def iteration(j: int, log: Any) -> None:
            col = pg.intColor(j, hues=max(len(shown), 2), values=1, maxValue=200)
            s = log.s + self.s_offset if self.s_offset else log.s
            item = self.set_curve("iterations", f"iteration {log.r}", s, log.sdot, "#000", 1.2,
                                  legend=f"r = {log.r}" if j in (0, len(shown) - 1) else None)
            item.setPen(pg.mkPen(col, width=1.2))

        def tube_bounds() -> None:
            self.iterations = list(its)
            if not its:
                self.bounds_of.setEnabled(False)
                return
            self.bounds_of.blockSignals(True)
            self.bounds_of.setRange(its[0].r, its[-1].r)
            self.bounds_of.setValue(its[-1].r)
            self.bounds_of.blockSignals(False)
            self.bounds_of.setEnabled(True)
            self.show_iteration(its[-1].r)

        def finals() -> None:
            for name, law, col, w in ((main_name, tube, "#d62728", 2.4), ("DP", dp, "#1f77b4", 1.6),
                                      ("TOPP-RA", toppra, "#2ca02c", 1.6)):
                self.set_curve("final", f"final {name}", law.t, law.sdot, col, w,
                               legend=f"{name}: {law.total_time_s:.3f} s")

        return [start, *[lambda j=j, log=log: iteration(j, log) for j, log in enumerate(shown)],
                tube_bounds, finals,
                lambda: self._done(
                                   tr("{source} · {n} iterations · T {main_name} {total_time_s:.3f} "
                                      "s, DP {v4:.3f} s, TOPP-RA {v5:.3f} s")
                                   .format(source=source, n=n, main_name=main_name, total_time_s=tube.total_time_s,
                                           v4=dp.total_time_s, v5=toppra.total_time_s))]
