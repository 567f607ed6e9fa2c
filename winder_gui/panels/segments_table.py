"""Numeric editor of a generatrix sketched from exact segments (``[mandrel] kind = "segments"``).

One row per segment (see :mod:`engine.sketch`): its type (line, arc, ellipse, isotensoid, spline,
smoothstep), the end point (z, r), the centre (arcs, ellipses), a radius (signed arc radius: > 0
convex, < 0 concave; the equator radius of a rising isotensoid dome), the pole radius of a falling
isotensoid dome, the ellipse's semi-axes, the spline's points, and whether the joint at the start of
the segment is a *corner* (not tangent) rounded by a *fillet* radius.  Joints are tangent (G1) by
default.  The start point of the sketch sits above the table.

Every change is checked at once for what the table can know (numbers, the fields a type needs); a
valid table is emitted as :attr:`SegmentsTable.segments_edited` (a
:class:`~engine.job.SegmentsSpec`); a bad cell turns red with the message as its tooltip, the first
message shows under the table and goes out as :attr:`SegmentsTable.problem`.  Geometric problems
found when the mandrel is built (a point not on its arc, a joint that is not tangent, a fillet that
does not fit) come back through :meth:`SegmentsTable.show_error`, which marks the segment's cell.

Typed values snap to :attr:`SegmentsTable.snap_mm` (0 = off) when it is set, so a sketch drawn on a
0.5 mm grid keeps its round numbers.
"""

from __future__ import annotations

import math
import re
from typing import Any

from pydantic import ValidationError
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from engine.job import SegmentsSpec
from winder_gui.i18n import QT_TR_NOOP, tr

TYPES = ("line", "arc", "ellipse", "isotensoid", "spline", "smoothstep")
COLUMNS = (QT_TR_NOOP("Type"), QT_TR_NOOP("End z"), QT_TR_NOOP("End r"), QT_TR_NOOP("Centre z"),
           QT_TR_NOOP("Centre r"), QT_TR_NOOP("Radius"), QT_TR_NOOP("Pole r"), QT_TR_NOOP("Semi-axes a, b"),
           QT_TR_NOOP("Spline points"),
           QT_TR_NOOP("Corner"), QT_TR_NOOP("Fillet"))
C_TYPE, C_Z, C_R, C_CZ, C_CR, C_RAD, C_POLE, C_AXES, C_PTS, C_CORNER, C_FILLET = range(len(COLUMNS))
FIELD_COLUMN = {"type": C_TYPE, "to_mm": C_Z, "center_mm": C_CZ, "radius_mm": C_RAD, "pole_radius_mm": C_POLE,
                "semi_axes_mm": C_AXES, "points_mm": C_PTS, "corner": C_CORNER, "fillet_mm": C_FILLET}
NEEDS = {"line": (C_Z, C_R), "smoothstep": (C_Z, C_R), "arc": (C_Z, C_R), "ellipse": (C_Z, C_R, C_CZ, C_CR, C_AXES),
         "isotensoid": (), "spline": (C_PTS,)}
USES = {"line": {C_Z, C_R}, "smoothstep": {C_Z, C_R}, "arc": {C_Z, C_R, C_CZ, C_CR, C_RAD},
        "ellipse": {C_Z, C_R, C_CZ, C_CR, C_AXES}, "isotensoid": {C_RAD, C_POLE}, "spline": {C_PTS}}
_BAD_BG = QBrush(QColor(255, 200, 200))
_OFF_BG = QBrush(QColor(236, 236, 236))
_OK_BG = QBrush()


def fmt(v: float) -> str:
    """A number for a cell: short, exact enough to round-trip typed values."""
    return format(float(v), ".10g")


def _num(text: str) -> float | str:
    t = text.strip().replace(",", ".")
    try:
        v = float(t)
    except ValueError:
        return f"not a number: {text.strip()!r}"
    return v if math.isfinite(v) else f"not a finite number: {text.strip()!r}"


def parse_pairs(text: str) -> list[list[float]] | str:
    """'z r; z r; …' (or 'z, r; …') into [[z, r], …], or the message why not."""
    out = []
    for part in [p for p in re.split(r"[;\n]", text) if p.strip()]:
        nums = [x for x in re.split(r"[\s,]+", part.strip()) if x]
        if len(nums) != 2:
            return f"each point is 'z r' (separated by ';'), got {part.strip()!r}"
        vals = [_num(x) for x in nums]
        if any(isinstance(v, str) for v in vals):
            return next(v for v in vals if isinstance(v, str))  # type: ignore[return-value]
        out.append([float(v) for v in vals])  # type: ignore[arg-type]
    return out or "at least one point 'z r' is required"


class SegmentsTable(QWidget):
    """The segment rows and the start point of a sketch; see the module docstring."""

    segments_edited = Signal(object)
    """A valid :class:`~engine.job.SegmentsSpec` typed by the user."""
    problem = Signal(str)
    """The first problem of the table ('' when it became valid)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._loading = False
        self.message = ""
        self.snap_mm = 0.0
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        start = QHBoxLayout()
        start.addWidget(QLabel(tr("Start z, r [mm]")))
        self.start_z = QLineEdit()
        self.start_r = QLineEdit()
        for ed, name in ((self.start_z, "start.z"), (self.start_r, "start.r")):
            ed.setObjectName(name)
            ed.setAlignment(Qt.AlignmentFlag.AlignRight)
            ed.textEdited.connect(lambda _t: self._changed())
            start.addWidget(ed)
        lay.addLayout(start)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setObjectName("segmentsTable")
        self.table.setHorizontalHeaderLabels([tr(c) for c in COLUMNS])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.itemChanged.connect(lambda _it: self._changed())
        lay.addWidget(self.table, 1)
        buttons = QHBoxLayout()
        self.add_button = QPushButton(tr("Add segment"))
        self.add_button.clicked.connect(self.add_row)
        self.delete_button = QPushButton(tr("Delete segment"))
        self.delete_button.clicked.connect(self.delete_row)
        buttons.addWidget(self.add_button)
        buttons.addWidget(self.delete_button)
        buttons.addStretch(1)
        lay.addLayout(buttons)
        self.info = QLabel("")
        self.info.setWordWrap(True)
        self.info.setStyleSheet("color: #c01010;")
        lay.addWidget(self.info)

    # -- public API ------------------------------------------------------------------------------
    def set_spec(self, spec: SegmentsSpec) -> None:
        """Show ``spec`` without emitting anything."""
        self._loading = True
        try:
            self.start_z.setText(fmt(spec.start_mm[0]))
            self.start_r.setText(fmt(spec.start_mm[1]))
            self.table.setRowCount(0)
            for sg in spec.segments:
                self._append(sg.model_dump(exclude_none=True))
            self._set_message("")
        finally:
            self._loading = False
        self._refresh_enabled()

    def add_row(self) -> None:
        """Append a line segment continuing the last one by 10 % of the sketch's length."""
        spec = self.spec()
        z, r = (spec.start_mm if spec is not None else (0.0, 10.0))
        if spec is not None:
            ends = [sg.to_mm for sg in spec.segments if sg.to_mm is not None]
            if ends:
                z, r = ends[-1]
        self._loading = True
        try:
            self._append({"type": "line", "to_mm": [float(z) + 10.0, float(r)]})
        finally:
            self._loading = False
        self._changed()

    def delete_row(self) -> None:
        """Remove the selected segment (one always stays)."""
        row = self.table.currentRow()
        if self.table.rowCount() > 1 and row >= 0:
            self.table.removeRow(row)
            self._changed()

    def set_type(self, row: int, kind: str) -> None:
        """Change the type of segment ``row`` as the user would (emits when the table is valid)."""
        combo = self.table.cellWidget(row, C_TYPE)
        assert isinstance(combo, QComboBox)
        combo.setCurrentText(kind)
        self._changed()

    def set_cell(self, row: int, col: int, text: str) -> None:
        """Type ``text`` into a cell (or tick the corner with "1"/"0") as the user would."""
        item = self.table.item(row, col)
        assert item is not None
        if col == C_CORNER:
            item.setCheckState(Qt.CheckState.Checked if text in ("1", "true", "yes") else Qt.CheckState.Unchecked)
        else:
            item.setText(text)

    def spec(self) -> SegmentsSpec | None:
        """The table as a spec, or None while it has a problem."""
        data, errs = self._read()
        if errs:
            return None
        try:
            return SegmentsSpec.model_validate(data)
        except ValidationError:
            return None

    def show_error(self, field: str, message: str) -> bool:
        """Mark the cell of ``segments[i].name`` (as the engine names it) with ``message``; False if unknown."""
        m = re.search(r"segments\[(\d+)\](?:\.(\w+))?", field or "")
        if not m:
            if "start_mm" in (field or ""):
                self.start_z.setStyleSheet("background: #ffc8c8;")
                self.start_z.setToolTip(message)
                self._set_message(message)
                return True
            return False
        row, name = int(m.group(1)), m.group(2) or "type"
        if not 0 <= row < self.table.rowCount():
            return False
        col = FIELD_COLUMN.get(name, C_TYPE)
        item = self.table.item(row, col)
        if item is not None:
            blocked = self.table.blockSignals(True)  # marking a cell is not an edit
            try:
                item.setBackground(_BAD_BG)
                item.setToolTip(message)
            finally:
                self.table.blockSignals(blocked)
        self.table.selectRow(row)
        self._set_message(tr("segment {v0}: {v1}").format(v0=row + 1, v1=message.split(': ', 1)[-1]))
        return True

    # -- internals -------------------------------------------------------------------------------
    def _append(self, sg: dict[str, Any]) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        combo = QComboBox()
        combo.addItems(TYPES)
        combo.setCurrentText(sg.get("type", "line"))
        combo.currentTextChanged.connect(lambda _t: self._changed())
        self.table.setCellWidget(row, C_TYPE, combo)
        self.table.setItem(row, C_TYPE, QTableWidgetItem(""))

        def put(col: int, v: Any) -> None:
            self.table.setItem(row, col, QTableWidgetItem("" if v is None else fmt(v)))

        to = sg.get("to_mm")
        put(C_Z, to[0] if to else None)
        put(C_R, to[1] if to else None)
        c = sg.get("center_mm")
        put(C_CZ, c[0] if c else None)
        put(C_CR, c[1] if c else None)
        put(C_RAD, sg.get("radius_mm"))
        put(C_POLE, sg.get("pole_radius_mm"))
        ax = sg.get("semi_axes_mm")
        self.table.setItem(row, C_AXES, QTableWidgetItem(f"{fmt(ax[0])} {fmt(ax[1])}" if ax else ""))
        pts = sg.get("points_mm")
        self.table.setItem(row, C_PTS, QTableWidgetItem("; ".join(f"{fmt(a)} {fmt(b)}" for a, b in pts) if pts else ""))
        corner = QTableWidgetItem("")
        corner.setFlags(Qt.ItemFlag.ItemIsUserCheckable | Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsSelectable)
        corner.setCheckState(Qt.CheckState.Checked if sg.get("corner") else Qt.CheckState.Unchecked)
        self.table.setItem(row, C_CORNER, corner)
        put(C_FILLET, sg.get("fillet_mm"))

    def _type(self, row: int) -> str:
        combo = self.table.cellWidget(row, C_TYPE)
        return combo.currentText() if isinstance(combo, QComboBox) else "line"

    def _text(self, row: int, col: int) -> str:
        item = self.table.item(row, col)
        return item.text().strip() if item is not None else ""

    def _snap(self, v: float) -> float:
        g = self.snap_mm
        return round(v / g) * g if g > 0 else v

    def _read(self) -> tuple[dict[str, Any], dict[tuple[int, int], str]]:
        errs: dict[tuple[int, int], str] = {}
        start = []
        for k, ed in enumerate((self.start_z, self.start_r)):
            v = _num(ed.text())
            if isinstance(v, str):
                errs[(-1, k)] = f"start point: {v}"
                v = 0.0
            start.append(self._snap(v))
        segs = []
        for row in range(self.table.rowCount()):
            kind = self._type(row)
            sg: dict[str, Any] = {"type": kind}
            vals: dict[int, float] = {}
            for col in (C_Z, C_R, C_CZ, C_CR, C_RAD, C_POLE, C_FILLET):
                t = self._text(row, col)
                if not t:
                    continue
                if col not in USES[kind] and col != C_FILLET:
                    errs[(row, col)] = f"segment {row + 1}: {COLUMNS[col]} does not apply to a {kind}"
                    continue
                v = _num(t)
                if isinstance(v, str):
                    errs[(row, col)] = f"segment {row + 1}, {COLUMNS[col]}: {v}"
                    continue
                vals[col] = v if col in (C_RAD, C_POLE, C_FILLET) else self._snap(v)
            for col in NEEDS[kind]:
                if col in (C_AXES, C_PTS):
                    if not self._text(row, col):
                        errs[(row, col)] = f"segment {row + 1}: a {kind} needs {COLUMNS[col]}"
                elif col not in vals and (row, col) not in errs:
                    errs[(row, col)] = f"segment {row + 1}: a {kind} needs {COLUMNS[col]}"
            if C_Z in vals and C_R in vals:
                sg["to_mm"] = [vals[C_Z], vals[C_R]]
            if C_CZ in vals and C_CR in vals:
                sg["center_mm"] = [vals[C_CZ], vals[C_CR]]
            if C_RAD in vals:
                sg["radius_mm"] = vals[C_RAD]
            if C_POLE in vals:
                sg["pole_radius_mm"] = vals[C_POLE]
            if kind == "isotensoid" and (C_RAD in vals) == (C_POLE in vals):
                errs[(row, C_POLE)] = (f"segment {row + 1}: an isotensoid dome takes a Pole r (falling) or a Radius "
                                       "(rising), one of them")
            if kind == "ellipse" and self._text(row, C_AXES):
                ax = [x for x in re.split(r"[\s,;]+", self._text(row, C_AXES)) if x]
                nums = [_num(x) for x in ax]
                if len(nums) != 2 or any(isinstance(v, str) for v in nums):
                    errs[(row, C_AXES)] = f"segment {row + 1}: semi-axes are two numbers 'a b' (mm)"
                else:
                    sg["semi_axes_mm"] = [float(v) for v in nums]  # type: ignore[arg-type]
            if kind == "spline" and self._text(row, C_PTS):
                pts = parse_pairs(self._text(row, C_PTS))
                if isinstance(pts, str):
                    errs[(row, C_PTS)] = f"segment {row + 1}: {pts}"
                else:
                    sg["points_mm"] = [[self._snap(a), self._snap(b)] for a, b in pts]
            corner = self.table.item(row, C_CORNER)
            if corner is not None and corner.checkState() == Qt.CheckState.Checked:
                sg["corner"] = True
            if C_FILLET in vals:
                sg["fillet_mm"] = vals[C_FILLET]
            segs.append(sg)
        if not segs:
            errs[(-1, 2)] = "a sketch needs at least one segment"
        return {"kind": "segments", "start_mm": start, "segments": segs}, errs

    def _refresh_enabled(self) -> None:
        """Grey the cells a row's type does not use."""
        blocked = self.table.blockSignals(True)
        try:
            for row in range(self.table.rowCount()):
                uses = USES[self._type(row)] | {C_CORNER, C_FILLET}
                for col in range(1, len(COLUMNS)):
                    item = self.table.item(row, col)
                    if item is not None and item.background() != _BAD_BG:
                        item.setBackground(_OK_BG if col in uses else _OFF_BG)
        finally:
            self.table.blockSignals(blocked)

    def _set_message(self, text: str) -> None:
        self.message = text
        self.info.setText(text)
        self.info.setVisible(bool(text))

    def _changed(self) -> None:
        if self._loading:
            return
        data, errs = self._read()
        blocked = self.table.blockSignals(True)
        try:
            for row in range(self.table.rowCount()):
                for col in range(1, len(COLUMNS)):
                    item = self.table.item(row, col)
                    if item is not None:
                        item.setBackground(_OK_BG)
                        item.setToolTip(errs.get((row, col), ""))
                        if (row, col) in errs:
                            item.setBackground(_BAD_BG)
        finally:
            self.table.blockSignals(blocked)
        self._refresh_enabled()
        for k, ed in enumerate((self.start_z, self.start_r)):
            ed.setStyleSheet("background: #ffc8c8;" if (-1, k) in errs else "")
        if errs:
            msg = next(iter(errs.values()))
            self._set_message(msg)
            self.problem.emit(msg)
            return
        try:
            spec = SegmentsSpec.model_validate(data)
        except ValidationError as exc:
            e = exc.errors()[0]
            msg = f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
            self._set_message(msg)
            self.problem.emit(msg)
            return
        self._set_message("")
        self.problem.emit("")
        self.segments_edited.emit(spec)


def segment_handles(spec: SegmentsSpec) -> tuple[list[float], list[float], list[int]]:
    """The points of a sketch that can be dragged on the r(z) plot: the start point (owner −1) and the
    end point of every segment that has one (owner = its index); z, r in mm."""
    z, r, owners = [float(spec.start_mm[0])], [float(spec.start_mm[1])], [-1]
    for i, sg in enumerate(spec.segments):
        if sg.to_mm is not None:
            z.append(float(sg.to_mm[0]))
            r.append(float(sg.to_mm[1]))
            owners.append(i)
    return z, r, owners


def apply_handles(spec: SegmentsSpec, z: Any, r: Any) -> SegmentsSpec:
    """``spec`` with its handles (:func:`segment_handles`) moved to (z, r) mm; same number of handles."""
    _, _, owners = segment_handles(spec)
    if len(z) != len(owners) or len(r) != len(owners):
        raise ValueError("add or remove segments in the table (points of a sketch of segments are its joints)")
    data = spec.model_dump(exclude_none=True)
    for k, i in enumerate(owners):
        if i < 0:
            data["start_mm"] = [float(z[k]), float(r[k])]
        else:
            data["segments"][i]["to_mm"] = [float(z[k]), float(r[k])]
    return SegmentsSpec.model_validate(data)
