"""The turning dialog's constraint table and its drawing of the feasible region (a mixin of
:class:`winder_gui.dialogs.turning.TurningDialog`, which has the inputs and runs the optimiser)."""

from __future__ import annotations

import html
import math
from typing import Any

import pyqtgraph as pg
from PySide6.QtCore import QPointF, Qt
from PySide6.QtGui import QBrush, QColor, QPen, QPolygonF
from PySide6.QtWidgets import (
    QGraphicsPolygonItem,
    QTableWidgetItem,
)

from engine.errors import InputError
from engine.turning import (
    CONSTRAINT_NAMES,
    LABELS,
)
from winder_gui.i18n import tr

#: colour per constraint (the paper's Fig. 2 colours where it has them)
COLOURS: dict[str, str] = {
    "tool_life": "#8b4513",  # brown, as the paper's 3
    "power": "#c08040",  # light brown
    "feed_mechanism": "#7f7f7f",
    "holder": "#9467bd",
    "insert": "#e377c2",
    "roughness": "#7ccd7c",  # light green, as the paper's 4
    "accuracy": "#17becf",
    "s_min": "#1f4fff",  # blue, as the paper's 1
    "s_max": "#1f4fff",
    "n_min": "#2ca02c",  # green, as the paper's 2
    "n_max": "#2ca02c",
}
_USER_COLOURS = ("#ff7f0e", "#bcbd22", "#8c564b", "#d62728")

def _fmt(v: Any, spec: str = ".4g") -> str:
    return "—" if v is None else format(v, spec)


class TurningViewsMixin:
    """The constraint table (``table``, ``_rows``) and the (n, S) plot (``plot_widget``, ``_pools``) of the
    turning dialog; needs the dialog's ``result``, ``summary``, ``snap``, ``current_mode``, ``_changed`` and
    ``_show_input_error``."""

    # ------------------------------------------------------------------------------ the table
    def _refill_table(self) -> None:
        self.table.blockSignals(True)
        try:
            self.table.setRowCount(len(self._rows))
            expert = self.current_mode() == "expert"
            for i, r in enumerate(self._rows):
                on = QTableWidgetItem()
                on.setFlags(Qt.ItemFlag.ItemIsUserCheckable | Qt.ItemFlag.ItemIsEnabled)
                on.setCheckState(Qt.CheckState.Checked if r["on"] else Qt.CheckState.Unchecked)
                self.table.setItem(i, 0, on)
                paper = f"b{CONSTRAINT_NAMES.index(r['name']) + 1}" if r["name"] in CONSTRAINT_NAMES else "user"
                cells = [paper, LABELS.get(r["name"], r["name"]), _fmt(r["a"]), _fmt(r["b"]),
                         _fmt(r["rhs"], ".5g"), _fmt(r["factor"]), "", "", ""]
                for j, text in enumerate(cells, start=1):
                    it = QTableWidgetItem(text)
                    editable = (j in (3, 4, 5) and (expert or r["user"])) or (j == 6 and not expert and not r["user"])
                    flags = Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsSelectable
                    if editable:
                        flags |= Qt.ItemFlag.ItemIsEditable
                    it.setFlags(flags)
                    if j == 2:
                        it.setForeground(QBrush(QColor(self._colour(r["name"]))))
                    self.table.setItem(i, j, it)
        finally:
            self.table.blockSignals(False)

    def _table_changed(self, item: QTableWidgetItem) -> None:
        i, j = item.row(), item.column()
        if i >= len(self._rows):
            return
        r = self._rows[i]
        if j == 0:
            r["on"] = item.checkState() == Qt.CheckState.Checked
        elif j in (3, 4, 5, 6):
            key = {3: "a", 4: "b", 5: "rhs", 6: "factor"}[j]
            try:
                v = float(item.text().replace(",", "."))
                if not math.isfinite(v) or (key == "factor" and v <= 0):
                    raise ValueError
            except ValueError:
                self._show_input_error(InputError(
                    f"row {r['name']!r}: {key} must be a {'positive ' if key == 'factor' else ''}number, "
                    f"got {item.text()!r}", field=f"constraints.{r['name']}.{key}"))
                return
            r[key] = v
        else:
            return  # read-only columns
        self._changed()

    def add_user_row(self) -> None:
        """Append a user constraint ``n^a S^b <= c`` (default ``n S <= 2000``, i.e. 2 m/min feed rate)."""
        k = 1 + sum(r["user"] for r in self._rows)
        names = {r["name"] for r in self._rows}
        while f"user{k}" in names:
            k += 1
        self._rows.append({"name": f"user{k}", "a": 1.0, "b": 1.0, "rhs": math.log(2000.0), "on": True,
                           "factor": 1.0, "user": True})
        self._refill_table()
        self._changed()

    def remove_user_row(self) -> None:
        """Remove the selected user row (or the last one)."""
        sel = [i.row() for i in self.table.selectedIndexes() if self._rows[i.row()]["user"]]
        idx = sel[0] if sel else max((i for i, r in enumerate(self._rows) if r["user"]), default=None)
        if idx is not None:
            del self._rows[idx]
            self._refill_table()
            self._changed()

    def rows_to_expert(self) -> None:
        """Switch to expert mode with the rows of the current result (the feed band in use)."""
        if self.result is None:
            self.message.setText(tr("No result to copy the rows from; fix the set-up first."))
            return
        users = [r for r in self._rows if r["user"]]
        rows = [{"name": r.name, "a": r.a, "b": r.b, "rhs": r.rhs, "on": r.enabled, "factor": 1.0, "user": False}
                for r in self.result.rows if r.kind != "user"]
        self._loading = True
        try:
            self._set_combo(self.mode, "expert")
        finally:
            self._loading = False
        self._rows = rows + users
        self._refill_table()
        self._apply_mode_enabling()
        self._changed()

    # ------------------------------------------------------------------------------ the result
    def _show_result(self) -> None:
        res = self.result
        self.table.blockSignals(True)
        try:
            for i in range(len(self._rows)):
                for j in (7, 8, 9):
                    it = self.table.item(i, j)
                    if it is not None:
                        it.setText("")
        finally:
            self.table.blockSignals(False)
        if res is None:
            self.summary.setText(tr("<b>No feasible cutting mode.</b>"))
            return
        q = res.quantities
        lines = [f"<b>n = {res.n_rpm:.2f} rpm, S = {res.feed_mm_rev:.4g} mm/rev</b> "
                 f"(x1 = ln n = {res.x1:.4f}, x2 = ln S = {res.x2:.4f})",
                 f"V = {_fmt(q['speed_m_min'])} m/min, feed {_fmt(q['feed_mm_min'])} mm/min, "
                 f"machine time {_fmt(q['machine_time_min'])} min"]
        if q.get("force_pz_n") is not None:
            lines.append(f"P_z = {_fmt(q['force_pz_n'], '.5g')} N, P_y = {_fmt(q['force_py_n'], '.5g')} N, "
                         f"P_x = {_fmt(q['force_px_n'], '.5g')} N, cutting power {_fmt(q['power_kw'], '.3g')} kW")
            lines.append(f"tool life T = {_fmt(q['tool_life_min'])} min, Rz = {_fmt(q['rz_um'], '.3g')} µm, "
                         f"part deflection {_fmt(q['deflection_mm'], '.3g')} mm")
        lines.append("active: " + ", ".join(res.active))
        if res.snapped is not None:
            sn = res.snapped
            if sn.get("feasible"):
                lines.append(f"on the machine's series: n = {sn['n_rpm']:g} rpm, S = {sn['feed_mm_rev']:g} mm/rev, "
                             f"t_m = {_fmt(sn['machine_time_min'])} min")
            else:
                lines.append(sn["message"])
        elif self.snap.isChecked():
            lines.append("the machine has no discrete speed/feed series (continuous)")
        self.summary.setText("<br>".join(lines))
        by_name = {r.name: r for r in res.rows}
        self.table.blockSignals(True)
        try:
            for i, r in enumerate(self._rows):
                row = by_name.get(r["name"])
                if row is not None and self.current_mode() == "physical" and not r["user"]:
                    self.table.item(i, 3).setText(_fmt(row.a))
                    self.table.item(i, 4).setText(_fmt(row.b))
                    self.table.item(i, 5).setText(_fmt(row.rhs, ".5g"))
                if r["name"] in res.slack:
                    self.table.item(i, 7).setText(f"{res.slack[r['name']]:.4f}")
                    self.table.item(i, 8).setText(f"{100 * res.utilisation[r['name']]:.1f} %")
                    self.table.item(i, 9).setText(tr("ACTIVE") if r["name"] in res.active else "")
                elif not r["on"]:
                    self.table.item(i, 9).setText(tr("off"))
        finally:
            self.table.blockSignals(False)

    # ------------------------------------------------------------------------------ drawing
    def _colour(self, name: str) -> str:
        if name in COLOURS:
            return COLOURS[name]
        users = [r["name"] for r in self._rows if r["user"]]
        return _USER_COLOURS[users.index(name) % len(_USER_COLOURS)] if name in users else "#000000"

    def _item(self, pool: str, i: int, make: Any) -> Any:
        """The ``i``-th reusable plot item of ``pool`` (created on first use; items are never re-created)."""
        items = self._pools.setdefault(pool, [])
        while len(items) <= i:
            it = make()
            self.plot_widget.addItem(it)
            items.append(it)
        items[i].setVisible(True)
        return items[i]

    def _draw(self, pd: dict[str, Any] | None) -> None:
        """Show ``plot_data`` output.  Plot items are pooled and updated in place."""
        used: dict[str, int] = {}
        self.curves, self.region_items, self.label_items = {}, [], []
        legend: list[tuple[Any, str]] = []
        if pd is not None:
            for reg in pd["regions"]:
                poly = QPolygonF([QPointF(math.log10(n), math.log10(s)) for n, s in zip(reg["n"], reg["S"])])
                item = self._item("region", used.setdefault("region", 0), self._make_region)
                used["region"] += 1
                item.setPolygon(poly)
                self.region_items.append(item)
            for ln in pd["lines"] + [dict(o, n=None, S=None, active=False) for o in pd.get("offscreen", [])]:
                colour = self._colour(ln["name"])
                if ln["n"] is None:
                    style = Qt.PenStyle.DashDotLine
                else:
                    style = Qt.PenStyle.SolidLine if ln["enabled"] else Qt.PenStyle.DotLine
                width = 3 if ln["active"] else 1.5
                item = self._item("line", used.setdefault("line", 0), pg.PlotDataItem)
                used["line"] += 1
                item.setData(ln["n"] or [], ln["S"] or [])
                item.setPen(pg.mkPen(colour, width=width, style=style))
                self.curves.setdefault(ln["name"], []).append(item)
                label = ln["label"] if ln["enabled"] else f"{ln['label']} (off)"
                if ln["band"] is not None:
                    label += f", band {ln['band'] + 1}"
                if ln["n"] is None:
                    label += " — outside the view"
                if len(self.curves[ln["name"]]) == 1 or ln["band"] is not None:
                    legend.append((item, html.escape(label)))
                if ln["n"] is None:
                    continue
                tag = ln["name"] if ln["band"] is None else f"{ln['name']}[{ln['band'] + 1}]"
                text = self._item("text", used.setdefault("text", 0), lambda: pg.TextItem(anchor=(0.5, 1.0)))
                used["text"] += 1
                text.setText(tag, color=colour)
                text.setPos(0.5 * (math.log10(ln["n"][0]) + math.log10(ln["n"][1])),
                            0.5 * (math.log10(ln["S"][0]) + math.log10(ln["S"][1])))
                self.label_items.append(text)
        for pool, items in self._pools.items():
            for it in items[used.get(pool, 0):]:
                it.setVisible(False)
        if pd is not None and pd["objective"] is not None:
            self.objective_item.setData(pd["objective"]["n"], pd["objective"]["S"])
            legend.append((self.objective_item, "objective n·S = max"))
        else:
            self.objective_item.setData([], [])
        if pd is not None and pd["optimum"] is not None:
            self.optimum_item.setData([pd["optimum"][0]], [pd["optimum"][1]])
            legend.append((self.optimum_item, "optimum"))
        else:
            self.optimum_item.setData([], [])
        if pd is not None and pd.get("snapped") is not None:
            self.snapped_item.setData([pd["snapped"][0]], [pd["snapped"][1]])
            legend.append((self.snapped_item, "best discrete pair"))
        else:
            self.snapped_item.setData([], [])
        key = [(id(it), name) for it, name in legend]
        if key != self._legend_key:  # rebuild the legend only when its entries change
            self.legend.clear()
            for it, name in legend:
                self.legend.addItem(it, name)
            self._legend_key = key
        if pd is not None:
            n0, n1, s0, s1 = pd["box"]
            self.plot_widget.setRange(xRange=(math.log10(n0), math.log10(n1)),
                                      yRange=(math.log10(s0), math.log10(s1)), padding=0)

    @staticmethod
    def _make_region() -> QGraphicsPolygonItem:
        item = QGraphicsPolygonItem()
        item.setBrush(QBrush(QColor(120, 170, 255, 70)))
        item.setPen(QPen(Qt.PenStyle.NoPen))
        item.setZValue(-10)
        return item
