"""Properties panel of the Mandrel step: template kind and its parameters, or the sketch table.

Each kind has its own page of fields (units in the labels); only the current kind's page is shown
and enabled, and the dome axis ratio only for elliptical domes.  Every keystroke is checked at
once: a bad value shows a red message right under its field and nothing is emitted; a valid set
of values is emitted as a new mandrel spec (:attr:`MandrelPanel.spec_edited`).  Errors found later,
when the mandrel is built, come back through :meth:`MandrelPanel.show_error`.

A sketched mandrel (kind ``points``) shows its points in a numeric table
(:class:`winder_gui.panels.points_table.PointsTable`): a valid table is emitted as a
:class:`~engine.job.PointsSpec` through the same :attr:`MandrelPanel.spec_edited`, a bad cell is red
with its message and the message also goes to :attr:`MandrelPanel.status`, which is what blocks Run
(the window reads it as the mandrel's problem).  A template offers "Convert to sketch", which asks the
window (:attr:`MandrelPanel.points_requested`) to replace it by points sampled from its curve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSizePolicy,
    QStackedWidget,
    QVBoxLayout,
    QWidget,
)

from engine.job import BottleSpec, ConeSpec, FileSpec, PipeSpec, PointsSpec, SegmentsSpec, VesselSpec
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.panels.points_table import PointsTable
from winder_gui.panels.points_table import fmt as table_fmt
from winder_gui.panels.segments_table import SegmentsTable

KINDS: tuple[tuple[str, str], ...] = (
    ("vessel", "Vessel — cylinder + two domes"),
    ("cone", "Cone — frustum"),
    ("pipe", "Pipe — cylinder"),
    ("bottle", "Bottle — concave neck"),
    ("segments", "Sketch — lines, arcs, domes (exact)"),
    ("points", "Sketched points (spline)"),
    ("file", "Imported profile (CSV/DXF/STEP)"),
)
SPEC_TYPES: dict[str, type] = {
    "vessel": VesselSpec,
    "cone": ConeSpec,
    "pipe": PipeSpec,
    "bottle": BottleSpec,
    "points": PointsSpec,
    "segments": SegmentsSpec,
    "file": FileSpec,
}
DOMES = ("hemisphere", "ellipse", "isotensoid")

# (key, label); "name.0"/"name.1" are the left/right members of a pair field
FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    "vessel": (
        ("radius_mm", QT_TR_NOOP("Radius R [mm]")),
        ("cylinder_length_mm", QT_TR_NOOP("Cylinder length [mm]")),
        ("dome.0", QT_TR_NOOP("Left dome")),
        ("dome_ratio.0", QT_TR_NOOP("Left dome axis ratio a/R [–]")),
        ("pole_radius_mm.0", QT_TR_NOOP("Left pole opening radius [mm]")),
        ("dome.1", QT_TR_NOOP("Right dome")),
        ("dome_ratio.1", QT_TR_NOOP("Right dome axis ratio a/R [–]")),
        ("pole_radius_mm.1", QT_TR_NOOP("Right pole opening radius [mm]")),
    ),
    "cone": (
        ("r0_mm", QT_TR_NOOP("Radius at z = 0, r0 [mm]")),
        ("r1_mm", QT_TR_NOOP("Radius at z = L, r1 [mm]")),
        ("length_mm", QT_TR_NOOP("Length L [mm]")),
    ),
    "pipe": (("radius_mm", QT_TR_NOOP("Radius R [mm]")), ("length_mm", QT_TR_NOOP("Length L [mm]"))),
    "bottle": (
        ("radius_mm", QT_TR_NOOP("Body radius R [mm]")),
        ("body_length_mm", QT_TR_NOOP("Body length [mm]")),
        ("shoulder_length_mm", QT_TR_NOOP("Shoulder length [mm]")),
        ("waist_radius_mm", QT_TR_NOOP("Waist radius [mm]")),
        ("neck_length_mm", QT_TR_NOOP("Neck length [mm]")),
        ("neck_radius_mm", QT_TR_NOOP("Neck radius [mm]")),
        ("bottom_pole_radius_mm", QT_TR_NOOP("Bottom pole opening radius [mm]")),
    ),
    "points": (),
    "segments": (),
    "file": (("path", QT_TR_NOOP("Profile file")), ("smoothing_mm", QT_TR_NOOP("Smoothing tolerance [mm]"))),
}
OPTIONAL = {"smoothing_mm"}
"""Fields that may stay empty (then left out of the spec)."""


def fmt(v: float) -> str:
    """A number for a text field: short, but exact enough to round-trip typical inputs."""
    return format(float(v), ".10g")


@dataclass
class _Row:
    key: str
    editor: QLineEdit | QComboBox
    error: QLabel
    shown: str = ""
    value: Any = None


class MandrelPanel(QWidget):
    """Kind selector and parameter fields of the job's mandrel.

    Signals
    -------
    spec_edited(spec):
        A valid new mandrel spec (pydantic model from :mod:`engine.job`) typed by the user.
    points_requested():
        The user chose "Sketched points": the window converts the current mandrel.
    import_requested():
        The user wants to import a profile file.
    """

    spec_edited = Signal(object)
    checked = Signal()
    """Emitted after every check of the fields (valid or not): the window re-evaluates Run."""
    points_requested = Signal()
    sketch_requested = Signal()
    """The user asked for "Convert to sketch": the window replaces the template by its exact segments."""
    import_requested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.spec: Any = None
        self.hint = (100.0, 400.0)
        """(r_max, length) of the current mandrel in mm: scales the defaults of a newly chosen kind."""
        self.rows: dict[tuple[str, str], _Row] = {}
        self._loading = False

        lay = QVBoxLayout(self)
        lay.setContentsMargins(6, 6, 6, 6)
        title = QLabel(tr("<b>Mandrel</b>"))
        lay.addWidget(title)
        kind_form = QFormLayout()
        self.kind_combo = QComboBox()
        for key, text in KINDS:
            self.kind_combo.addItem(text, key)
        kind_form.addRow(tr("Kind"), self.kind_combo)
        lay.addLayout(kind_form)

        self.pages = QStackedWidget()
        self.page_index: dict[str, int] = {}
        for kind, _ in KINDS:
            box = QGroupBox(tr("Parameters"))
            form = QFormLayout(box)
            form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
            for key, label in FIELDS[kind]:
                row = self._make_row(kind, key)
                cell = QWidget()
                v = QVBoxLayout(cell)
                v.setContentsMargins(0, 0, 0, 0)
                v.setSpacing(1)
                if kind == "file":
                    h = QHBoxLayout()
                    h.addWidget(row.editor, 1)
                    self.import_button = QPushButton(tr("Import…"))
                    self.import_button.clicked.connect(self.import_requested)
                    h.addWidget(self.import_button)
                    v.addLayout(h)
                else:
                    v.addWidget(row.editor)
                form.addRow(tr(label), cell)
                form.addRow(row.error)  # full width under its field; hidden while the value is fine
            if kind == "points":
                box.setTitle(tr("Points"))
                self.points_info = QLabel("")
                self.points_info.setWordWrap(True)
                self.points_info.setStyleSheet("color: #666;")
                form.addRow(self.points_info)
                self.points_table = PointsTable()
                form.addRow(self.points_table)
            if kind == "segments":
                box.setTitle(tr("Segments"))
                note = QLabel(tr("Joints are tangent unless Corner is ticked (then rounded by Fillet). Arc: Centre, "
                              "or a signed Radius (> 0 convex, < 0 concave), or neither (tangent arc). Isotensoid: "
                              "Pole r (dome down to it) or Radius (dome up to that equator)."))
                note.setWordWrap(True)
                note.setStyleSheet("color: #666;")
                form.addRow(note)
                self.segments_table = SegmentsTable()
                form.addRow(self.segments_table)
            if kind == "file":
                note = QLabel(tr("The profile is read from the file each time the job is opened. Smoothing (CSV "
                              "tables only): the smoothest spline within this distance of the measured points; "
                              "empty = through the points."))
                note.setWordWrap(True)
                note.setStyleSheet("color: #666;")
                form.addRow(note)
                self.file_info = QLabel("")
                self.file_info.setObjectName("fileInfo")
                self.file_info.setWordWrap(True)
                form.addRow(self.file_info)
            self.page_index[kind] = self.pages.addWidget(box)
        lay.addWidget(self.pages)
        self.convert_button = QPushButton(tr("Convert to sketch (exact segments)"))
        self.convert_button.setObjectName("convertToSketch")
        self.convert_button.setToolTip(
            tr("Replace the template by a sketch of its exact segments (lines, arcs, ellipse arcs, domes);\n"
            "the segments can then be edited in a table (undo with Ctrl+Z)")
        )
        self.convert_button.clicked.connect(self.convert_to_sketch)
        lay.addWidget(self.convert_button)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.status.setStyleSheet("color: #c01010;")
        lay.addWidget(self.status)
        self._stretch = QWidget()  # takes the spare height, except for the sketch table which takes it itself
        lay.addWidget(self._stretch, 1)
        self.kind_combo.activated.connect(self._on_kind_activated)
        self.points_table.points_edited.connect(self._on_table_edited)
        self.points_table.problem.connect(self._on_table_problem)
        self.segments_table.segments_edited.connect(self._on_segments_edited)
        self.segments_table.problem.connect(self._on_table_problem)

    def _make_row(self, kind: str, key: str) -> _Row:
        editor: QLineEdit | QComboBox
        if key.startswith("dome."):
            editor = QComboBox()
            editor.addItems(DOMES)
            editor.activated.connect(lambda _i, k=kind: self._on_edited(k))
        else:
            editor = QLineEdit()
            if key == "path":
                editor.setReadOnly(True)
                editor.setPlaceholderText(tr("choose a file with Import…"))
            else:
                editor.setAlignment(Qt.AlignmentFlag.AlignRight)
                editor.textEdited.connect(lambda _t, k=kind: self._on_edited(k))
        editor.setObjectName(f"{kind}.{key}")
        err = QLabel("")
        err.setObjectName(f"error.{kind}.{key}")
        err.setStyleSheet("color: #c01010; font-size: 9pt; padding-left: 12px;")
        err.setWordWrap(True)
        err.hide()
        row = _Row(key, editor, err)
        self.rows[(kind, key)] = row
        return row

    # -- public API ------------------------------------------------------------------------------
    def current_kind(self) -> str:
        """The kind shown in the selector."""
        return str(self.kind_combo.currentData())

    def editor(self, key: str, kind: str | None = None) -> QLineEdit | QComboBox:
        """The field editor of ``key`` (e.g. ``"radius_mm"``, ``"pole_radius_mm.0"``) for ``kind``."""
        return self.rows[(kind or self.current_kind(), key)].editor

    def error_text(self, key: str, kind: str | None = None) -> str:
        """The inline message under field ``key`` ("" when none is shown)."""
        row = self.rows[(kind or self.current_kind(), key)]
        return row.error.text() if not row.error.isHidden() else ""

    def set_value(self, key: str, value: float | str) -> None:
        """Type ``value`` into field ``key`` of the current kind as a user would (emits on success)."""
        ed = self.editor(key)
        if isinstance(ed, QComboBox):
            ed.setCurrentText(str(value))
        else:
            ed.setText(fmt(value) if isinstance(value, int | float) else str(value))
        self._on_edited(self.current_kind())

    def set_spec(self, spec: Any) -> None:
        """Show ``spec`` (a mandrel spec of the job) without emitting anything."""
        self._loading = True
        try:
            self.spec = spec
            kind = spec.kind
            self.kind_combo.setCurrentIndex(self.kind_combo.findData(kind))
            vals = self._values_of(spec)
            for (k, key), row in self.rows.items():
                if k != kind:
                    continue
                v = vals.get(key)
                row.value = v
                if isinstance(row.editor, QComboBox):
                    row.editor.setCurrentText(str(v))
                    row.shown = str(v)
                else:
                    row.shown = "" if v is None else (fmt(v) if isinstance(v, int | float) else str(v))
                    row.editor.setText(row.shown)
            if kind == "points":
                self.points_table.set_points(spec.z_mm, spec.r_mm)
                self._update_points_info()
            if kind == "segments":
                self.segments_table.set_spec(spec)
            self.clear_errors()
            self._show_page(kind)
        finally:
            self._loading = False

    def clear_errors(self) -> None:
        """Hide every inline message (a problem still in the sketch table stays: it blocks Run)."""
        for row in self.rows.values():
            row.error.hide()
            row.error.setText("")
        self._set_status(self._table_problem())

    def show_built(self, mandrel: Any) -> None:
        """Say how an imported profile was read: exact DXF segments or a spline fit (and why), and for a
        smoothed CSV table the deviation reached."""
        meta = getattr(mandrel, "meta", {}) or {}
        parts = []
        if meta.get("dxf_exact") is True:
            parts.append(f"DXF: {meta.get('segments', len(mandrel.segments))} exact line/arc segments")
        elif meta.get("dxf_exact") is False:
            parts.append(f"DXF: fitted by a spline ({meta.get('dxf_spline_reason', '')})")
        sm = meta.get("smoothing")
        if sm and sm.get("applied"):
            parts.append(f"smoothed within {sm['tolerance_mm']:g} mm: max deviation {sm['max_deviation_mm']:.4g} mm "
                         f"at z = {sm['at_z_mm']:.6g} mm, rms {sm['rms_deviation_mm']:.4g} mm")
        elif sm:
            parts.append(f"smoothing: {sm.get(QT_TR_NOOP('note'), '')}")
        self.file_info.setText("; ".join(parts))

    def convert_to_sketch(self) -> None:
        """Ask the window to replace the template by the sketch of its exact segments."""
        if self.spec is not None and self.spec.kind not in ("points", "segments"):
            self.sketch_requested.emit()

    def attach_plot(self, plot: Any) -> None:
        """Follow the r(z) plot (:class:`winder_gui.views.profile_plot.ProfilePlot`) live.

        The table already follows the job (every applied plot edit comes back through
        :meth:`set_spec`); attached, it also follows a drag in progress, and the selected point and
        row highlight each other, and the rows in concave zones of the built mandrel are marked.
        """
        plot.points_moving.connect(self.points_table.show_points)
        plot.data_shown.connect(lambda data: self.points_table.set_concave(data.concave))
        if plot.data is not None:
            self.points_table.set_concave(plot.data.concave)
        plot.point_selected.connect(self.points_table.select_row)
        self.points_table.row_selected.connect(plot.select_point)
        # the plot's snap grid also rounds the coordinates typed into the segment table
        plot.snap_changed.connect(self._on_snap_changed)
        self._on_snap_changed(plot.snap_check.isChecked(), float(plot.snap_spin.value()))

    def _on_snap_changed(self, on: bool, step: float) -> None:
        self.segments_table.snap_mm = float(step) if on else 0.0

    def show_error(self, field: str | None, message: str) -> None:
        """Show an error of the built mandrel at its field (``mandrel.<name>``) or under the fields."""
        key = (field or "").removeprefix("mandrel.").split(".")[0]
        kind = self.current_kind()
        if kind == "segments" and self.segments_table.show_error(field or "", message):
            self._set_status(self._table_problem())
            return
        keys = [k for (kk, k) in self.rows if kk == kind]
        cands = [k for k in keys if k.split(".")[0] in (key, f"{key}_mm")]
        if len(cands) > 1:
            side = "1" if "right" in message.lower() else "0"
            cands = [k for k in cands if k.endswith(side)] or cands
        if cands:
            row = self.rows[(kind, cands[0])]
            row.error.setText(message)
            row.error.show()
        else:
            self._set_status(message)

    # -- internals -------------------------------------------------------------------------------
    @staticmethod
    def _values_of(spec: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, v in spec.model_dump().items():
            if name == "kind":
                continue
            if isinstance(spec, VesselSpec) and name in ("dome", "dome_ratio", "pole_radius_mm"):
                pair = tuple(v) if isinstance(v, tuple | list) else (v, v)
                out[f"{name}.0"], out[f"{name}.1"] = pair
            else:
                out[name] = v
        return out

    def _set_status(self, text: str) -> None:
        """The message under the fields (the window reads it as the mandrel's problem that blocks Run);
        hidden when it only repeats the message shown under the sketch table."""
        self.status.setText(text)
        self.status.setVisible(bool(text) and text != self._table_problem())

    def _table_problem(self) -> str:
        kind = self.current_kind()
        if kind == "segments":
            msg = self.segments_table.message
            return f"sketch: {msg}" if msg else ""
        msg = self.points_table.message if kind == "points" else ""
        return f"sketch table {msg}" if msg else ""

    def _on_segments_edited(self, spec: Any) -> None:
        if self._loading:
            return
        self.spec_edited.emit(spec)
        self.checked.emit()

    def _on_table_edited(self, z: Any, r: Any) -> None:
        if self._loading:
            return
        try:
            spec = PointsSpec(z_mm=[float(v) for v in z], r_mm=[float(v) for v in r])
        except ValidationError as exc:  # cannot happen after the table's checks; never a traceback
            self._set_status(tr("sketch table: {v0}").format(v0=exc.errors()[0]['msg']))
        else:
            self.spec_edited.emit(spec)
        self._update_points_info()
        self.checked.emit()

    def _on_table_problem(self, _msg: str) -> None:
        if self._loading:
            return
        self._set_status(self._table_problem())
        self.checked.emit()

    def _update_points_info(self) -> None:
        vals = self.points_table.values()
        n = self.points_table.table.rowCount()
        span = f", z from {table_fmt(vals[0][0])} to {table_fmt(vals[0][-1])} mm" if vals is not None else ""
        self.points_info.setText(
            tr("{n} points{span}. C2 spline through them; ◐ marks a point in a concave zone (shaded "
               "on the plot). Also editable on the r(z) plot (drag, double-click to add, right-click "
               "to remove).").format(n=n, span=span)
        )

    def _show_page(self, kind: str) -> None:
        self.pages.setCurrentIndex(self.page_index[kind])
        sketch = kind in ("points", "segments")
        self.convert_button.setVisible(not sketch)
        self._stretch.setVisible(not sketch)
        self.pages.setSizePolicy(QSizePolicy.Policy.Preferred,
                                 QSizePolicy.Policy.Expanding if sketch else QSizePolicy.Policy.Maximum)
        for k, idx in self.page_index.items():
            self.pages.widget(idx).setEnabled(k == kind)
        if kind == "vessel":
            for side in ("0", "1"):
                dome = self.rows[("vessel", f"dome.{side}")].editor
                assert isinstance(dome, QComboBox)
                self.rows[("vessel", f"dome_ratio.{side}")].editor.setEnabled(dome.currentText() == "ellipse")

    def _read(self, kind: str) -> tuple[dict[str, Any], dict[str, str]]:
        """Field values of ``kind`` and per-field problems."""
        vals: dict[str, Any] = {}
        errs: dict[str, str] = {}
        for (k, key), row in self.rows.items():
            if k != kind:
                continue
            ed = row.editor
            if isinstance(ed, QComboBox):
                vals[key] = ed.currentText()
                continue
            text = ed.text().strip()
            if key == "path":
                vals[key] = text
                if not text:
                    errs[key] = "choose a profile file"
                continue
            if text == row.shown and row.value is not None:
                vals[key] = row.value
                continue
            if key in OPTIONAL and not text:
                continue
            try:
                v = float(text.replace(",", "."))
            except ValueError:
                errs[key] = f"not a number: {text!r}" if text else "a value is required"
                continue
            zero_ok = key.startswith(("pole_radius_mm", "cylinder_length_mm"))
            if not math.isfinite(v):
                errs[key] = f"not a finite number: {text!r}"
            elif v < 0 or (v == 0 and not zero_ok):
                errs[key] = f"must be {'≥' if zero_ok else '>'} 0, got {fmt(v)}"
            vals[key] = v
        return vals, {k: m for k, m in errs.items() if m}

    def _assemble(self, kind: str, vals: dict[str, Any]) -> dict[str, Any]:
        data: dict[str, Any] = {"kind": kind}
        for key, v in vals.items():
            if key.endswith(".0"):
                name = key[:-2]
                right = vals[f"{name}.1"]
                data[name] = v if v == right else (v, right)
            elif not key.endswith(".1"):
                data[key] = v
        return data

    def _on_edited(self, kind: str) -> None:
        if self._loading:
            return
        try:
            self._check(kind)
        finally:
            self.checked.emit()

    def _check(self, kind: str) -> None:
        self._show_page(kind)
        self.clear_errors()
        vals, errs = self._read(kind)
        if kind == "vessel":
            for side, name in (("0", "left"), ("1", "right")):
                rp, big_r = vals.get(f"pole_radius_mm.{side}"), vals.get("radius_mm")
                if isinstance(rp, float) and isinstance(big_r, float) and rp >= big_r:
                    errs[f"pole_radius_mm.{side}"] = (
                        f"{name} pole opening {fmt(rp)} mm must be smaller than the radius {fmt(big_r)} mm"
                    )
        if not errs:
            try:
                spec = SPEC_TYPES[kind].model_validate(self._assemble(kind, vals))
            except ValidationError as exc:
                e = exc.errors()[0]
                name = str(e["loc"][0]) if e["loc"] else ""
                keys = [k for (kk, k) in self.rows if kk == kind and k.split(".")[0] == name]
                errs[keys[0] if keys else ""] = e["msg"]
            else:
                self.spec_edited.emit(spec)
                return
        for key, msg in errs.items():
            if (kind, key) in self.rows:
                self.rows[(kind, key)].error.setText(msg)
                self.rows[(kind, key)].error.show()
            else:
                self._set_status(msg)

    def _on_kind_activated(self, _index: int) -> None:
        kind = self.current_kind()
        if self.spec is not None and kind == self.spec.kind:
            return
        if kind == "points":
            self.points_requested.emit()
            return
        if kind == "segments":
            self.sketch_requested.emit()
            return
        if kind == "file":
            self.import_requested.emit()
            return
        spec = self.default_spec(kind)
        self.set_spec(spec)
        self.spec_edited.emit(spec)

    def default_spec(self, kind: str) -> Any:
        """A template spec of ``kind`` sized like the current mandrel (:attr:`hint`)."""
        r, length = (max(float(x), 1.0) for x in self.hint)
        r = round(r, 1)
        length = round(length, 1)
        if kind == "vessel":
            return VesselSpec(radius_mm=r, cylinder_length_mm=round(0.6 * length, 1), pole_radius_mm=round(0.25 * r, 1))
        if kind == "cone":
            return ConeSpec(r0_mm=r, r1_mm=round(0.6 * r, 1), length_mm=length)
        if kind == "pipe":
            return PipeSpec(radius_mm=r, length_mm=length)
        if kind == "bottle":
            return BottleSpec()
        raise ValueError(f"no template for kind {kind!r}")
