"""Properties page of the Machine step: kinematic template, its axes and limits, post-processor, controller.

The template list is ``resources/machines/*.toml`` (:func:`engine.kinematics.list_machines`).  Under
it, a schematic of the template's kinematic chain (:class:`winder_gui.views.machine_schematic.MachineSchematic`,
drawn from the engine's forward kinematics; each axis in the colour of its table row, the selected
row's axis drawn bold; clicking an axis in the drawing selects its row).  The axes table shows each
axis's name, type, units, travel limits and speed/acceleration/jump limits (controller units: mm or
deg, per s).  The limit cells are editable: a value different from the template's becomes an override
in the job (``[machine.axes.<name>]``); a blank cell restores the template's value.  Post-processor
(:func:`engine.post.list_posts`) and controller profile
(:func:`engine.post.list_controllers`) are chosen below; both lists offer only what can address the
template's axes (:func:`engine.machine_setup.compatible_posts`).  The set-up group edits
``[machine.setup]`` (:class:`engine.job.SetupSpec`): where the mandrel sits on the machine (blank:
centred), the eye radius and head offsets, the shafts, chuck and tailstock, the clearance and the
back-turn tolerance; the schematic draws the part and its supports at that placement.
"""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QBrush, QColor, QIcon, QPixmap
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHeaderView,
    QLabel,
    QLineEdit,
    QTableWidget,
    QTableWidgetItem,
)

from engine.job import Job
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.panels.section_panel import Field, SectionPanel, fmt
from winder_gui.views.machine_schematic import MachineSchematic, axis_colour

LIMIT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("min", QT_TR_NOOP("min")),
    ("max", QT_TR_NOOP("max")),
    ("max_speed", QT_TR_NOOP("speed")),
    ("max_accel", QT_TR_NOOP("accel")),
    ("max_jump", QT_TR_NOOP("jump")),
)
UNLIMITED = 1e11
DEFAULT_CONTROLLER = QT_TR_NOOP("(post's own)")

# [machine.setup] editors: key, label, optional (blank = the engine's default)
SETUP_FIELDS: tuple[tuple[str, str, bool], ...] = (
    ("mandrel_z0_mm", QT_TR_NOOP("Mandrel z = 0 at carriage [mm]"), True),
    ("eye_radius_mm", QT_TR_NOOP("Eye radius (fixed-radius machine) [mm]"), True),
    ("head_offset_mm.0", QT_TR_NOOP("Head offset radial [mm]"), False),
    ("head_offset_mm.1", QT_TR_NOOP("Head offset vertical [mm]"), False),
    ("head_offset_mm.2", QT_TR_NOOP("Head offset axial [mm]"), False),
    ("shaft_radius_mm", QT_TR_NOOP("Shaft radius [mm]"), True),
    ("shaft_length_mm", QT_TR_NOOP("Free shaft length [mm]"), False),
    ("chuck_radius_mm", QT_TR_NOOP("Chuck radius [mm]"), True),
    ("chuck_length_mm", QT_TR_NOOP("Chuck length [mm]"), False),
    ("tailstock_radius_mm", QT_TR_NOOP("Tailstock radius [mm]"), True),
    ("tailstock_length_mm", QT_TR_NOOP("Tailstock length [mm]"), False),
    ("clearance_mm", QT_TR_NOOP("Clearance to supports [mm]"), False),
    ("head_radius_mm", QT_TR_NOOP("Head body radius around the eye [mm]"), False),
    ("head_length_mm", QT_TR_NOOP("Head body length along the roll axis [mm]"), False),
    ("back_turn_tol_deg", QT_TR_NOOP("Back-turn tolerance [deg]"), False),
)
SETUP_DEFAULT_TEXT = {"mandrel_z0_mm": QT_TR_NOOP("centred"), "eye_radius_mm": QT_TR_NOOP("template's"),
                      "shaft_radius_mm": QT_TR_NOOP("0.6 x end radius"), "chuck_radius_mm": QT_TR_NOOP("2 x shaft"),
                      "tailstock_radius_mm": QT_TR_NOOP("1.5 x shaft")}

POST_FIELDS: tuple[Field, ...] = (
    Field("post", "tolerance_mm", QT_TR_NOOP("Path tolerance [mm]"), group=QT_TR_NOOP("NC output")),
    Field("post", "min_block_time_s", QT_TR_NOOP("Min block time τ [s]"), group=QT_TR_NOOP("NC output")),
)


class MachinePanel(SectionPanel):
    """Machine template picker with its axes table, post-processor and controller choice."""

    def __init__(self) -> None:
        super().__init__(tr("Machine"), POST_FIELDS)
        from engine.kinematics import list_machines
        from engine.post import list_controllers, list_posts

        box = QGroupBox(tr("Kinematic template"))
        form = QFormLayout(box)
        self.template_combo = QComboBox()
        self.template_combo.setObjectName("machine.template")
        self.template_combo.addItems(list_machines())
        form.addRow(tr("Template"), self.template_combo)
        self.title_label = QLabel("")
        self.title_label.setWordWrap(True)
        self.title_label.setStyleSheet("color: #555;")
        form.addRow(self.title_label)
        self.schematic = MachineSchematic()
        form.addRow(self.schematic)
        self.table = QTableWidget(0, 3 + len(LIMIT_COLUMNS))
        self.table.setObjectName("machine.axes")
        self.table.setHorizontalHeaderLabels([tr("axis"), tr("type"), tr("units"), *[tr(h) for _, h in LIMIT_COLUMNS]])
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
        self.table.setToolTip(tr("Limits in controller units (mm or deg, per s). Blank: the template's value."))
        form.addRow(self.table)
        self.table_error = QLabel("")
        self.table_error.setObjectName("error.machine.axes")
        self.table_error.setStyleSheet("color: #c01010; font-size: 9pt;")
        self.table_error.setWordWrap(True)
        self.table_error.hide()
        form.addRow(self.table_error)

        pbox = QGroupBox(tr("Post-processor"))
        pform = QFormLayout(pbox)
        self.post_combo = QComboBox()
        self.post_combo.setObjectName("post.post")
        self.post_combo.addItems(list_posts())
        self.controller_combo = QComboBox()
        self.controller_combo.setObjectName("post.controller")
        self.controller_combo.addItems([tr(DEFAULT_CONTROLLER), *list_controllers()])
        pform.addRow(tr("Dialect"), self.post_combo)
        pform.addRow(tr("Controller profile"), self.controller_combo)
        self.post_note = QLabel("")
        self.post_note.setWordWrap(True)
        self.post_note.setStyleSheet("color: #555; font-size: 9pt;")
        pform.addRow(self.post_note)
        sbox = QGroupBox(tr("Set-up (placement, head, supports)"))
        sform = QFormLayout(sbox)
        self.setup_edits: dict[str, QLineEdit] = {}
        for key, label, optional in SETUP_FIELDS:
            ed = QLineEdit()
            ed.setObjectName(f"machine.setup.{key}")
            ed.setAlignment(Qt.AlignmentFlag.AlignRight)
            if optional:
                ed.setPlaceholderText(tr(SETUP_DEFAULT_TEXT.get(key, QT_TR_NOOP("default"))))
            ed.textEdited.connect(lambda _t: self._on_edited())
            sform.addRow(tr(label), ed)
            self.setup_edits[key] = ed
        self.placement_label = QLabel("")
        self.placement_label.setObjectName("machine.placement")
        self.placement_label.setWordWrap(True)
        self.placement_label.setStyleSheet("color: #555; font-size: 9pt;")
        sform.addRow(self.placement_label)
        # template + post first, then the set-up, then the NC output fields of the base class
        self.lay.insertWidget(1, box)
        self.lay.insertWidget(2, pbox)
        self.lay.insertWidget(3, sbox)
        self.finish()
        self.template: Any = None
        self.template_combo.activated.connect(self._on_template)
        self.post_combo.activated.connect(lambda _i: self._on_post())
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
        self._fill_table(job)
        self._fill_posts(job.post.post, job.post.controller)
        su = job.machine.setup.model_dump()
        for key, _label, _opt in SETUP_FIELDS:
            base, _, idx = key.partition(".")
            v = su[base] if not idx else su[base][int(idx)]
            self.setup_edits[key].setText("" if v is None else fmt(v))
        self.placement_label.setText("")

    def _fill_posts(self, post: str, controller: str | None) -> None:
        """Only the dialects and profiles that can address the template's axes (all when unknown)."""
        from engine.machine_setup import compatible_posts
        from engine.post import list_controllers, list_posts

        if self.template is not None:
            pairs = compatible_posts(self.template)
        else:       # no template to check against: every dialect with its own profiles
            from engine.post import load_controller

            dialect = {c: load_controller(c).dialect for c in list_controllers()}
            pairs = [(p, c) for p in list_posts() for c in list_controllers() if dialect[c] == p]
        posts = sorted({p for p, _c in pairs})
        self.post_combo.blockSignals(True)
        self.controller_combo.blockSignals(True)
        try:
            self.post_combo.clear()
            self.post_combo.addItems(posts)
            note = ""
            if post in posts:
                self.post_combo.setCurrentText(post)
            elif posts:
                pick = "linuxcnc" if "linuxcnc" in posts else posts[0]
                self.post_combo.setCurrentText(pick)
                note = (f"{post or 'no post'} cannot address the axes of {getattr(self.template, 'name', '?')}: "
                        f"{pick} chosen")
            ctls = [c for p, c in pairs if p == self.post_combo.currentText()]
            self.controller_combo.clear()
            self.controller_combo.addItems([tr(DEFAULT_CONTROLLER), *ctls])
            if controller and controller in ctls:
                self.controller_combo.setCurrentText(controller)
            elif controller:
                note = (note + "; " if note else "") + f"controller {controller} does not fit: the dialect's own used"
            self.post_note.setText(note)
        finally:
            self.post_combo.blockSignals(False)
            self.controller_combo.blockSignals(False)

    def set_mandrel(self, mandrel: Any) -> None:
        """The job's built mandrel (from the build worker): the schematic draws it and its supports."""
        self._mandrel = mandrel
        if self.template is not None and getattr(self, "job_for_part", None) is not None:
            from engine.errors import InputError
            from engine.pipeline import load_machine_for_job

            try:
                self._show_part(load_machine_for_job(self.job_for_part))
            except InputError:
                pass

    def show_placement(self, machine: Any, placement: Any, mandrel: Any = None) -> None:
        """After a run: the template as placed (carriage offset) and the placement sentence."""
        self.placement_label.setText(placement.message() if placement is not None else "")
        self._placed = machine
        if mandrel is not None:
            self._mandrel = mandrel
        if machine is not None and self.template is not None and machine.name == self.template.name:
            self._show_part(machine)

    def _show_part(self, machine: Any) -> None:
        """The schematic of ``machine`` with the job's mandrel and supports (the mandrel the build worker
        made, :meth:`set_mandrel`; nothing is computed here - the nominal mandrel until one is built)."""
        from engine.errors import InputError
        from engine.machine_setup import apply_setup, support_obstacles

        job = getattr(self, "job_for_part", None)
        mandrel = getattr(self, "_mandrel", None)
        part = None
        if job is not None and mandrel is not None:
            try:
                obs = support_obstacles(mandrel, job.machine.setup)
                part = (mandrel.z_min, mandrel.z_max, float(mandrel.r_max), [(o.name, o.z0, o.z1, o.radius)
                                                                            for o in obs])
                if machine is not None and job.machine.setup.mandrel_z0_mm is not None:
                    machine = apply_setup(machine, job.machine.setup)
                elif machine is not None and machine is not getattr(self, "_placed", None):
                    machine = _centre_estimate(machine, mandrel)
            except InputError:
                part = None
        self.schematic.set_part(part)
        if job is not None:
            self.schematic.set_head(job.machine.setup.head_radius_mm, job.machine.setup.head_length_mm)
        self.schematic.set_machine(machine)

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
            self.job_for_part = job
            self._show_part(shown)
            self.title_label.setText(f"{self.template.title} ({self.template.kind})")
            self.table.setRowCount(len(shown.axes))
            # every row and column in view: the page scrolls, not the table
            rows_h = sum(self.table.rowHeight(i) for i in range(len(shown.axes)))
            self.table.setMinimumHeight(min(self.table.horizontalHeader().height() + rows_h + 24, 600))
            for i, (ax, base) in enumerate(zip(shown.axes, self.template.axes, strict=True)):
                for j, text in enumerate((ax.name, ax.type, ax.units)):
                    it = QTableWidgetItem(text)
                    it.setFlags(Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsSelectable)
                    it.setToolTip(tr("{name}: {type} axis [{units}]")
                                  .format(name=ax.name, type=ax.type, units=ax.units))
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
                        it.setToolTip(tr("template: {v0}").format(v0=fmt(float(getattr(base, key)))))
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
        self._show_part(replace(self.template, axes=tuple(axes)))

    def _on_post(self) -> None:
        ctl = self.controller_combo.currentText()
        self._fill_posts(self.post_combo.currentText(), None if ctl == tr(DEFAULT_CONTROLLER) else ctl)
        self._on_edited()

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
        job = self.job.replace(machine={"template": name, "axes": {}, "setup": self.job.machine.setup})
        self.job = job
        self._loading = True
        try:
            self._fill_table(job)
            ctl = self.controller_combo.currentText()
            self._fill_posts(self.post_combo.currentText(), None if ctl == tr(DEFAULT_CONTROLLER) else ctl)
        finally:
            self._loading = False
        self._on_edited()

    def extra_changes(self, sections: dict[str, dict[str, Any]], errs: dict[str, str]) -> None:
        sections["post"]["post"] = self.post_combo.currentText()
        ctl = self.controller_combo.currentText()
        sections["post"]["controller"] = None if ctl == tr(DEFAULT_CONTROLLER) else ctl
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
        setup: dict[str, Any] = {}
        offs = [0.0, 0.0, 0.0]
        for key, label, optional in SETUP_FIELDS:
            text = self.setup_edits[key].text().strip().replace(",", ".")
            base, _, idx = key.partition(".")
            if not text:
                if not optional and not idx:
                    from engine.job import SetupSpec

                    setup[base] = SetupSpec.model_fields[base].default
                continue
            if not _num(text):
                bad.append(tr("{label}: not a number ({text!r})").format(label=tr(label), text=text))
                continue
            if idx:
                offs[int(idx)] = float(text)
            else:
                setup[base] = float(text)
        setup["head_offset_mm"] = tuple(offs)
        sections["machine"] = {"template": self.template_combo.currentText(), "axes": axes, "setup": setup}
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


def _centre_estimate(machine: Any, mandrel: Any) -> Any:
    """Before a run: the carriage offset that centres the mandrel's length in the travel (the run
    centres the eye path, engine.machine_setup.place_on_machine)."""
    from dataclasses import replace

    from engine.machine_setup import carriage_index

    k = carriage_index(machine)
    if k is None:
        return machine
    ax = machine.axes[k]
    if abs(ax.min) >= UNLIMITED or abs(ax.max) >= UNLIMITED:
        return machine
    off = round(0.5 * (ax.min + ax.max) - ax.scale * 0.5 * (mandrel.z_min + mandrel.z_max), 1)
    return replace(machine, axes=tuple(replace(a, offset=off) if i == k else a for i, a in enumerate(machine.axes)))


def _num(text: str) -> bool:
    try:
        return math.isfinite(float(text.replace(",", ".")))
    except ValueError:
        return False
