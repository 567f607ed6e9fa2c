"""The laminate plot tab: cross-section r(z) of every layer boundary, winding angle β(z) and thickness t(z).

Fed by :class:`winder_gui.laminate_tasks.LaminateOutput` (the engine's arrays, thinned in the worker).
The cross-section shows the bare mandrel and the outer boundary of every wound layer, the band between
two boundaries filled in the layer's colour (the colours of the layer table); the angle and thickness
plots show each layer's β (deg) on its first pass and the thickness it adds (mm), with the total.  The
selected layer is drawn bold, the others thin.  ``Build-up`` plots the boundaries as height above the
bare mandrel (mm) instead of radius, where layers of a few tenths of a millimetre become visible.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QCheckBox, QSizePolicy, QWidget

from winder_gui.i18n import tr
from winder_gui.panels.layers_panel import layer_colour
from winder_gui.views.plots import PlotPage


class LaminatePlots(PlotPage):
    """Cross-section, angle and thickness of the laminate along z (see the module docstring).

    Curves (``curves``): ``bare``, ``boundary <n>``, ``angle <n>``, ``thickness <n>`` (n: job layer,
    1-based) and ``total thickness``.
    """

    title = "laminate"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.add_plot("section", 0, 0, tr("r [mm]"), tr("z [mm]"), title=tr("Cross-section: layer boundaries"),
                      colspan=2)
        self.add_plot("angle", 1, 0, tr("β [deg]"), tr("z [mm]"), title=tr("Winding angle (first pass)"))
        self.add_plot("thickness", 1, 1, tr("t [mm]"), tr("z [mm]"), title=tr("Thickness added by each layer"),
                      colspan=2)
        lay = self.glw.ci.layout
        lay.setRowStretchFactor(0, 3)
        lay.setRowStretchFactor(1, 2)
        # the cross-section's legend beside it, in its own cell: never over the boundaries or the fills
        # (the build-up view fills the whole plot); the thickness plot spans the cell below it
        self.legend = pg.LegendItem(brush=pg.mkBrush(255, 255, 255, 0), labelTextColor="#202020", colCount=1,
                                    verSpacing=-4)
        self.legend.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Maximum)   # its own height, top
        self.glw.addItem(self.legend, row=0, col=2)
        lay.setAlignment(self.legend, Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        lay.setColumnStretchFactor(0, 1)
        lay.setColumnStretchFactor(1, 1)
        lay.setColumnStretchFactor(2, 0)
        self.output: Any = None
        self.selected = -1
        self._inner: Any = None
        self._total_t = np.zeros(0)
        self.fills: dict[str, Any] = {}
        self.buildup = QCheckBox(tr("Build-up (height above the mandrel)"))
        self.buildup.setToolTip(tr("plot the boundaries as r − r_mandrel(z) (mm): thin layers become visible"))
        self.buildup.toggled.connect(lambda _on: self._draw())
        self.layout().itemAt(0).layout().insertWidget(1, self.buildup)
        self.set_message(tr("No laminate yet: run a layered job (F5)."))

    def set_output(self, out: Any, selected: int | None = None) -> None:
        """Show a :class:`~winder_gui.laminate_tasks.LaminateOutput` (``None``: clear) at once."""
        for step in self.updates(out, selected):
            step()

    def updates(self, out: Any, selected: int | None = None) -> list[Callable[[], Any]]:
        """:meth:`set_output` as short GUI-thread steps (one per layer) for a presenter's update queue:
        each stays far below the 100 ms an event-loop turn may take."""
        def begin() -> None:
            self.output = out
            if selected is not None:
                self.selected = selected
            self._begin()

        views = list(out.views) if out is not None else []
        return [begin, *[lambda v=v: self._draw_layer(v) for v in views], self._finish]

    def select_layer(self, index: int) -> None:
        """Draw job layer ``index`` (0-based) bold (pens and fills restyled, nothing recomputed)."""
        if index == self.selected:
            return
        self.selected = index
        out = self.output
        if out is None or not out.views:
            return
        for v in out.views:
            sel = v.index == index
            n = v.index + 1
            col = layer_colour(v.index)
            for name in (f"boundary {n}", f"angle {n}", f"thickness {n}"):
                item = self.curves.get(name)
                if item is not None:
                    pen = pg.mkPen(item.opts["pen"])
                    pen.setWidthF(3.0 if sel else 1.2)
                    item.setPen(pen)
            fill = self.fills.get(f"fill {n}")
            if fill is not None:
                c = QColor(col)
                c.setAlpha(150 if sel else 70)
                fill.setBrush(pg.mkBrush(c))
        self._set_summary()

    def _draw(self) -> None:
        for step in self.updates(self.output):
            step()

    def _y_of(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        out = self.output
        return r - np.interp(z, np.asarray(out.bare_z), np.asarray(out.bare_r)) if self.buildup.isChecked() else r

    def clear_data(self, message: str = "") -> None:
        """Remove every curve and the legend's entries; show ``message``."""
        super().clear_data(message)
        if hasattr(self, "legend"):
            self.legend.clear()

    def _begin(self) -> None:
        out = self.output
        for item in self.fills.values():
            self.plots["section"].removeItem(item)
        self.fills.clear()
        self._inner: Any = None
        if out is None or not out.views:
            self.clear_data(tr("No laminate yet: run a layered job (F5)."))
            return
        self.clear_data("")
        bz, br = np.asarray(out.bare_z), np.asarray(out.bare_r)
        self._inner = self.set_curve("section", "bare", bz, self._y_of(bz, br), colour="#000000", width=1.5)
        self.legend.addItem(self._inner, tr("mandrel"))
        self.legend.setColumnCount(1 if len(out.views) < 9 else 2)
        self._total_t = np.zeros_like(bz)

    def _draw_layer(self, v: Any) -> None:
        if self._inner is None or v.outer_z.size == 0:
            return
        n = v.index + 1
        col = layer_colour(v.index)
        sel = v.index == self.selected
        w = 3.0 if sel else 1.2
        outer = self.set_curve("section", f"boundary {n}", v.outer_z, self._y_of(v.outer_z, v.outer_r), colour=col,
                               width=w)
        self.legend.addItem(outer, f"{n} {v.name}" if v.name != f"{n} {v.kind}" else f"{n} {v.kind}")
        c = QColor(col)
        c.setAlpha(150 if sel else 70)
        fill = pg.FillBetweenItem(self._inner, outer, brush=pg.mkBrush(c))
        self.plots["section"].addItem(fill)
        self.fills[f"fill {n}"] = fill
        self._inner = outer
        if v.angle_z.size:
            self.set_curve("angle", f"angle {n}", v.angle_z, v.angle_deg, colour=col, width=w)
        self.set_curve("thickness", f"thickness {n}", v.thick_z, v.thick_t, colour=col, width=w)
        bz = np.asarray(self.output.bare_z)
        self._total_t = self._total_t + np.interp(bz, v.thick_z, v.thick_t, left=0.0, right=0.0)

    def _finish(self) -> None:
        out = self.output
        if self._inner is None or out is None:
            return
        self.set_curve("thickness", "total thickness", np.asarray(out.bare_z), self._total_t, colour="#000000",
                       width=1.0, dash=True)
        self._set_summary()
        self.export_button.setEnabled(True)
        for p in self.plots.values():
            p.enableAutoRange()

    def _set_summary(self) -> None:
        out = self.output
        names = [v.name for v in out.views if v.index == self.selected]
        self.set_message(tr("{v0} layers wound").format(v0=len(out.views)) + (tr("; selected: {v0}")
                                                                              .format(v0=names[0]) if names else ""))

    def selected_pen_width(self, name: str) -> float:
        """The pen width of curve ``name`` (the selected layer's are bold)."""
        return float(self.curves[name].opts["pen"].widthF())
