"""The r(z) plot of the generatrix with editable points, and the r''(z) plot with concave zones.

Editing (on the r(z) plot):

- drag a point to move it;
- double-click on empty plot space to add a point (inserted in order of z);
- right-click a point, or select it (click) and press Delete, to remove it.

Snap (the "Snap" toggle and its grid step in mm above the plot, kept in the settings): a dragged
or added point lands on the grid, and its r snaps to the r of a neighbouring point within a few
pixels (to draw cylindrical stretches).  z never snaps to another point's z: z must increase strictly.

Every edit is checked at once (:func:`winder_gui.views.geometry.check_points`); an invalid
point is drawn red with the message above the plot and the edit is *not* emitted, so the job
never receives it.  Valid edits are emitted as :attr:`ProfilePlot.points_edited` (z, r arrays).
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, Qt, Signal
from PySide6.QtGui import QKeySequence, QShortcut
from PySide6.QtWidgets import QCheckBox, QDoubleSpinBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.views.geometry import FloatArray, MandrelViewData, check_points

_OK_BRUSH = pg.mkBrush(30, 100, 200, 230)
_TEMPLATE_BRUSH = pg.mkBrush(255, 255, 255, 230)
_SEL_BRUSH = pg.mkBrush(255, 170, 0, 255)
_BAD_BRUSH = pg.mkBrush(220, 30, 30, 255)
_CONCAVE_BRUSH = pg.mkBrush(230, 60, 60, 45)
SNAP_STEP_MM = 1.0
"""Default grid step of the snap (mm)."""
SNAP_PIXELS = 6.0
"""How close (screen pixels) r must come to a neighbour's r to take it."""
HINT = QT_TR_NOOP("Drag a point to move it · double-click to add one · right-click or Delete to remove it")


def snap_to_grid(v: float, step: float) -> float:
    """``v`` rounded to the nearest multiple of ``step`` (mm); exact decimal for decimal steps."""
    k = round(v / step)
    digits = max(0, -int(np.floor(np.log10(step))) + 6)
    return float(round(k * step, digits))


def check_joints(z: FloatArray, r: FloatArray) -> tuple[int, str] | None:
    """The first problem of moved joints of a sketch of segments (z increasing, r >= 0), or None."""
    for i in range(len(z)):
        if not (np.isfinite(z[i]) and np.isfinite(r[i])) or r[i] < 0:
            return i, f"joint {i + 1} must have a finite z and r >= 0"
    for i in range(1, len(z)):
        if not z[i] > z[i - 1]:
            return i, (f"z must increase along the axis: joint {i + 1} at z = {z[i]:.4g} mm is not after "
                       f"{z[i - 1]:.4g} mm")
    return None


class PointEditor(pg.ScatterPlotItem):
    """Draggable, addable, deletable generatrix points (mm) on a pyqtgraph plot.

    Signals
    -------
    edited(z, r):
        A valid edit finished (arrays in mm).
    problem(str):
        Message of the edit in progress; ``""`` when the points are valid again.
    selected(int):
        Index of the point clicked last (-1: none).
    """

    edited = Signal(object, object)
    problem = Signal(str)
    selected = Signal(int)
    moving = Signal(object, object)
    """The drawn points changed (z, r mm), also during a drag and for edits that are not applied."""

    def __init__(self) -> None:
        super().__init__(size=11, pen=pg.mkPen(20, 60, 140, width=1.5), hoverable=True, hoverSize=14)
        self._z: FloatArray = np.zeros(0)
        self._r: FloatArray = np.zeros(0)
        self._work_z: FloatArray = self._z
        self._work_r: FloatArray = self._r
        self._bad: int | None = None
        self._drag: int | None = None
        self._drag_offset = QPointF(0.0, 0.0)
        self.selected_index = -1
        self.sketch = True
        """False while the points only sample a template (dragging one converts it to a sketch)."""
        self.message = ""
        self.snap_step = 0.0
        """Grid step of the snap in mm; 0 = snap off."""
        self.segment_mode = False
        """True while the points are the joints of a sketch of segments: they move, but are neither added
        nor removed here (that is a segment of the table), and 2 or 3 of them are enough."""

    # -- data ------------------------------------------------------------------------------------
    def set_points(self, z: FloatArray, r: FloatArray, sketch: bool) -> None:
        """Show committed points (mm); ``sketch`` marks them as the job's own points."""
        self._z = np.array(z, dtype=float)
        self._r = np.array(r, dtype=float)
        self._work_z, self._work_r = self._z.copy(), self._r.copy()
        self.sketch = sketch
        self._bad = None
        self._drag = None
        if self.selected_index >= len(self._z):
            self.selected_index = -1
        self._set_message("")
        self._redraw()

    def current_points(self) -> tuple[FloatArray, FloatArray]:
        """The points as drawn now (mm), including an edit in progress."""
        return self._work_z.copy(), self._work_r.copy()

    def committed_points(self) -> tuple[FloatArray, FloatArray]:
        """The last points set from the job (mm)."""
        return self._z.copy(), self._r.copy()

    def _redraw(self) -> None:
        base = _OK_BRUSH if self.sketch else _TEMPLATE_BRUSH
        brushes = [base] * len(self._work_z)
        if 0 <= self.selected_index < len(brushes):
            brushes[self.selected_index] = _SEL_BRUSH
        if self._bad is not None and 0 <= self._bad < len(brushes):
            brushes[self._bad] = _BAD_BRUSH
        self.setData(x=self._work_z, y=self._work_r, brush=brushes, data=np.arange(len(self._work_z)))

    def _set_message(self, msg: str) -> None:
        if msg != self.message:
            self.message = msg
            self.problem.emit(msg)

    # -- snap --------------------------------------------------------------------------------------
    def snap(self, z: float, r: float, neighbours: tuple[int, ...] = ()) -> tuple[float, float]:
        """(z, r) mm as the snap places them: on the grid, r on a neighbour's r when within a few pixels.

        Returns (z, r) unchanged when the snap is off.  ``neighbours`` are indices of committed points.
        """
        if self.snap_step <= 0.0:
            return z, r
        zs, rs = snap_to_grid(z, self.snap_step), snap_to_grid(r, self.snap_step)
        vb = self.getViewBox()
        px = vb.viewPixelSize()[1] if vb is not None else 0.0
        best = SNAP_PIXELS * px
        for j in neighbours:
            if 0 <= j < len(self._r) and abs(self._r[j] - r) <= best:
                best, rs = abs(self._r[j] - r), float(self._r[j])
        return zs, rs

    # -- edits (used by the mouse handlers and by tests) ------------------------------------------
    def move_point(self, i: int, z: float, r: float, finish: bool = True) -> str | None:
        """Move point ``i`` to (z, r) mm (snapped when the snap is on); returns the problem message, or
        ``None`` if valid.

        With ``finish`` a valid edit is emitted and an invalid one reverted to the committed points.
        """
        z, r = self.snap(z, r, (i - 1, i + 1))
        wz, wr = self._z.copy(), self._r.copy()
        wz[i], wr[i] = z, r
        return self._try(wz, wr, finish, focus=i)

    def add_point(self, z: float, r: float) -> str | None:
        """Insert a point at (z, r) mm (snapped when the snap is on) in order of z."""
        if self.segment_mode:
            self._set_message(tr("Not applied: add segments in the table (the points are the joints of the segments)"))
            return self.message
        i = int(np.searchsorted(self._z, z))
        z, r = self.snap(z, r, (i - 1, i))
        i = int(np.searchsorted(self._z, z))
        return self._try(np.insert(self._z, i, z), np.insert(self._r, i, r), True, focus=i)

    def select(self, i: int) -> None:
        """Highlight point ``i`` (-1: none) without emitting."""
        i = i if 0 <= i < len(self._work_z) else -1
        if i != self.selected_index:
            self.selected_index = i
            self._redraw()

    def delete_point(self, i: int) -> str | None:
        """Remove point ``i``."""
        if not 0 <= i < len(self._z):
            return None
        if self.segment_mode:
            self._set_message(
                              tr("Not applied: delete segments in the table (the points are the "
                                 "joints of the segments)"))
            return self.message
        self.selected_index = -1
        return self._try(np.delete(self._z, i), np.delete(self._r, i), True, focus=None)

    def _try(self, wz: FloatArray, wr: FloatArray, finish: bool, focus: int | None) -> str | None:
        bad = check_joints(wz, wr) if self.segment_mode else check_points(wz, wr)
        self._work_z, self._work_r = wz, wr
        self._bad = bad[0] if bad else None
        msg = bad[1] if bad else ""
        if finish:
            if bad is None:
                self._z, self._r = wz.copy(), wr.copy()
                if focus is not None:
                    self.selected_index = focus
                self._set_message("")
                self._redraw()
                self.edited.emit(wz.copy(), wr.copy())
                return None
            # not applied: show the committed points again, keep the message up
            self._work_z, self._work_r = self._z.copy(), self._r.copy()
            self._bad = None
            self._set_message("")
            self._set_message(tr("Not applied: {msg}").format(msg=msg))
            self._redraw()
            self.moving.emit(self._work_z.copy(), self._work_r.copy())
            return msg
        self._set_message(msg)
        self._redraw()
        self.moving.emit(wz.copy(), wr.copy())
        return msg or None

    # -- mouse -----------------------------------------------------------------------------------
    def _point_at(self, pos: QPointF) -> int | None:
        pts = self.pointsAt(pos)
        if len(pts) == 0:
            return None
        return int(pts[0].index())

    def mouseDragEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph override
        if ev.button() != Qt.MouseButton.LeftButton:
            ev.ignore()
            return
        if ev.isStart():
            i = self._point_at(ev.buttonDownPos())
            if i is None:
                ev.ignore()
                return
            self._drag = i
            self.selected_index = i
            self._drag_offset = QPointF(self._z[i], self._r[i]) - ev.buttonDownPos()
        elif self._drag is None:
            ev.ignore()
            return
        ev.accept()
        p = ev.pos() + self._drag_offset
        i = self._drag
        if ev.isFinish():
            self._drag = None
            self.move_point(i, p.x(), p.y(), finish=True)
        else:
            self.move_point(i, p.x(), p.y(), finish=False)

    def mouseClickEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph override
        i = self._point_at(ev.pos())
        if i is None:
            ev.ignore()
            return
        ev.accept()
        if ev.button() == Qt.MouseButton.RightButton:
            self.delete_point(i)
        elif ev.button() == Qt.MouseButton.LeftButton:
            self.selected_index = i
            self._redraw()
            self.selected.emit(i)


class ProfilePlot(QWidget):
    """r(z) with editable points above r''(z); concave zones (r'' > 0) shaded red in both.

    Signals
    -------
    points_edited(z, r):
        The user made a valid edit of the points (mm arrays).
    message(str):
        Validation message of the edit in progress ("" when valid).
    """

    points_edited = Signal(object, object)
    message = Signal(str)
    points_moving = Signal(object, object)
    """The drawn points (mm) changed, also during a drag (for a table that follows live)."""
    point_selected = Signal(int)
    """A point was clicked (its index)."""
    data_shown = Signal(object)
    """A mandrel's curves were shown (its :class:`MandrelViewData`)."""
    snap_changed = Signal(bool, float)
    """The snap was switched or its grid step (mm) changed."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.data: MandrelViewData | None = None
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.setSpacing(2)
        self.message_label = QLabel("")
        self.message_label.setStyleSheet("color: #c01010; font-weight: bold;")
        self.message_label.setWordWrap(True)
        self.message_label.hide()
        self.hint_label = QLabel(tr(HINT))
        self.hint_label.setStyleSheet("color: #666;")
        self.hint_label.setWordWrap(True)
        self.snap_check = QCheckBox(tr("Snap"))
        self.snap_check.setObjectName("snapToggle")
        self.snap_check.setToolTip(
            tr("Dragged and added points land on a grid of this step;\nr also snaps to a "
               "neighbouring point's r within {SNAP_PIXELS:.0f} pixels").format(SNAP_PIXELS=SNAP_PIXELS)
        )
        self.snap_spin = QDoubleSpinBox()
        self.snap_spin.setObjectName("snapStep")
        self.snap_spin.setDecimals(2)
        self.snap_spin.setRange(0.01, 1000.0)
        self.snap_spin.setSingleStep(0.5)
        self.snap_spin.setSuffix(tr(" mm"))
        self.snap_spin.setValue(SNAP_STEP_MM)
        self.snap_spin.setToolTip(tr("Grid step of the snap"))
        self.snap_spin.setKeyboardTracking(False)
        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(self.hint_label, 1)
        bar.addWidget(self.snap_check)
        bar.addWidget(self.snap_spin)
        lay.addLayout(bar)
        lay.addWidget(self.message_label)

        self.graphics = pg.GraphicsLayoutWidget()
        self.graphics.setBackground("w")
        self.graphics.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        lay.addWidget(self.graphics, 1)
        self.plot_r = self.graphics.addPlot(row=0, col=0)
        self.plot_d2 = self.graphics.addPlot(row=1, col=0)
        self.graphics.ci.layout.setRowStretchFactor(0, 3)
        self.graphics.ci.layout.setRowStretchFactor(1, 2)
        self.plot_d2.setXLink(self.plot_r)
        self.plot_r.setLabel("left", "r", units="mm")
        self.plot_d2.setLabel("left", "r''", units="1/mm")
        self.plot_d2.setLabel("bottom", "z", units="mm")
        for p in (self.plot_r, self.plot_d2):
            p.showGrid(x=True, y=True, alpha=0.25)
            p.setMenuEnabled(False)
            p.getAxis("left").setWidth(60)
            p.getAxis("left").enableAutoSIPrefix(False)
            p.getAxis("bottom").enableAutoSIPrefix(False)
        self.plot_r.setTitle(tr("Generatrix r(z)"), size="9pt")
        self.plot_d2.setTitle(tr("r''(z) — concave zones (r'' > 0) shaded"), size="9pt")
        self.curve_r = self.plot_r.plot(pen=pg.mkPen(20, 20, 20, width=2))
        self.curve_d2 = self.plot_d2.plot(pen=pg.mkPen(120, 40, 160, width=1.5))
        self.plot_d2.addItem(pg.InfiniteLine(pos=0.0, angle=0, pen=pg.mkPen(150, 150, 150, style=Qt.PenStyle.DashLine)))
        self.editor = PointEditor()
        self.editor.setZValue(10)
        self.plot_r.addItem(self.editor)
        self._regions: list[pg.LinearRegionItem] = []

        self.editor.edited.connect(self.points_edited)
        self.editor.problem.connect(self._on_problem)
        self.editor.moving.connect(self.points_moving)
        self.editor.selected.connect(self.point_selected)
        self._load_snap()
        self.snap_check.toggled.connect(lambda _on: self._on_snap_changed())
        self.snap_spin.valueChanged.connect(lambda _v: self._on_snap_changed())
        self.plot_r.scene().sigMouseClicked.connect(self._on_scene_click)
        for key in (QKeySequence.StandardKey.Delete, QKeySequence(Qt.Key.Key_Backspace)):
            sc = QShortcut(key, self.graphics)
            sc.setContext(Qt.ShortcutContext.WidgetWithChildrenShortcut)
            sc.activated.connect(self.delete_selected)

    # -- data ------------------------------------------------------------------------------------
    def set_data(self, data: MandrelViewData, sketch: bool, reset_view: bool = False) -> None:
        """Show a mandrel's curves and editable points; ``sketch``: points are the job's own."""
        self.data = data
        self.curve_r.setData(data.z, data.r)
        d2 = np.where(np.isfinite(data.d2r), data.d2r, np.nan)
        self.curve_d2.setData(data.z, d2, connect="finite")
        for reg in self._regions:
            reg.getViewBox().removeItem(reg) if reg.getViewBox() is not None else None
        self._regions.clear()
        for z0, z1 in data.concave:
            for p in (self.plot_r, self.plot_d2):
                reg = pg.LinearRegionItem((z0, z1), movable=False, brush=_CONCAVE_BRUSH, pen=pg.mkPen(None))
                reg.setZValue(-10)
                p.addItem(reg)
                self._regions.append(reg)
        self.editor.segment_mode = False
        self.editor.set_points(data.handle_z, data.handle_r, sketch)
        zmin, zmax, rmax = float(data.z[0]), float(data.z[-1]), float(np.max(data.r))
        (x0, x1), (y0, y1) = self.plot_r.getViewBox().viewRange()
        if reset_view or zmin < x0 or zmax > x1 or rmax > y1 or y0 > 0.0:
            pad = 0.04 * (zmax - zmin)
            self.plot_r.setXRange(zmin - pad, zmax + pad, padding=0)
            self.plot_r.setYRange(0.0, 1.12 * rmax, padding=0)
        # r'' is unbounded at a closed pole: scale to the bulk of the curve, always showing 0
        finite = d2[np.isfinite(d2)]
        lo, hi = (np.percentile(finite, [2.0, 98.0]) if finite.size else (0.0, 0.0))
        lo, hi = min(float(lo), 0.0), max(float(hi), 0.0)
        span = (hi - lo) or 1e-3
        self.plot_d2.setYRange(lo - 0.1 * span, hi + 0.1 * span, padding=0)
        self.data_shown.emit(data)

    def curve_data(self) -> tuple[FloatArray, FloatArray]:
        """The plotted r(z) curve (mm)."""
        x, y = self.curve_r.getData()
        return np.asarray(x), np.asarray(y)

    def set_segment_handles(self, z: FloatArray, r: FloatArray) -> None:
        """Make the joints (z, r mm) of a sketch of segments the editable points: they can be dragged
        (with the snap), not added or removed (see :func:`winder_gui.panels.segments_table.segment_handles`)."""
        self.editor.segment_mode = True
        self.editor.set_points(np.asarray(z, dtype=float), np.asarray(r, dtype=float), True)

    def revert_points(self) -> None:
        """Show the points of the current data again (after a rejected edit)."""
        if self.data is not None:
            self.editor.set_points(self.data.handle_z, self.data.handle_r, self.editor.sketch)

    def show_message(self, msg: str) -> None:
        """Show (or clear, with "") the red message above the plot."""
        self.message_label.setText(msg)
        self.message_label.setVisible(bool(msg))

    # -- snap --------------------------------------------------------------------------------------
    def set_snap(self, on: bool, step_mm: float | None = None) -> None:
        """Switch the snap and optionally set its grid step (mm), as the user would (persisted)."""
        if step_mm is not None:
            self.snap_spin.setValue(float(step_mm))
        self.snap_check.setChecked(bool(on))
        self._on_snap_changed()

    @property
    def snap_step(self) -> float:
        """The grid step in force (mm); 0 when the snap is off."""
        return self.editor.snap_step

    def _apply_snap(self) -> None:
        on = self.snap_check.isChecked()
        step = float(self.snap_spin.value())
        self.editor.snap_step = step if on else 0.0
        self.snap_spin.setEnabled(on)
        hint = tr(HINT)
        self.hint_label.setText(tr("{hint} · snap to a {step:g} mm grid").format(hint=hint, step=step) if on else hint)

    def _on_snap_changed(self) -> None:
        self._apply_snap()
        st = _settings()
        if st is not None:
            st.setValue("sketch/snap", self.snap_check.isChecked())
            st.setValue("sketch/snap_step_mm", float(self.snap_spin.value()))
        self.snap_changed.emit(self.snap_check.isChecked(), float(self.snap_spin.value()))

    def _load_snap(self) -> None:
        st = _settings()
        if st is not None:
            on = str(st.value("sketch/snap", False)).lower() in ("true", "1")
            try:
                step = float(st.value("sketch/snap_step_mm", SNAP_STEP_MM))
            except (TypeError, ValueError):
                step = SNAP_STEP_MM
            if not (np.isfinite(step) and step > 0.0):
                step = SNAP_STEP_MM
            for w in (self.snap_check, self.snap_spin):
                w.blockSignals(True)
            self.snap_spin.setValue(step)
            self.snap_check.setChecked(on)
            for w in (self.snap_check, self.snap_spin):
                w.blockSignals(False)
        self._apply_snap()

    # -- interaction -----------------------------------------------------------------------------
    def select_point(self, i: int) -> None:
        """Highlight point ``i`` (e.g. the current row of the points table); -1: none."""
        self.editor.select(i)

    def delete_selected(self) -> None:
        """Delete the selected point (Delete key)."""
        if self.editor.selected_index >= 0:
            self.editor.delete_point(self.editor.selected_index)

    def _on_problem(self, msg: str) -> None:
        self.show_message(msg)
        self.message.emit(msg)

    def _on_scene_click(self, ev) -> None:
        if not ev.double() or ev.button() != Qt.MouseButton.LeftButton:
            return
        vb = self.plot_r.getViewBox()
        if not vb.sceneBoundingRect().contains(ev.scenePos()):
            return
        if self.editor._point_at(self.editor.mapFromScene(ev.scenePos())) is not None:
            return
        p = vb.mapSceneToView(ev.scenePos())
        ev.accept()
        self.editor.add_point(p.x(), p.y())


def _settings():  # noqa: ANN202 - QSettings | None
    """The application's settings (:func:`winder_gui.settings.app_settings`)."""
    from winder_gui.settings import app_settings

    return app_settings()
