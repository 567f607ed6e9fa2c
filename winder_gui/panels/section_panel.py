"""Properties pages for the job sections edited as plain fields: winding (+ band), payout, time law, post.

A page is a list of :class:`Field` rows; every label carries its unit (mm, deg, s, …).  Each
keystroke is checked at once: the fields are read, merged into the current job's sections and the
result validated by the job model itself (:meth:`engine.job.Job.replace`), so the panel has no rules
of its own.  A bad value shows a red message right under its field and nothing is emitted; a valid
set is emitted as a whole new job (:attr:`SectionPanel.job_edited`).  :meth:`SectionPanel.errors`
lists the problems shown (the window disables Run with the reason).

Degrees stay degrees: the job stores angles in degrees where the field name says ``_deg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QComboBox, QFormLayout, QGroupBox, QLabel, QLineEdit, QVBoxLayout, QWidget

from engine.job import Job
from winder_gui.i18n import QT_TR_NOOP, tr


def fmt(v: Any) -> str:
    """A value for a text field ('' for None)."""
    if v is None:
        return ""
    if isinstance(v, float):
        return format(v, ".10g")
    return str(v)


@dataclass(frozen=True)
class Field:
    """One editable value of a job section.

    ``kind``: ``float``, ``int``, ``str``, ``choice`` (``choices``), ``angles`` (``z:β, …`` list of
    required winding angles).  ``index`` selects a member of a pair field (e.g. ``dwell_deg``);
    ``optional`` fields may be left blank (the engine default applies).
    """

    section: str
    key: str
    label: str
    kind: str = "float"
    index: int | None = None
    optional: bool = False
    choices: tuple[str, ...] = ()
    tip: str = ""
    group: str = ""

    @property
    def name(self) -> str:
        return f"{self.section}.{self.key}" + (f".{self.index}" if self.index is not None else "")


@dataclass
class _Row:
    spec: Field
    editor: QLineEdit | QComboBox
    error: QLabel
    extra: dict[str, Any] = field(default_factory=dict)


def _parse_angles(text: str) -> list[dict[str, float]]:
    out = []
    for part in text.replace(";", ",").split(","):
        part = part.strip()
        if not part:
            continue
        if ":" not in part:
            raise ValueError(f"write each requirement as z:angle, got {part!r}")
        z, a = part.split(":", 1)
        out.append({"z_mm": float(z), "angle_deg": float(a)})
    return out


def _fmt_angles(items: Any) -> str:
    return ", ".join(f"{fmt(float(a['z_mm']))}:{fmt(float(a['angle_deg']))}" for a in items or ())


class SectionPanel(QWidget):
    """Fields of one or more job sections.

    Signals
    -------
    job_edited(Job):
        A valid job with the values typed by the user.
    validity_changed(str):
        ``""`` when every field is valid, else the first problem (``"<label>: <message>"``).
    """

    job_edited = Signal(object)
    validity_changed = Signal(str)

    def __init__(self, title: str, fields: tuple[Field, ...], parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.job: Job | None = None
        self.rows: dict[str, _Row] = {}
        self._loading = False
        self._problem = ""
        self.lay = QVBoxLayout(self)
        self.lay.setContentsMargins(6, 6, 6, 6)
        self.lay.addWidget(QLabel(f"<b>{title}</b>"))  # title: translated by the caller
        forms: dict[str, QFormLayout] = {}
        for f in fields:
            g = f.group or QT_TR_NOOP("Parameters")
            if g not in forms:
                box = QGroupBox(tr(g))
                form = QFormLayout(box)
                form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
                form.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapLongRows)
                forms[g] = form
                self.lay.addWidget(box)
            self._add_row(forms[g], f)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.status.setStyleSheet("color: #c01010;")
        self.lay.addWidget(self.status)

    def finish(self) -> None:
        """Close the layout (subclasses add their widgets first)."""
        self.lay.addStretch(1)

    def _add_row(self, form: QFormLayout, f: Field) -> None:
        editor: QLineEdit | QComboBox
        if f.kind == "choice":
            editor = QComboBox()
            editor.addItems(list(f.choices))
            editor.activated.connect(lambda _i: self._on_edited())
        else:
            editor = QLineEdit()
            if f.kind in ("float", "int"):
                editor.setAlignment(Qt.AlignmentFlag.AlignRight)
            if f.optional:
                editor.setPlaceholderText(tr("default"))
            editor.textEdited.connect(lambda _t: self._on_edited())
        editor.setObjectName(f.name)
        editor.setMinimumWidth(90)
        if f.tip:
            editor.setToolTip(tr(f.tip))
        err = QLabel("")
        err.setObjectName(f"error.{f.name}")
        err.setStyleSheet("color: #c01010; font-size: 9pt; padding-left: 12px;")
        err.setWordWrap(True)
        err.hide()
        form.addRow(tr(f.label), editor)
        form.addRow(err)
        self.rows[f.name] = _Row(f, editor, err)

    # -- public API ------------------------------------------------------------------------------
    def set_job(self, job: Job) -> None:
        """Show ``job``'s values without emitting anything."""
        self.job = job
        self._loading = True
        try:
            data = job.model_dump(mode="python")
            for row in self.rows.values():
                f = row.spec
                v = data[f.section].get(f.key)
                if f.index is not None and v is not None:
                    v = v[f.index]
                if f.kind == "choice":
                    assert isinstance(row.editor, QComboBox)
                    row.editor.setCurrentText(str(v) if v is not None else "")
                elif f.kind == "angles":
                    row.editor.setText(_fmt_angles(v))
                else:
                    row.editor.setText(fmt(v))
            self.load_extra(job)
            self.clear_errors()
        finally:
            self._loading = False
        self._set_problem("")

    def load_extra(self, job: Job) -> None:
        """Subclasses: show values that are not plain fields."""

    def editor(self, name: str) -> QLineEdit | QComboBox:
        """The editor of field ``name`` (``"<section>.<key>[.<index>]"``)."""
        return self.rows[name].editor

    def error_text(self, name: str) -> str:
        """The inline message under field ``name`` ('' when none is shown)."""
        row = self.rows[name]
        return row.error.text() if not row.error.isHidden() else ""

    def set_value(self, name: str, value: Any) -> None:
        """Type ``value`` into field ``name`` as a user would (emits when the job stays valid)."""
        ed = self.editor(name)
        if isinstance(ed, QComboBox):
            ed.setCurrentText(str(value))
        else:
            ed.setText(fmt(value) if not isinstance(value, str) else value)
        self._on_edited()

    def errors(self) -> str:
        """The first problem shown ('' when none)."""
        return self._problem

    def clear_errors(self) -> None:
        for row in self.rows.values():
            row.error.hide()
            row.error.setText("")
        self.status.setText("")

    def show_error(self, field_name: str | None, message: str) -> bool:
        """Show an engine error at its field (``"section.key"``); True if this panel has that field."""
        name = field_name or ""
        cands = [n for n in self.rows if n == name or n.startswith(name + ".")] if name else []
        if not cands:
            sec = name.split(".")[0]
            if not any(r.spec.section == sec for r in self.rows.values()):
                return False
            self.status.setText(message)
            return True
        row = self.rows[cands[0]]
        row.error.setText(message)
        row.error.show()
        return True

    # -- internals -------------------------------------------------------------------------------
    def extra_changes(self, sections: dict[str, dict[str, Any]], errs: dict[str, str]) -> None:
        """Subclasses: put values that are not plain fields into ``sections`` (or messages into ``errs``)."""

    def _read(self) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
        assert self.job is not None
        data = self.job.model_dump(mode="python")
        sections: dict[str, dict[str, Any]] = {}
        errs: dict[str, str] = {}
        pairs: dict[tuple[str, str], list[Any]] = {}
        for name, row in self.rows.items():
            f = row.spec
            sec = sections.setdefault(f.section, dict(data[f.section]))
            ed = row.editor
            if isinstance(ed, QComboBox):
                v: Any = ed.currentText()
                if f.key == "impregnation_k":
                    v = int(v)
            else:
                text = ed.text().strip()
                if f.kind == "str":
                    v = text
                elif f.kind == "angles":
                    try:
                        v = _parse_angles(text)
                    except ValueError as exc:
                        errs[name] = str(exc).replace("could not convert string to float", "not a number")
                        continue
                elif not text:
                    if f.optional:
                        v = None
                    else:
                        errs[name] = "a value is required"
                        continue
                else:
                    try:
                        num = float(text.replace(",", "."))
                    except ValueError:
                        errs[name] = f"not a number: {text!r}"
                        continue
                    if not math.isfinite(num):
                        errs[name] = f"not a finite number: {text!r}"
                        continue
                    if f.kind == "int":
                        if num != int(num):
                            errs[name] = f"must be a whole number, got {text!r}"
                            continue
                        num = int(num)
                    v = num
            if f.index is not None:
                cur = sec.get(f.key)
                lst = pairs.setdefault((f.section, f.key), list(cur) if cur is not None else [None, None])
                lst[f.index] = v
                sec[f.key] = lst
            else:
                sec[f.key] = v
        for (secname, key), lst in pairs.items():
            if all(x is None for x in lst):
                sections[secname][key] = None
            elif any(x is None for x in lst):
                name = next(r for r in self.rows.values() if r.spec.section == secname and r.spec.key == key
                            and lst[r.spec.index or 0] is None).spec.name
                errs[name] = "give both values or leave both blank"
            else:
                sections[secname][key] = tuple(lst)
        self.extra_changes(sections, errs)
        return sections, errs

    def _on_edited(self) -> None:
        if self._loading or self.job is None:
            return
        self.clear_errors()
        sections, errs = self._read()
        if not errs:
            try:
                job = self.job.replace(**sections)
            except ValidationError as exc:
                for e in exc.errors():
                    errs[self._field_of(e["loc"])] = e["msg"].removeprefix("Value error, ")
            else:
                self._set_problem("")
                self.job = job
                self.job_edited.emit(job)
                return
        for name, msg in errs.items():
            if name in self.rows:
                self.rows[name].error.setText(msg)
                self.rows[name].error.show()
            else:
                self.status.setText(msg)
        name, msg = next(iter(errs.items()))
        label = self.rows[name].spec.label if name in self.rows else name
        self._set_problem(f"{label}: {msg}")

    def _field_of(self, loc: tuple[Any, ...]) -> str:
        parts = [str(p) for p in loc if not (isinstance(p, str) and p.startswith(("tuple[", "function-")))]
        for n in range(len(parts), 0, -1):
            cand = ".".join(parts[:n])
            if cand in self.rows:
                return cand
            hits = [k for k in self.rows if k.startswith(cand + ".")]
            if hits:
                return hits[0]
        return ".".join(parts)

    def _set_problem(self, problem: str) -> None:
        if problem != self._problem:
            self._problem = problem
            self.validity_changed.emit(problem)


# ------------------------------------------------------------------------------------------------
WINDING_FIELDS: tuple[Field, ...] = (
    Field("band", "width_mm", QT_TR_NOOP("Band width [mm]"), group=QT_TR_NOOP("Band")),
    Field("band", "thickness_mm", QT_TR_NOOP("Band thickness [mm]"), group=QT_TR_NOOP("Band")),
    Field("band", "friction", QT_TR_NOOP("Friction μ [–]"), group=QT_TR_NOOP("Band"),
          tip=QT_TR_NOOP("band-on-mandrel friction: |λ| > μ slips")),
    Field("band", "material", QT_TR_NOOP("Material"), kind="str", group=QT_TR_NOOP("Band")),
    Field("winding", "mode", QT_TR_NOOP("Line"), kind="choice",
          choices=("auto", "geodesic", "constant-lambda", "piecewise-lambda",
                   "minimax"), group=QT_TR_NOOP("Winding line")),
    Field("winding", "angles", QT_TR_NOOP("Required angles z [mm] : β [deg]"), kind="angles",
          group=QT_TR_NOOP("Winding line"),
          tip=QT_TR_NOOP("e.g. 500:55, 200:40 — winding angle β (deg) required on the parallel at z (mm)")),
    Field("winding", "pole_c_mm", QT_TR_NOOP("Pole C left [mm]"), index=0, optional=True,
          group=QT_TR_NOOP("Winding line")),
    Field("winding", "pole_c_mm", QT_TR_NOOP("Pole C right [mm]"), index=1, optional=True,
          group=QT_TR_NOOP("Winding line")),
    Field("winding", "dwell_deg", QT_TR_NOOP("Dwell left [deg]"), index=0, group=QT_TR_NOOP("Winding line")),
    Field("winding", "dwell_deg", QT_TR_NOOP("Dwell right [deg]"), index=1, group=QT_TR_NOOP("Winding line")),
    Field("winding", "points_per_pass", QT_TR_NOOP("Points per pass [–]"), kind="int",
          group=QT_TR_NOOP("Winding line")),
    Field("winding", "circuits", QT_TR_NOOP("Circuits [–]"), kind="int", optional=True, group=QT_TR_NOOP("Pattern")),
    Field("winding", "pattern_p", QT_TR_NOOP("Pattern p [–]"), kind="int", optional=True, group=QT_TR_NOOP("Pattern")),
    Field("winding", "pattern_q", QT_TR_NOOP("Pattern q [–]"), kind="int", optional=True, group=QT_TR_NOOP("Pattern")),
    Field("winding", "layers", QT_TR_NOOP("Layers [–]"), kind="int", group=QT_TR_NOOP("Pattern")),
    Field("winding", "lead", QT_TR_NOOP("Lead"), kind="choice", choices=("leading", "lagging"),
          group=QT_TR_NOOP("Pattern")),
    Field("winding", "close_by", QT_TR_NOOP("Close pattern by"), kind="choice", choices=("dwell", "angle"),
          group=QT_TR_NOOP("Pattern")),
)

PAYOUT_FIELDS: tuple[Field, ...] = (
    Field("payout", "law", QT_TR_NOOP("Law"), kind="choice",
          choices=("parallel", "equidistant", "equal-tangent", "curve", "min-range")),
    Field("payout", "impregnation_k", QT_TR_NOOP("Impregnation scheme k [–]"), kind="choice", choices=("0", "1")),
    Field("payout", "parameter", QT_TR_NOOP("Process parameter x"), kind="choice", choices=("s", "v"),
          tip=QT_TR_NOOP("s: laid length (mm), v: mandrel twist (rad)")),
    Field("payout", "clearance_mm", QT_TR_NOOP("Clearance [mm]")),
    Field("payout", "eye_radius_mm", QT_TR_NOOP("Eye radius (parallel) [mm]"), optional=True),
    Field("payout", "offset_mm", QT_TR_NOOP("Offset (equidistant) [mm]"), optional=True),
    Field("payout", "free_length_mm", QT_TR_NOOP("Free length (eq.-tangent) [mm]"), optional=True),
    Field("payout", "free_length_max_mm", QT_TR_NOOP("Max free length [mm]")),
    Field("payout", "grid_points", QT_TR_NOOP("Grid points [–]"), kind="int"),
    Field("payout", "u_min", QT_TR_NOOP("u min [– or mm/rad]")),
)

TIMELAW_FIELDS: tuple[Field, ...] = (
    Field("timelaw", QT_TR_NOOP("method"), QT_TR_NOOP("Method (blocks: (17)/(18))"), kind="choice", choices=("blocks",
                                                                                                             "tube",
                                                                                                 "dp", "toppra")),
    Field("timelaw", "levels", QT_TR_NOOP("DP levels [–]"), kind="int"),
    Field("timelaw", "penalty", QT_TR_NOOP("Penalty weight [–]")),
    Field("timelaw", "tube_share", QT_TR_NOOP("Tube share [–]")),
    Field("timelaw", "stop_percent", QT_TR_NOOP("Stop when gain below [%]")),
    Field("timelaw", "sweep", QT_TR_NOOP("Final sweep"), kind="choice", choices=("True", "False"),
          tip=QT_TR_NOOP("True: after the tube, the fastest law within the limits where it is faster (up to a few "
                         "% shorter programs); False: the tube's own, smoother law")),
    Field("timelaw", "sdot_max", QT_TR_NOOP("Path speed limit ṡ max [mm/s]"), optional=True),
    Field("timelaw", "sddot_max", QT_TR_NOOP("Path acceleration limit [mm/s²]"), optional=True),
)


def winding_panel() -> SectionPanel:
    p = SectionPanel(tr("Winding"), WINDING_FIELDS)
    p.finish()
    return p


def payout_panel() -> SectionPanel:
    p = SectionPanel(tr("Payout eye"), PAYOUT_FIELDS)
    p.finish()
    return p
