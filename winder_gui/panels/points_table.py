"""Numeric entry table of a sketched generatrix: one row per point, columns z [mm] and r [mm].

The table is the numeric twin of the editable points on the r(z) plot.  Every change (a typed
cell, an added/inserted/deleted row, a pasted block) is checked at once:

- a cell that is not a number, an r < 0 (or r = 0 except at the two end points: a closed pole),
  a z that is not after the z of the row above, or fewer than 4 rows is an error;
- a bad cell turns red with the message as its tooltip, the first message shows in red under
  the table and is emitted as :attr:`PointsTable.problem`; nothing is emitted as an edit, so the
  job never receives it;
- a valid table is emitted as :attr:`PointsTable.points_edited` (z, r arrays in mm).

Pasting (Ctrl+V or the Paste button) takes a block of numbers from the clipboard separated by
tabs, semicolons, commas or spaces (e.g. copied from a spreadsheet); a first line that is not
numeric (a header such as ``z,r``) is skipped.  Two or more columns fill z and r of rows from the
current row on (rows are appended as needed); one column fills the current column only.
"""

from __future__ import annotations

import math
import re

import numpy as np
from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QGuiApplication, QKeyEvent, QKeySequence
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QSizePolicy,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from engine.mandrel import MIN_SKETCH_POINTS
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.views.geometry import FloatArray

MIN_POINTS = MIN_SKETCH_POINTS
"""A C2 spline through the points needs at least this many (as :func:`winder_gui.views.geometry.check_points`)."""
COLUMNS = (QT_TR_NOOP("z [mm]"), QT_TR_NOOP("r [mm]"))
_EXACT = Qt.ItemDataRole.UserRole
_CONCAVE_FG = QBrush(QColor(200, 30, 30))
_BAD_BG = QBrush(QColor(255, 200, 200))
_OK_BG = QBrush()


SHOWN_DECIMALS = 4
"""Decimals shown in a cell (0.1 µm); a cell the user did not retype keeps the job's exact value."""


def fmt(v: float) -> str:
    """A number for a cell or a message: at most :data:`SHOWN_DECIMALS` decimals, no trailing zeros."""
    t = f"{float(v):.{SHOWN_DECIMALS}f}".rstrip("0").rstrip(".")
    return "0" if t in ("-0", "") else t


def parse_number(text: str) -> float | str:
    """The value of a cell (a decimal comma is accepted), or the message why it is not a number."""
    t = text.strip()
    if not t:
        return "a value is required"
    try:
        v = float(t.replace(",", "."))
    except ValueError:
        return f"not a number: {t!r}"
    if not math.isfinite(v):
        return f"not a finite number: {t!r}"
    return v


def parse_block(text: str) -> list[list[str]]:
    """Split pasted text into rows of fields (tab, semicolon, comma or blank separated).

    Lines with tabs or semicolons are split on those only, so a decimal comma survives
    (``12,5<TAB>80``); so are lines with both blanks and commas (``12,5 80``: blank separated,
    decimal commas); other lines are split on commas or blanks.  Empty lines are dropped; the first
    line is dropped as a header (``z,r``, ``z [mm]<TAB>r [mm]``) only when none of its fields is a
    number, so a mistyped first data row stays and is reported in its cell.
    """
    rows: list[list[str]] = []
    for line in text.replace("\r\n", "\n").replace("\r", "\n").split("\n"):
        if not line.strip():
            continue
        if "\t" in line or ";" in line:
            fields = [f.strip() for f in re.split(r"[\t;]", line)]
        elif "," in line and re.search(r"\S\s+\S", line.replace(", ", ",")):
            fields = line.split()
        else:
            fields = [f for f in re.split(r"[,\s]+", line.strip())]
        rows.append([f for f in fields if f != ""])
    if rows and all(isinstance(parse_number(f), str) for f in rows[0]):
        rows = rows[1:]
    return [r for r in rows if r]


Problems = dict[tuple[int, int], str]


def check_table(cells: list[tuple[str, str]]) -> tuple[FloatArray | None, FloatArray | None, Problems]:
    """Values and per-cell problems of the table ``cells`` (rows of (z text, r text)).

    Returns ``(z, r, problems)``; z and r (mm) are ``None`` unless every cell is a number.  Keys of
    ``problems`` are (row, column) with column 0 = z, 1 = r; a problem of the whole table (too few
    rows) is keyed (-1, -1).
    """
    n = len(cells)
    probs: dict[tuple[int, int], str] = {}
    vals: list[list[float | None]] = []
    for i, row in enumerate(cells):
        pair: list[float | None] = []
        for j, text in enumerate(row):
            v = parse_number(text)
            if isinstance(v, str):
                probs[(i, j)] = v
                pair.append(None)
            else:
                pair.append(v)
        vals.append(pair)
    for i in range(n):
        zi, ri = vals[i]
        if ri is not None and (ri < 0 or (ri <= 0 and i not in (0, n - 1))):
            probs[(i, 1)] = (
                f"r must be > 0 (0 only at an end point: a closed pole), got {fmt(ri)} mm"
            )
        if i > 0 and zi is not None:
            prev = next((vals[k][0] for k in range(i - 1, -1, -1) if vals[k][0] is not None), None)
            if prev is not None and not zi > prev:
                probs[(i, 0)] = f"z must increase down the table: {fmt(zi)} mm is not after {fmt(prev)} mm"
    if n < MIN_POINTS:
        probs[(-1, -1)] = f"a sketched generatrix needs at least {MIN_POINTS} points (the table has {n})"
    if any(v is None for pair in vals for v in pair):
        return None, None, probs
    z = np.array([p[0] for p in vals], dtype=float)
    r = np.array([p[1] for p in vals], dtype=float)
    return z, r, probs


class PointsTable(QWidget):
    """Editable table of the sketch points (z, r in mm) with Add / Insert / Delete / Paste.

    Signals
    -------
    points_edited(z, r):
        The table changed and is valid (mm arrays); the caller applies it to the job.
    problem(str):
        The first problem of the table ("" when it is valid again).
    row_selected(int):
        The current row (-1: none); lets the plot highlight the same point.
    """

    points_edited = Signal(object, object)
    problem = Signal(str)
    row_selected = Signal(int)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._loading = False
        self.message = ""
        self.problems: dict[tuple[int, int], str] = {}
        self._last: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())
        self.concave: tuple[tuple[float, float], ...] = ()
        """Concave zones (z_from, z_to) in mm of the built mandrel; their rows are marked."""

        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(3)
        self.table = QTableWidget(0, 2)
        self.table.setObjectName("pointsTable")
        self.table.setHorizontalHeaderLabels([tr(c) for c in COLUMNS])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.table.verticalHeader().setDefaultSectionSize(22)
        self.table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Fixed)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectItems)
        self.table.setEditTriggers(
            QAbstractItemView.EditTrigger.DoubleClicked
            | QAbstractItemView.EditTrigger.EditKeyPressed
            | QAbstractItemView.EditTrigger.AnyKeyPressed
        )
        self.table.setMinimumHeight(200)
        self.table.setToolTip(
            tr("Type a value and press Enter · Delete removes the selected rows · "
            "Ctrl+V pastes numbers copied from a spreadsheet")
        )
        lay.addWidget(self.table, 1)

        buttons = QHBoxLayout()
        buttons.setSpacing(3)
        self.add_button = QPushButton(tr("Add"))
        self.add_button.setToolTip(tr("Append a point after the last one"))
        self.insert_button = QPushButton(tr("Insert"))
        self.insert_button.setToolTip(tr("Insert a point midway between the current row and the next"))
        self.delete_button = QPushButton(tr("Delete"))
        self.delete_button.setToolTip(tr("Delete the selected rows (Delete key)"))
        self.paste_button = QPushButton(tr("Paste"))
        self.paste_button.setToolTip(tr("Paste rows of z, r from the clipboard (tab, comma or space separated)"))
        for b in (self.add_button, self.insert_button, self.delete_button, self.paste_button):
            b.setAutoDefault(False)
            b.setMinimumWidth(40)
            b.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Fixed)
            buttons.addWidget(b)
        lay.addLayout(buttons)

        self.message_label = QLabel("")
        self.message_label.setObjectName("pointsTableMessage")
        self.message_label.setWordWrap(True)
        self.message_label.setStyleSheet("color: #c01010;")
        self.message_label.hide()
        lay.addWidget(self.message_label)

        self.add_button.clicked.connect(lambda: self.add_row())
        self.insert_button.clicked.connect(lambda: self.insert_row())
        self.delete_button.clicked.connect(lambda: self.delete_rows())
        self.paste_button.clicked.connect(lambda: self.paste())
        self.table.itemChanged.connect(self._on_item_changed)
        self.table.currentCellChanged.connect(lambda row, _c, _pr, _pc: self._on_current(row))
        self.table.installEventFilter(self)

    # -- data ------------------------------------------------------------------------------------
    def set_points(self, z: FloatArray | list[float], r: FloatArray | list[float]) -> None:
        """Show the job's points (mm) without emitting an edit; clears any problem."""
        self._fill([(repr(float(a)), repr(float(b))) for a, b in zip(z, r, strict=True)])
        self._last = (tuple(float(v) for v in z), tuple(float(v) for v in r))
        self._check(emit=False)

    def show_points(self, z: FloatArray, r: FloatArray) -> None:
        """Follow a drag on the plot live (no emit); ignored while a cell is being edited or rows differ."""
        if self.table.state() == QAbstractItemView.State.EditingState or len(z) != self.table.rowCount():
            return
        self._loading = True
        try:
            for i, (a, b) in enumerate(zip(z, r, strict=True)):
                for j, v in ((0, a), (1, b)):
                    it = self.table.item(i, j)
                    if it is not None:
                        self._set_text(it, repr(float(v)))
        finally:
            self._loading = False

    def cells(self) -> list[tuple[str, str]]:
        """The text of every row as (z, r); a cell still showing a job value gives it exactly (repr)."""
        out = []
        for i in range(self.table.rowCount()):
            pair = []
            for j in range(2):
                it = self.table.item(i, j)
                text = it.text() if it is not None else ""
                exact = it.data(_EXACT) if it is not None else None
                pair.append(repr(float(exact)) if isinstance(exact, float) and text == fmt(exact) else text)
            out.append((pair[0], pair[1]))
        return out

    def values(self) -> tuple[FloatArray, FloatArray] | None:
        """The points (mm) if the table is valid, else ``None``."""
        z, r, probs = check_table(self.cells())
        return None if probs or z is None or r is None else (z, r)

    def set_concave(self, zones: tuple[tuple[float, float], ...] | list[tuple[float, float]]) -> None:
        """Mark the rows whose z lies in a concave zone (r'' > 0) of the built mandrel (mm)."""
        self.concave = tuple((float(a), float(b)) for a, b in zones)
        self._mark_concave()

    def concave_rows(self) -> list[int]:
        """Rows (0-based) marked as lying in a concave zone."""
        z, _ = self._numbers(self.cells())
        return [i for i, v in enumerate(z) if any(a <= v <= b for a, b in self.concave)]

    def cell_problem(self, row: int, col: int) -> str:
        """The message of a bad cell ("" when the cell is fine)."""
        return self.problems.get((row, col), "")

    # -- edits (buttons, keys and tests) ---------------------------------------------------------
    def set_cell(self, row: int, col: int, text: str) -> None:
        """Type ``text`` into cell (row, col) as a user would (checks and emits)."""
        it = self.table.item(row, col)
        if it is None:
            it = self._item("")
            self.table.setItem(row, col, it)
        it.setText(text)  # itemChanged -> check

    def add_row(self) -> None:
        """Append a point beyond the last one (same step in z, same r)."""
        cells = self.cells()
        z, r = self._numbers(cells)
        n = len(cells)
        if n >= 2 and not math.isnan(z[-1]) and not math.isnan(z[-2]):
            new = (fmt(z[-1] + (z[-1] - z[-2])), cells[-1][1])
        elif n >= 1:
            new = (fmt(z[-1] + 10.0) if not math.isnan(z[-1]) else "", cells[-1][1])
        else:
            new = ("0", "50")
        self._fill([*cells, new])
        self.table.setCurrentCell(n, 0)
        self._check()

    def insert_row(self, row: int | None = None) -> None:
        """Insert a point midway between ``row`` (default: current) and the next one."""
        cells = self.cells()
        n = len(cells)
        if n < 2:
            self.add_row()
            return
        k = self.table.currentRow() if row is None else row
        k = min(max(k, 0), n - 2)
        z, r = self._numbers(cells)
        mid = tuple("" if math.isnan(a) or math.isnan(b) else fmt(0.5 * (a + b))
                    for a, b in ((z[k], z[k + 1]), (r[k], r[k + 1])))
        self._fill([*cells[: k + 1], (mid[0], mid[1]), *cells[k + 1:]])
        self.table.setCurrentCell(k + 1, 0)
        self._check()

    def delete_rows(self, rows: list[int] | None = None) -> None:
        """Delete ``rows`` (default: the rows of the selected cells).

        Fewer than 4 points left is refused with a message (the rows stay).
        """
        if rows is None:
            rows = sorted({ix.row() for ix in self.table.selectedIndexes()})
            if not rows and self.table.currentRow() >= 0:
                rows = [self.table.currentRow()]
        cells = self.cells()
        rows = sorted({i for i in rows if 0 <= i < len(cells)})
        if not rows:
            return
        left = len(cells) - len(rows)
        if left < MIN_POINTS:
            self._show_message(
                tr("Not applied: a sketched generatrix needs at least {MIN_POINTS} points (deleting "
                   "{v1} row{v2} would leave {left})")
                .format(MIN_POINTS=MIN_POINTS, v1=len(rows), v2='s' if len(rows) > 1 else '', left=left)
            )
            return
        keep = [c for i, c in enumerate(cells) if i not in set(rows)]
        self._fill(keep)
        self.table.setCurrentCell(min(rows[0], len(keep) - 1), 0)
        self._check()

    def paste(self, text: str | None = None, row: int | None = None, col: int | None = None) -> int:
        """Fill rows from pasted ``text`` (default: the clipboard) from ``row``/``col`` (default: current).

        Returns the number of rows filled.
        """
        if text is None:
            text = QGuiApplication.clipboard().text()
        block = parse_block(text or "")
        if not block:
            self._show_message(tr("Nothing to paste: the clipboard holds no numbers"))
            return 0
        cells = [list(c) for c in self.cells()]
        r0 = self.table.currentRow() if row is None else row
        c0 = self.table.currentColumn() if col is None else col
        r0, c0 = max(r0, 0), max(c0, 0)
        wide = max(len(b) for b in block) >= 2
        for k, fields in enumerate(block):
            i = r0 + k
            while i >= len(cells):
                cells.append(["", ""])
            if wide:
                cells[i][0] = fields[0]
                cells[i][1] = fields[1] if len(fields) > 1 else cells[i][1]
            else:
                cells[i][c0] = fields[0]
        self._fill([(a, b) for a, b in cells])
        self.table.setCurrentCell(r0, 0 if wide else c0)
        self._check()
        return len(block)

    def copy(self) -> str:
        """Copy the selected rows (all rows if none) to the clipboard as tab-separated text."""
        rows = sorted({ix.row() for ix in self.table.selectedIndexes()}) or list(range(self.table.rowCount()))
        cells = self.cells()
        text = "\n".join(f"{cells[i][0]}\t{cells[i][1]}" for i in rows) + "\n"
        QGuiApplication.clipboard().setText(text)
        return text

    def select_row(self, i: int) -> None:
        """Make row ``i`` current (from a click on the plot); -1 clears the selection."""
        if 0 <= i < self.table.rowCount():
            if self.table.currentRow() != i:
                self.table.blockSignals(True)
                self.table.setCurrentCell(i, 0)
                self.table.blockSignals(False)
                self.table.selectRow(i)
            self.table.scrollToItem(self.table.item(i, 0))
        else:
            self.table.clearSelection()

    # -- internals -------------------------------------------------------------------------------
    @staticmethod
    def _numbers(cells: list[tuple[str, str]]) -> tuple[list[float], list[float]]:
        def num(t: str) -> float:
            v = parse_number(t)
            return math.nan if isinstance(v, str) else v

        return [num(a) for a, _ in cells], [num(b) for _, b in cells]

    @staticmethod
    def _item(text: str) -> QTableWidgetItem:
        it = QTableWidgetItem(text)
        it.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        return it

    @staticmethod
    def _set_text(it: QTableWidgetItem, text: str) -> None:
        """Show ``text``; a number keeps its exact value behind its rounded display."""
        v = parse_number(text)
        if isinstance(v, float):
            it.setData(_EXACT, v)
            shown = fmt(v)
        else:
            it.setData(_EXACT, None)
            shown = text
        if it.text() != shown:
            it.setText(shown)

    def _mark_concave(self) -> None:
        z, _ = self._numbers(self.cells())
        for i in range(self.table.rowCount()):
            h = self.table.verticalHeaderItem(i)
            if h is None:
                h = QTableWidgetItem()
                self.table.setVerticalHeaderItem(i, h)
            zone = next(((a, b) for a, b in self.concave if a <= z[i] <= b), None)
            h.setText(f"{i + 1} ◐" if zone else str(i + 1))
            h.setForeground(_CONCAVE_FG if zone else QBrush())
            h.setToolTip(
                tr("In a concave zone (r'' > 0) from z {v0} to {v1} mm: the fibre bridges here "
                   "unless friction holds it").format(v0=fmt(zone[0]), v1=fmt(zone[1])) if zone else ""
            )

    def _fill(self, cells: list[tuple[str, str]]) -> None:
        self._loading = True
        try:
            self.table.setRowCount(len(cells))
            for i, (a, b) in enumerate(cells):
                for j, t in ((0, a), (1, b)):
                    it = self.table.item(i, j)
                    if it is None:
                        it = self._item("")
                        self.table.setItem(i, j, it)
                    self._set_text(it, t)
        finally:
            self._loading = False

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        if self._loading:
            return
        self._loading = True
        try:
            self._set_text(item, item.text())  # the typed value becomes the cell's exact value
        finally:
            self._loading = False
        self._check()

    def _on_current(self, row: int) -> None:
        if not self._loading:
            self.row_selected.emit(row)

    def _show_message(self, msg: str) -> None:
        self.message_label.setText(msg)
        self.message_label.setVisible(bool(msg))

    def _check(self, emit: bool = True) -> None:
        """Mark bad cells, show the first problem; emit a valid, changed table."""
        z, r, probs = check_table(self.cells())
        self.problems = probs
        self._loading = True
        try:
            for i in range(self.table.rowCount()):
                for j in range(2):
                    it = self.table.item(i, j)
                    if it is None:
                        continue
                    msg = probs.get((i, j), "")
                    it.setBackground(_BAD_BG if msg else _OK_BG)
                    it.setToolTip(msg)
        finally:
            self._loading = False
        self._mark_concave()
        if probs:
            (i, j), first = min(probs.items())  # (-1, -1) (too few rows) first, then top to bottom
            where = "" if i < 0 else f"row {i + 1}, {'zr'[j]}: "
            more = len(probs) - 1
            msg = f"{where}{first}" + (f" (and {more} more red cell{'s' if more > 1 else ''})" if more else "")
        else:
            msg = ""
        self._show_message(msg)
        if msg != self.message:
            self.message = msg
            self.problem.emit(msg)
        if not msg and emit and z is not None and r is not None:
            new = (tuple(float(v) for v in z), tuple(float(v) for v in r))
            if new != self._last:
                self._last = new
                self.points_edited.emit(z, r)

    def eventFilter(self, obj: QObject, ev: QEvent) -> bool:  # noqa: N802 - Qt override
        if obj is self.table and ev.type() == QEvent.Type.KeyPress and isinstance(ev, QKeyEvent):
            if self.table.state() != QAbstractItemView.State.EditingState:
                if ev.matches(QKeySequence.StandardKey.Paste):
                    self.paste()
                    return True
                if ev.matches(QKeySequence.StandardKey.Copy):
                    self.copy()
                    return True
                if ev.key() in (Qt.Key.Key_Delete, Qt.Key.Key_Backspace):
                    self.delete_rows()
                    return True
        return super().eventFilter(obj, ev)
