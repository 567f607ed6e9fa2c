"""The plot tabs of the workflow (pyqtgraph): winding line, eye path, pull speed here; axes, time law and
coverage in :mod:`~winder_gui.views.axes_plot`, :mod:`~winder_gui.views.timelaw_plot`,
:mod:`~winder_gui.views.coverage_plot` (the same :class:`PlotPage`).

Every page shows engine arrays as they are (no mathematics here): the curves keep the engine's
arrays in ``xData``/``yData`` and pyqtgraph thins them for display (``autoDownsample`` +
``clipToView``), so a million points stay interactive.  Each page can be exported as PNG, SVG or
CSV (:meth:`PlotPage.export`); the CSV holds every curve of the page, one pair of columns each.
Units are in the axis labels (mm, deg, s).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, Qt
from PySide6.QtWidgets import (
    QFileDialog,
    QFrame,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QVBoxLayout,
    QWidget,
)

from engine.fileio import atomic_write_text
from winder_gui.i18n import QT_TR_NOOP, tr

EXPORT_FILTER = QT_TR_NOOP("PNG image (*.png);;SVG drawing (*.svg);;CSV table (*.csv)")
LAW_COLOURS = {"parallel": "#1f77b4", "equidistant": "#2ca02c", "equal-tangent": "#9467bd", "curve": "#8c564b",
               "min-range": "#d62728"}
AXIS_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
MAX_ITERATION_CURVES = 40
MIN_PLOT_PX = 120
"""Least height of a plot's data area (px); a page with more rows than fit scrolls."""
LEFT_AXIS_PX = 64
"""Width of every left axis, so that stacked plots with one x axis line up."""
FLAT_REL = 1e-9
"""A curve whose values span less than this (relative) is drawn in a fixed band around its value."""
_LABEL = re.compile(r"^\s*(?P<name>.*?)\s*\[(?P<unit>[^\]]*)\]\s*$")


class TickAxis(pg.AxisItem):
    """An axis whose tick labels carry no more decimals than the tick spacing needs (no
    ``18.000000000000005``) and never an SI prefix (the unit is in the label)."""

    def tickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:  # noqa: N802 - Qt API
        if not values:
            return []
        step = abs(spacing * scale) or 1.0
        # the fewest decimals that write the tick spacing exactly (0.25 -> 2, 0.1 -> 1, 500 -> 0)
        places = next((p for p in range(10) if abs(step * 10**p - round(step * 10**p)) <= 1e-6 * step * 10**p), 9)
        big = max(abs(v * scale) for v in values)
        if big >= 1e7 or (big < 1e-4 and big > 0):
            return [f"{v * scale:.3g}" for v in values]
        out = []
        for v in values:
            t = f"{v * scale:.{places}f}"
            out.append("0" if t.strip("-0.") == "" else t)
        return out


class LogTickAxis(TickAxis):
    """A log-scale axis that labels only the 1, 2 and 5 of each decade (the minor ticks 3, 4, 6…9 keep
    their grid lines but no text, so labels never run into each other)."""

    def tickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:  # noqa: N802 - Qt API
        if not self.logMode:
            return super().tickStrings(values, scale, spacing)
        out = []
        for v in values:
            x = 10.0 ** float(v)
            mant = x / 10.0 ** math.floor(math.log10(x)) if x > 0 else 0.0
            keep = any(abs(mant - k) < 1e-6 * k for k in (1.0, 2.0, 5.0))
            out.append(f"{x:.6g}" if keep else "")
        return out


def split_label(text: str) -> tuple[str, str]:
    """``"z [mm]"`` -> ``("z", "mm")``; a label without a unit -> ``(text, "")``."""
    m = _LABEL.match(text or "")
    return (m.group("name"), m.group("unit")) if m else ((text or "").strip(), "")


def readout_text(x_label: str, y_label: str, x: float, y: float) -> str:
    """The crosshair read-out: ``"z = 12.5 mm · β = 55.01 deg"`` (units from the axis labels)."""
    parts = []
    for label, v in ((x_label, x), (y_label, y)):
        name, unit = split_label(label)
        unit = "" if unit in ("", "–", "-") else f" {unit}"
        parts.append(f"{name or '?'} = {v:.6g}{unit}")
    return " · ".join(parts)


def _pen(colour: str, width: float = 1.5, dash: bool = False) -> Any:
    return pg.mkPen(colour, width=width, style=Qt.PenStyle.DashLine if dash else Qt.PenStyle.SolidLine)


class PlotPage(QWidget):
    """A tab with one or more plots, a message line and an Export button.

    ``curves`` maps a name to each data item shown (for export and tests); ``plots`` maps a name to
    each :class:`pyqtgraph.PlotItem`.
    """

    title = "plot"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.glw = pg.GraphicsLayoutWidget()
        self.glw.setBackground("w")
        self.plots: dict[str, pg.PlotItem] = {}
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #555; padding: 2px 6px;")
        self.readout = QLabel("")
        self.readout.setObjectName("plotReadout")
        self.readout.setStyleSheet("color: #204080; padding: 2px 6px;")
        self.readout.setToolTip(tr("The values under the mouse pointer"))
        self._cross: dict[str, tuple[Any, Any]] = {}
        self.glw.scene().sigMouseMoved.connect(self._on_mouse)
        self.scroll = QScrollArea()
        self.scroll.setFrameShape(QFrame.Shape.NoFrame)
        self.scroll.setWidgetResizable(True)
        self.scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.scroll.setWidget(self.glw)
        self.export_button = QPushButton(tr("Export…"))
        self.export_button.setToolTip(tr("Save this plot as PNG, SVG or CSV"))
        self.export_button.clicked.connect(self._ask_export)
        self.export_button.setEnabled(False)
        top = QHBoxLayout()
        top.setContentsMargins(0, 0, 4, 0)
        top.addWidget(self.message, 1)
        top.addWidget(self.readout)
        top.addWidget(self.export_button)
        self.top = top
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(0)
        lay.addLayout(top)
        lay.addWidget(self.scroll, 1)
        self.set_message(tr("No data yet: run the pipeline (F5)."))

    # -- building blocks -------------------------------------------------------------------------
    @staticmethod
    def plot_min_height(p: pg.PlotItem) -> float:
        """The height plot ``p`` needs for a data area of :data:`MIN_PLOT_PX` (its title and x axis)."""
        ax = p.getAxis("bottom")
        h = MIN_PLOT_PX + 12.0
        if p.titleLabel.isVisible() and p.titleLabel.text:
            h += 24.0
        if ax.isVisible():
            h += (30.0 if ax.style.get("showValues", True) else 10.0) + (22.0 if ax.labelText else 0.0)
        return h

    def size_plot(self, p: pg.PlotItem) -> None:
        """Give ``p`` its minimum height (:meth:`plot_min_height`) and re-fit the page."""
        p.setMinimumHeight(self.plot_min_height(p))
        self.fit_rows()

    def fit_rows(self) -> None:
        """Let the page scroll rather than squeeze its rows of plots below :data:`MIN_PLOT_PX`."""
        heights: dict[int, float] = {}
        for item, cells in self.glw.ci.items.items():
            if isinstance(item, pg.PlotItem) and cells:
                r = cells[0][0]
                heights[r] = max(heights.get(r, 0.0), item.minimumHeight())
        self.glw.setMinimumHeight(int(sum(heights.values()) + 16 + 6 * max(len(heights), 1)))

    def _on_mouse(self, pos: QPointF) -> None:
        for name, p in self.plots.items():
            vb = p.getViewBox()
            if p.isVisible() and vb.sceneBoundingRect().contains(pos):
                pt = vb.mapSceneToView(pos)
                x_label = p.getAxis("bottom").labelText or self._x_label(name)
                self.readout.setText(readout_text(x_label, p.getAxis("left").labelText, pt.x(), pt.y()))
                lines = self._cross.get(name)
                if lines is None:
                    pen = pg.mkPen("#7090c0", width=1, style=Qt.PenStyle.DotLine)
                    lines = (pg.InfiniteLine(angle=90, pen=pen, movable=False),
                             pg.InfiniteLine(angle=0, pen=pen, movable=False))
                    for ln in lines:
                        p.addItem(ln, ignoreBounds=True)
                    self._cross[name] = lines
                lines[0].setPos(pt.x())
                lines[1].setPos(pt.y())
                for other, ls in self._cross.items():
                    for ln in ls:
                        ln.setVisible(other == name)
                return

    def _x_label(self, name: str) -> str:
        """The x label of plot ``name`` when its own axis shows none (stacked plots share the last one's)."""
        for p in reversed(list(self.plots.values())):
            if p.getAxis("bottom").labelText:
                return p.getAxis("bottom").labelText
        return "x"

    def guard_flat(self) -> None:
        """Give a plot whose curves are (nearly) constant a readable band around the value instead of
        a range of 1e-15 (ticks such as ``18.000000000000005``)."""
        for p in self.plots.values():
            ys = [np.asarray(c.yData, dtype=float) for c in self.curves.values()
                  if c in p.items and c.yData is not None]
            ys = [y[np.isfinite(y)] for y in ys if y.size]
            ys = [y for y in ys if y.size]
            if not ys:
                continue
            lo, hi = min(float(y.min()) for y in ys), max(float(y.max()) for y in ys)
            mid = 0.5 * (lo + hi)
            if hi - lo <= FLAT_REL * max(1.0, abs(mid)):
                half = max(0.05 * abs(mid), 1.0) if mid else 1.0
                p.setYRange(mid - half, mid + half, padding=0)
            else:
                p.enableAutoRange(axis="y")

    def add_plot(self, name: str, row: int, col: int, left: str, bottom: str, **kw: Any) -> pg.PlotItem:
        """A plot with axis labels (units in the labels) at ``row``, ``col`` of the layout."""
        axes = {side: TickAxis(side) for side in ("left", "bottom")}
        p = self.glw.addPlot(row=row, col=col, axisItems=axes, **kw)
        p.getAxis("left").setWidth(LEFT_AXIS_PX)
        p.showGrid(x=True, y=True, alpha=0.25)
        p.setLabel("left", left)
        p.setLabel("bottom", bottom)
        self.plots[name] = p
        self.size_plot(p)
        p.setClipToView(True)
        p.setDownsampling(auto=True, mode="peak")
        for side in ("left", "bottom"):
            p.getAxis(side).enableAutoSIPrefix(False)  # the unit is in the label; no hidden ×1000
        return p

    def set_curve(self, plot: str, name: str, x: Any, y: Any, colour: str = "#1f77b4", width: float = 1.5,
                  dash: bool = False, **kw: Any) -> pg.PlotDataItem:
        """Show ``(x, y)`` as curve ``name`` on ``plot`` (replacing a curve of that name)."""
        old = self.curves.pop(name, None)
        if old is not None:
            for p in self.plots.values():
                if old in p.items:
                    p.removeItem(old)
        item = pg.PlotDataItem(np.asarray(x, dtype=float), np.asarray(y, dtype=float), pen=_pen(colour, width, dash),
                               name=kw.pop("legend", None), **kw)
        self.plots[plot].addItem(item)
        self.curves[name] = item
        return item

    def clear_data(self, message: str = "") -> None:
        """Remove every curve; show ``message``."""
        for p in self.plots.values():
            p.clear()
            if p.legend is not None:
                p.legend.clear()
        self.curves.clear()
        self._cross.clear()
        self.readout.setText("")
        self.set_message(message)
        self.export_button.setEnabled(False)

    def set_message(self, text: str) -> None:
        self.message.setText(text)

    def has_data(self) -> bool:
        return bool(self.curves)

    def curve_data(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """The full arrays of curve ``name`` (as given; not the thinned display copy)."""
        c = self.curves[name]
        return np.asarray(c.xData), np.asarray(c.yData)

    # -- export ----------------------------------------------------------------------------------
    def export(self, path: str | Path) -> Path:
        """Write the page as PNG/SVG (the drawing) or CSV (every curve's data), by suffix."""
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".csv":
            atomic_write_text(p, self.csv_text())
            return p
        import pyqtgraph.exporters as ex

        scene = self.glw.scene()
        if suffix == ".svg":
            try:
                ex.SVGExporter(scene).export(str(p))
            except ValueError:  # pyqtgraph's SVG path rewriting fails on some curves: draw the scene as SVG
                self._svg_by_qt(p)
        else:
            if suffix != ".png":
                p = p.with_suffix(".png")
            exp = ex.ImageExporter(scene)
            exp.export(str(p))
        return p

    def _svg_by_qt(self, p: Path) -> None:
        from PySide6.QtCore import QRectF, QSize
        from PySide6.QtGui import QPainter
        from PySide6.QtSvg import QSvgGenerator

        scene = self.glw.scene()
        rect = scene.sceneRect()
        gen = QSvgGenerator()
        gen.setFileName(str(p))
        gen.setSize(QSize(int(rect.width()), int(rect.height())))
        gen.setViewBox(QRectF(0, 0, rect.width(), rect.height()))
        gen.setTitle(self.title)
        painter = QPainter(gen)
        scene.render(painter, QRectF(0, 0, rect.width(), rect.height()), rect)
        painter.end()

    def csv_text(self) -> str:
        """Every curve as two columns ``<name> x``, ``<name> y``; shorter columns padded with blanks."""
        cols: list[tuple[str, np.ndarray]] = []
        for name, item in self.curves.items():
            x, y = np.asarray(item.xData, dtype=float), np.asarray(item.yData, dtype=float)
            cols.append((f"{name} x", x))
            cols.append((f"{name} y", y))
        n = max((len(c) for _, c in cols), default=0)
        lines = [",".join(f'"{h}"' for h, _ in cols)]
        for i in range(n):
            lines.append(",".join(repr(float(c[i])) if i < len(c) else "" for _, c in cols))
        return "\n".join(lines) + "\n"

    def _ask_export(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, tr("Export {title}")
                                                    .format(title=self.title), f"{self.title}.png", tr(EXPORT_FILTER))
        if path:
            self.export(path)

    def _done(self, message: str = "") -> None:
        self.guard_flat()
        self.set_message(message)
        self.export_button.setEnabled(bool(self.curves))


# ------------------------------------------------------------------------------------------------
class WindingPlots(PlotPage):
    """β(z) [deg], C(z) [mm] and λ(z) [–] of the first circuit of the winding line."""

    title = "winding"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        # no titles (the left labels say what each plot is); one x axis, shown under the last plot
        self.add_plot("beta", 0, 0, tr("β [deg]"), "")
        self.add_plot("C", 1, 0, tr("C [mm]"), "")
        self.plots["C"].setToolTip(tr("Clairaut function C(z) = r·sin β"))
        self.add_plot("lam", 2, 0, "λ [–]", tr("z [mm]"))
        self.plots["lam"].setToolTip(tr("slip tendency λ(z); dashed: the friction limit ±μ"))
        for key in ("beta", "C"):
            self.plots[key].setXLink(self.plots["lam"])
            self.plots[key].getAxis("bottom").setStyle(showValues=False)
            self.plots[key].getAxis("bottom").setHeight(8)
            self.size_plot(self.plots[key])

    def set_line(self, line: Any) -> None:
        """Show ``line`` (engine.winding.WindingLine): its first circuit, and the friction limit ±μ."""
        self.clear_data()
        sl = line.circuit_slice(0)
        z = line.z[sl]
        self.set_curve("beta", "beta", z, np.degrees(line.beta[sl]), "#1f77b4")
        self.set_curve("C", "C", z, line.C[sl], "#2ca02c")
        self.set_curve("lam", "lam", z, line.lam[sl], "#d62728")
        for sign in (1.0, -1.0):
            self.plots["lam"].addItem(pg.InfiniteLine(sign * line.mu, angle=0, pen=_pen("#888", 1, True)))
        self._done(
                   tr("{mode} line · {circuits} circuits · pattern {pattern_p}/{pattern_q} · max |λ| "
                      "{max_abs_lambda:.3g} (μ = {mu:g})")
                   .format(mode=line.mode, circuits=line.circuits, pattern_p=line.pattern_p, pattern_q=line.pattern_q,
                           max_abs_lambda=line.max_abs_lambda, mu=line.mu))


class EyePlot(PlotPage):
    """The payout-eye path Z–R of one circuit over the mandrel generatrix (mm)."""

    title = "eye_path"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        p = self.add_plot("zr", 0, 0, tr("R, r [mm]"), tr("Z, z [mm]"))
        p.setAspectLocked(True)
        p.addLegend(offset=(10, 10))

    def set_eye(self, eye: Any, mandrel: Any) -> None:
        """Show ``eye`` (engine.payout.EyePath of one circuit) and the generatrix of ``mandrel``."""
        self.clear_data()
        z = np.linspace(mandrel.z_min, mandrel.z_max, 400)
        self.set_curve("zr", "mandrel", z, mandrel.r(z), "#555555", 2.0, legend=tr("mandrel r(z)"))
        self.set_curve("zr", "eye", eye.Z, eye.R, LAW_COLOURS.get(eye.law, "#d62728"), 2.0,
                       legend=tr("eye ({law})").format(law=eye.law))
        rep = eye.report
        self._done(tr("law {law} · free length {v1:.1f}…{v2:.1f} mm")
                   .format(law=eye.law, v1=float(np.min(eye.l)), v2=float(np.max(eye.l)))
                   + ("" if rep.get("feasible", True) else tr(" · violates a constraint (see NC warnings)")))


class PullSpeedPlot(PlotPage):
    """Relative pull speed u(x) of each payout law side by side (one plot per law, same scales)."""

    title = "pull_speed"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.laws: dict[str, Any] = {}

    def plan(self, laws: list[str]) -> list[Any]:
        """Steps that lay out one plot per law (none when laid out already); see :meth:`AxesPlot.plan`."""
        if laws == list(self.plots):
            return []

        def start() -> None:
            self.glw.clear()
            self.plots.clear()
            self.curves.clear()

        def col(c: int, law: str) -> None:
            p = self.add_plot(law, 0, c, "", "")
            if c:
                p.setYLink(next(iter(self.plots.values())))

        return [start, *[lambda c=c, law=law: col(c, law) for c, law in enumerate(laws)]]

    def set_laws(self, laws: dict[str, Any], job_law: str, parameter: str) -> None:
        """Show ``laws`` (law name -> EyePath or an error message)."""
        for step in (*self.plan(list(laws)), *self.updates(laws, job_law, parameter)):
            step()

    def updates(self, laws: dict[str, Any], job_law: str, parameter: str) -> list[Any]:
        """Steps of :meth:`set_laws` after :meth:`plan` (one plot each), to run one per event-loop turn."""
        unit_x = "s [mm]" if parameter == "s" else "v [rad]"
        unit_u = "u = dλ/ds [–]" if parameter == "s" else "u = dλ/dv [mm/rad]"
        notes: list[str] = []

        def start() -> None:
            for p in self.plots.values():
                p.clear()
            self.curves.clear()
            self.laws = dict(laws)

        def one(col: int, law: str, eye: Any) -> None:
            p = self.plots[law]
            p.setTitle(f"{law}{' (job)' if law == job_law else ''}")
            p.setLabel("left", unit_u if col == 0 else "")
            p.setLabel("bottom", unit_x)
            if isinstance(eye, str):
                p.addItem(pg.TextItem(eye[:160], color="#c01010"))
                notes.append(f"{law}: not available")
                return
            self.set_curve(law, law, eye.x_mid, eye.u, LAW_COLOURS.get(law, "#333"), 2.0 if law == job_law else 1.5)
            notes.append(f"{law}: u {eye.u_min:.3g}…{eye.u_max:.3g}")

        return [start, *[lambda c=c, law=law, e=e: one(c, law, e) for c, (law, e) in enumerate(laws.items())],
                lambda: self._done(" · ".join(notes))]
