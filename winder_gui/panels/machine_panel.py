"""Properties page of the Machine step: kinematic template, its axes and limits, post-processor, controller.

The template list is ``resources/machines/*.toml`` (:func:`engine.kinematics.list_machines`).  Under
it, a schematic of the template's kinematic chain (:class:`winder_gui.views.machine_schematic.MachineSchematic`,
drawn from the engine's forward kinematics; each axis in the colour of its table row, the selected
row's axis drawn bold; clicking an axis in the drawing selects its row).  The axes table shows each
axis's name, type, units, travel limits and speed/acceleration/jump limits (controller units: mm or
deg, per s).  The limit cells are editable: a value different from the template's becomes an override
in the job (``[machine.axes.<name>]``); a blank cell restores the template's value.  Post-processor
(:func:`engine.post.list_posts`) and controller profile
(:func:`engine.post.list_controllers`) are chosen below.
"""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QBrush, QColor, QIcon, QPixmap
from PySide6.QtWidgets import QComboBox, QFormLayout, QGroupBox, QHeaderView, QLabel, QTableWidget, QTableWidgetItem

from engine.job import Job
from winder_gui.panels.section_panel import Field, SectionPanel, fmt
from winder_gui.views.machine_schematic import MachineSchematic, axis_colour

LIMIT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("min", "min"),
    ("max", "max"),
    ("max_speed", "speed"),
    ("max_accel", "accel"),
    ("max_jump", "jump"),
)
UNLIMITED = 1e11
DEFAULT_CONTROLLER = "(post's own)"

POST_FIELDS: tuple[Field, ...] = (
    Field("post", "tolerance_mm", "Path tolerance [mm]", group="NC output"),
    Field("post", "min_block_time_s", "Min block time τ [s]", group="NC output"),
)


class MachinePanel(SectionPanel):
    """Machine template picker with its axes table, post-processor and controller choice."""

    def __init__(self) -> None:
        super().__init__("Machine", POST_FIELDS)
        from engine.kinematics import list_machines
        from engine.post import list_controllers, list_posts

        box = QGroupBox("Kinematic template")
        form = QFormLayout(box)
        self.template_combo = QComboBox()
        self.template_combo.setObjectName("machine.template")
        self.template_combo.addItems(list_machines())
        form.addRow("Template", self.template_combo)
        self.title_label = QLabel("")
        self.title_label.setWordWrap(True)
        self.title_label.setStyleSheet("color: #555;")
        form.addRow(self.title_label)
        self.schematic = MachineSchematic()
        form.addRow(self.schematic)
        self.table = QTableWidget(0, 3 + len(LIMIT_COLUMNS))
        self.table.setObjectName("machine.axes")
        self.table.setHorizontalHeaderLabels(["axis", "type", "units", *[h for _, h in LIMIT_COLUMNS]])
        self.table.verticalHeader().hide()
        self.table.setSelectionBehavior(QTableWidget.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QTableWidget.SelectionMode.SingleSelection)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.setColumnHidden(1, True)  # rotary/linear: the units say it (deg or mm); shown as a tooltip
        for j, tip in enumerate(("min position", "max position", "max speed [units/s]", "max acceleration [units/s²]",
                                 "max speed jump between blocks [units/s]")):
            self.table.horizontalHeaderItem(3 + j).setToolTip(tip)
        font = self.table.font()
        font.setPointSizeF(max(font.pointSizeF() - 1.0, 7.0))
        self.table.setFont(font)
        self.table.setMinimumHeight(150)
        self.table.setToolTip("Limits in controller units (mm or deg, per s). Blank: the template's value.")
        form.addRow(self.table)
        self.table_error = QLabel("")
        self.table_error.setObjectName("error.machine.axes")
        self.table_error.setStyleSheet("color: #c01010; font-size: 9pt;")
        self.table_error.setWordWrap(True)
        self.table_error.hide()
        form.addRow(self.table_error)

        pbox = QGroupBox("Post-processor")
        pform = QFormLayout(pbox)
        self.post_combo = QComboBox()
        self.post_combo.setObjectName("post.post")
        self.post_combo.addItems(list_posts())
        self.controller_combo = QComboBox()
        self.controller_combo.setObjectName("post.controller")
        self.controller_combo.addItems([DEFAULT_CONTROLLER, *list_controllers()])
        pform.addRow("Dialect", self.post_combo)
        pform.addRow("Controller profile", self.controller_combo)
        # template + post first, then the NC output fields of the base class
        self.lay.insertWidget(1, box)
        self.lay.insertWidget(2, pbox)
        self.finish()
        self.template: Any = None
        self.template_combo.activated.connect(self._on_template)
        self.post_combo.activated.connect(lambda _i: self._on_edited())
        self.controller_combo.activated.connect(lambda _i: self._on_edited())
        self.table.itemChanged.connect(lambda _it: self._on_edited())
        self.table.itemChanged.connect(lambda _it: self._update_schematic_limits())
        self.table.itemSelectionChanged.connect(self._on_row_selected)
        self.schematic.axis_clicked.connect(self.select_axis)

    # -- loading ---------------------------------------------------------------------------------
    def load_extra(self, job: Job) -> None:
        name = job.machine.template
        if self.template_combo.findText(name) < 0:
            self.template_combo.addItem(name)
        self.template_combo.setCurrentText(name)
        self.post_combo.setCurrentText(job.post.post)
        self.controller_combo.setCurrentText(job.post.controller or DEFAULT_CONTROLLER)
        self._fill_table(job)

    def _fill_table(self, job: Job) -> None:
        from engine.errors import InputError
        from engine.pipeline import load_machine_for_job

        self.table.blockSignals(True)
        try:
            try:
                from engine.kinematics import load_machine

                self.template = load_machine(job.machine.template)
                shown = load_machine_for_job(job)
            except InputError as exc:
                self.template = None
                self.table.setRowCount(0)
                self.title_label.setText(exc.message)
                self.schematic.set_machine(None, str(exc))
                return
            self.schematic.set_machine(shown)
            self.title_label.setText(f"{self.template.title} ({self.template.kind})")
            self.table.setRowCount(len(shown.axes))
            # every row and column in view: the page scrolls, not the table
            rows_h = sum(self.table.rowHeight(i) for i in range(len(shown.axes)))
            self.table.setMinimumHeight(min(self.table.horizontalHeader().height() + rows_h + 24, 600))
            for i, (ax, base) in enumerate(zip(shown.axes, self.template.axes, strict=True)):
                for j, text in enumerate((ax.name, ax.type, ax.units)):
                    it = QTableWidgetItem(text)
                    it.setFlags(Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsSelectable)
                    it.setToolTip(f"{ax.name}: {ax.type} axis [{ax.units}]")
                    if j == 0:   # the axis's colour in the schematic and the axis plots
                        pm = QPixmap(10, 10)
                        pm.fill(QColor(axis_colour(i)))
                        it.setIcon(QIcon(pm))
                    self.table.setItem(i, j, it)
                for j, (key, _h) in enumerate(LIMIT_COLUMNS):
                    v = float(getattr(ax, key))
                    it = QTableWidgetItem("" if abs(v) >= UNLIMITED else fmt(v))
                    it.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
                    if v != float(getattr(base, key)):
                        it.setBackground(QBrush(QColor("#fff3c4")))  # an override of the template
                        it.setToolTip(f"template: {fmt(float(getattr(base, key)))}")
                    self.table.setItem(i, 3 + j, it)
        finally:
            self.table.clearSelection()
            self.table.blockSignals(False)
            self.schematic.set_highlight(None)

    # -- API for tests and the window -------------------------------------------------------------
    def set_cell(self, axis: str, key: str, text: str) -> None:
        """Type ``text`` into the ``key`` limit cell of ``axis`` (as a user would)."""
        row = next(i for i in range(self.table.rowCount()) if self.table.item(i, 0).text() == axis)
        col = 3 + [k for k, _ in LIMIT_COLUMNS].index(key)
        self.table.item(row, col).setText(text)

    def axes_rows(self) -> list[dict[str, str]]:
        """The table as shown: one dict per axis, column key -> text."""
        keys = ["name", "type", "units", *[k for k, _ in LIMIT_COLUMNS]]
        return [{k: self.table.item(i, j).text() for j, k in enumerate(keys)} for i in range(self.table.rowCount())]

    def select_axis(self, name: str) -> None:
        """Select the table row of axis ``name`` (the schematic highlights that axis)."""
        for i in range(self.table.rowCount()):
            if self.table.item(i, 0).text() == name:
                self.table.selectRow(i)
                return

    def _on_row_selected(self) -> None:
        rows = {ix.row() for ix in self.table.selectedIndexes()}
        row = min(rows) if rows else None
        it = self.table.item(row, 0) if row is not None else None
        self.schematic.set_highlight(it.text() if it is not None else None)

    def _update_schematic_limits(self) -> None:
        """Redraw the schematic with the travel limits typed in the table (valid cells only)."""
        if self.template is None or self.table.rowCount() != len(self.template.axes):
            return
        from dataclasses import replace

        axes = []
        for i, ax in enumerate(self.template.axes):
            lim = {}
            for key in ("min", "max"):
                it = self.table.item(i, 3 + [k for k, _ in LIMIT_COLUMNS].index(key))
                text = it.text().strip().replace(",", ".") if it is not None else ""
                lim[key] = float(text) if text and _num(text) else float(getattr(ax, key))
            axes.append(replace(ax, **lim) if lim["min"] < lim["max"] else ax)
        self.schematic.set_machine(replace(self.template, axes=tuple(axes)))

    def select_template(self, name: str) -> None:
        self.template_combo.setCurrentText(name)
        self._on_template(0)

    # -- edits -----------------------------------------------------------------------------------
    def _on_template(self, _i: int) -> None:
        if self.job is None:
            return
        name = self.template_combo.currentText()
        if name == self.job.machine.template:
            return
        job = self.job.replace(machine={"template": name, "axes": {}})
        self.job = job
        self._loading = True
        try:
            self._fill_table(job)
        finally:
            self._loading = False
        self._on_edited()

    def extra_changes(self, sections: dict[str, dict[str, Any]], errs: dict[str, str]) -> None:
        sections["post"]["post"] = self.post_combo.currentText()
        ctl = self.controller_combo.currentText()
        sections["post"]["controller"] = None if ctl == DEFAULT_CONTROLLER else ctl
        if self.template is None:
            return
        axes: dict[str, dict[str, float]] = {}
        bad = []
        for i, base in enumerate(self.template.axes):
            ov: dict[str, float] = {}
            for j, (key, head) in enumerate(LIMIT_COLUMNS):
                it = self.table.item(i, 3 + j)
                text = it.text().strip() if it is not None else ""
                ok = True
                if text:
                    try:
                        v = float(text.replace(",", "."))
                        ok = math.isfinite(v) and (key in ("min", "max") or v > 0)
                    except ValueError:
                        ok = False
                    if ok and v != float(getattr(base, key)):
                        ov[key] = v
                    if not ok:
                        bad.append(f"axis {base.name} {head}: {'must be > 0' if _num(text) else 'not a number'}"
                                   f" ({text!r})")
                if it is not None:
                    self.table.blockSignals(True)
                    it.setForeground(QBrush(QColor("#c01010" if not ok else "#000000")))
                    self.table.blockSignals(False)
            lo, hi = ov.get("min", base.min), ov.get("max", base.max)
            if lo > hi:
                bad.append(f"axis {base.name}: min {fmt(lo)} > max {fmt(hi)}")
            if ov:
                axes[base.name] = ov
        sections["machine"] = {"template": self.template_combo.currentText(), "axes": axes}
        if bad:
            errs["machine.axes"] = "; ".join(bad)

    def clear_errors(self) -> None:
        super().clear_errors()
        if hasattr(self, "table_error"):
            self.table_error.hide()
            self.table_error.setText("")

    def show_error(self, field_name: str | None, message: str) -> bool:
        if field_name and field_name.startswith("machine"):
            self.table_error.setText(message)
            self.table_error.show()
            return True
        return super().show_error(field_name, message)

    def _on_edited(self) -> None:
        super()._on_edited()
        msg = self.status.text()
        if self.errors().startswith("machine.axes"):
            self.status.setText("")
            self.table_error.setText(msg)
            self.table_error.show()


def _num(text: str) -> bool:
    try:
        return math.isfinite(float(text.replace(",", ".")))
    except ValueError:
        return False
