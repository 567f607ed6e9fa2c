"""Tools → Slot forming: the cycloidal slot-forming calculator (engine/slotting.py, MATH.md §D).

Inputs on the left (units in the labels), checked on every keystroke: a bad value shows an inline
message and disables Compute and Export.  Compute runs :func:`engine.slotting.slot_study` through a
:class:`winder_gui.workers.JobRunner` (the GUI thread never computes) and shows

* the table of ``A`` and ``j`` over the slot lengths (the paper's Tables 2/3), with the paper's
  printed closure and the bracketing solver's answer alongside;
* ``A(i)`` for several slot lengths across down-cut and up-cut (Fig. 4);
* the error history ``Δ(j)`` of the iteration for several ratios (Fig. 5);
* the path ``S`` of the forming point in the part's frame, with the bore circle and slot ends.

Export writes the table as CSV atomically (:func:`engine.slotting.write_table_csv`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QCoreApplication, QEventLoop, Qt, QThread, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QDialog,
    QFileDialog,
    QFormLayout,
    QGridLayout,
    QGroupBox,
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

from engine.errors import InputError
from engine.slotting import (
    SlotSetup,
    SlotStudy,
    cutting_mode,
    parse_range,
    reduced_parameters,
    slot_study,
    write_table_csv,
)
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.texts import CUT_MODE, CUT_MODE_SHORT
from winder_gui.workers import JobRunner

_ERR_STYLE = "color: #b00020;"
_NOTE_STYLE = "color: #555555;"
_MAX_CURVE_POINTS = 20000


@dataclass(frozen=True)
class SlotInputs:
    """A validated snapshot of the dialog's inputs (mm, rad-free: ratios and lengths)."""

    setup: SlotSetup
    lengths: np.ndarray
    curve_lengths: np.ndarray
    curve_ratios: np.ndarray
    history_ratios: np.ndarray
    focus_length: float


# (key, label with unit, default text, tooltip)
_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("rho", QT_TR_NOOP("Forming radius ρ, mm"), "22",
     QT_TR_NOOP("Radius at which the slot length is given, e.g. the tube bore R_d1.")),
    ("tool_radius", QT_TR_NOOP("Tool radius R_u, mm"), "-95",
     QT_TR_NOOP("Signed, as in the paper: negative = external scheme (tool outside), positive = internal.")),
    ("ratio", QT_TR_NOOP("Kinematic ratio i = ω_d/ω_u"), "-2",
     QT_TR_NOOP("Part over tool angular speed. i·R_u > 0 is down-cut, i·R_u < 0 up-cut, 0 a fixed part.")),
    ("lengths", QT_TR_NOOP("Slot lengths l, mm (from:to:step)"), "2:20:2",
     QT_TR_NOOP("FROM:TO:STEP, one value, or a list a, b, c.")),
    ("tol", QT_TR_NOOP("Admissible rel. error [Δ], –"), "0.005", QT_TR_NOOP("Stop test of the iteration: |Δ| ≤ [Δ].")),
    ("max_iter", QT_TR_NOOP("Iteration budget, –"), "100",
     QT_TR_NOOP("Steps before the iteration is declared non-convergent.")),
    ("part_radius", QT_TR_NOOP("Part radius R_d, mm (optional)"), "",
     QT_TR_NOOP("Nominal part radius for the reduced parameters of Table 1 and the outer circle of the path plot.")),
    ("curve_lengths", QT_TR_NOOP("Fig. 4: slot lengths l, mm"), "2, 5, 10, 15, 20",
     QT_TR_NOOP("One A(i) curve per length.")),
    ("curve_ratios", QT_TR_NOOP("Fig. 4: ratios i (from:to:step)"), "-4:4:0.1",
     QT_TR_NOOP("The i axis of the A(i) curves.")),
    ("history_ratios", QT_TR_NOOP("Fig. 5: ratios i"), "-3, -2, -1, 0, 1, 2, 3",
     QT_TR_NOOP("One Δ(j) history per ratio.")),
    ("focus_length", QT_TR_NOOP("Fig. 5 and path S: slot length l, mm"), "20",
     QT_TR_NOOP("Slot length of the histories and of S.")),
)

_COLUMNS = (QT_TR_NOOP("l, mm"), QT_TR_NOOP("A, mm"), QT_TR_NOOP("A (paper eq.), mm"),
            QT_TR_NOOP("A check (brentq), mm"), QT_TR_NOOP("θ, deg"), "j", QT_TR_NOOP("converged"),
            QT_TR_NOOP("method"), QT_TR_NOOP("note"))


def parse_inputs(texts: dict[str, str], a_formula: str = "exact") -> SlotInputs:
    """Turn the dialog's texts into :class:`SlotInputs`; raise :class:`InputError` naming the field.

    Parameters
    ----------
    texts:
        Field key → text, keys as in ``_FIELDS``.
    a_formula:
        ``"exact"`` or ``"paper"``.
    """

    def num(key: str, what: str) -> float:
        t = texts.get(key, "").strip()
        try:
            v = float(t)
        except ValueError:
            raise InputError(f"{what}: {t!r} is not a number", field=key) from None
        if not math.isfinite(v):
            raise InputError(f"{what}: {t!r} is not a finite number", field=key)
        return v

    rho = num("rho", "forming radius ρ")
    ru = num("tool_radius", "tool radius R_u")
    ratio = num("ratio", "kinematic ratio i")
    tol = num("tol", "admissible error [Δ]")
    mi = num("max_iter", "iteration budget")
    if mi != int(mi) or mi < 1 or mi > 100000:
        raise InputError(f"iteration budget must be a whole number 1…100000, got {texts['max_iter']!r}",
                         field="max_iter")
    pr_text = texts.get("part_radius", "").strip()
    part_radius = num("part_radius", "part radius R_d") if pr_text else None
    setup = SlotSetup(rho, ru, ratio, tol, part_radius, int(mi), a_formula).validated()  # type: ignore[arg-type]

    def lengths(key: str, what: str) -> np.ndarray:
        arr = parse_range(texts.get(key, ""), what, key)
        bad = arr[(arr <= 0) | (arr >= 2 * math.pi * rho)]
        if bad.size:
            raise InputError(
                f"{what} must lie in (0, 2πρ = {2 * math.pi * rho:.4g}) mm, got {bad[0]:g}", field=key
            )
        return arr

    ls = lengths("lengths", "slot length")
    cl = lengths("curve_lengths", "Fig. 4 slot length")
    cr = parse_range(texts.get("curve_ratios", ""), "Fig. 4 ratio", "curve_ratios")
    if cl.size * cr.size > _MAX_CURVE_POINTS:
        raise InputError(
            f"Fig. 4 has {cl.size} × {cr.size} points; at most {_MAX_CURVE_POINTS}", field="curve_ratios"
        )
    hr = parse_range(texts.get("history_ratios", ""), "Fig. 5 ratio", "history_ratios")
    if hr.size > 50:
        raise InputError(f"Fig. 5 shows at most 50 ratios, got {hr.size}", field="history_ratios")
    focus = lengths("focus_length", "slot length of Fig. 5 / path S")
    if focus.size != 1:
        raise InputError("give one slot length for Fig. 5 / path S", field="focus_length")
    return SlotInputs(setup, ls, cl, cr, hr, float(focus[0]))


class SlotDialog(QDialog):
    """The slot-forming calculator (Tools → Slot forming).

    Signals
    -------
    computed(SlotStudy):
        A computation finished and is shown.
    """

    computed = Signal(object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle(tr("Slot forming — cycloidal slotting with a rotating blade tool"))
        self.resize(1400, 860)
        self.study: SlotStudy | None = None
        self._inputs: SlotInputs | None = None
        self._stale = True
        self._runner = JobRunner(self)
        self._runner.finished.connect(self._on_finished)
        self._runner.failed.connect(self._on_failed)
        self._runner.busy.connect(self._on_busy)

        # ---- inputs ------------------------------------------------------------------------
        self.edits: dict[str, QLineEdit] = {}
        form = QFormLayout()
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        for key, label, default, tip in _FIELDS:
            ed = QLineEdit(default)
            ed.setObjectName(key)
            ed.setToolTip(tr(tip))
            ed.textChanged.connect(self._validate)
            ed.returnPressed.connect(self.compute)
            self.edits[key] = ed
            lab = QLabel(tr(label))
            lab.setToolTip(tr(tip))
            form.addRow(lab, ed)
        self.formula = QComboBox()
        self.formula.addItem(tr("exact triangle closure"), "exact")
        self.formula.addItem(tr("paper's printed equation"), "paper")
        self.formula.setToolTip(
            tr("Which closure is reported as A. The paper prints A = −R_u + √(ρ² − (R_u sin θ)²), which\n"
            "drops cos θ; the exact closure is A = ρ cos(φ + iθ) − R_u cos θ (see docs/slotting.md).")
        )
        self.formula.currentIndexChanged.connect(self._validate)
        form.addRow(QLabel(tr("A reported by")), self.formula)

        self.mode_label = QLabel()
        self.mode_label.setWordWrap(True)
        self.error_label = QLabel()
        self.error_label.setWordWrap(True)
        self.error_label.setStyleSheet(_ERR_STYLE)
        self.error_label.setVisible(False)
        self.status_label = QLabel()
        self.status_label.setWordWrap(True)
        self.status_label.setStyleSheet(_NOTE_STYLE)
        self.reduced_label = QLabel()
        self.reduced_label.setWordWrap(True)
        self.reduced_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        self.compute_button = QPushButton(tr("Compute"))
        self.compute_button.setDefault(True)
        self.compute_button.clicked.connect(self.compute)
        self.export_button = QPushButton(tr("Export table (CSV)…"))
        self.export_button.clicked.connect(lambda: self.export_csv())
        close = QPushButton(tr("Close"))
        close.clicked.connect(self.reject)
        buttons = QHBoxLayout()
        buttons.addWidget(self.compute_button)
        buttons.addWidget(self.export_button)
        buttons.addStretch(1)
        buttons.addWidget(close)

        left = QVBoxLayout()
        box = QGroupBox(tr("Set-up"))
        box.setLayout(form)
        left.addWidget(box)
        left.addWidget(self.mode_label)
        left.addWidget(self.error_label)
        left.addLayout(buttons)
        left.addWidget(self.status_label)
        rbox = QGroupBox(tr("Reduced parameters (Table 1)"))
        rl = QVBoxLayout(rbox)
        rl.addWidget(self.reduced_label)
        left.addWidget(rbox)
        left.addStretch(1)
        left_w = QWidget()
        left_w.setLayout(left)
        left_w.setFixedWidth(400)

        # ---- table and plots ---------------------------------------------------------------
        self.table = QTableWidget(0, len(_COLUMNS))
        self.table.setHorizontalHeaderLabels([tr(c) for c in _COLUMNS])
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.verticalHeader().setVisible(False)
        hh = self.table.horizontalHeader()
        hh.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        hh.setStretchLastSection(True)

        self.plot_ai = pg.PlotWidget()
        self.plot_ai.setBackground("w")
        self.plot_ai.setTitle(tr("Fig. 4 — centre distance A(i)"))
        self.plot_ai.setLabel("bottom", tr("kinematic ratio i = ω_d/ω_u"))
        self.plot_ai.setLabel("left", tr("A, mm"))
        self.plot_ai.showGrid(x=True, y=True, alpha=0.3)
        self.plot_ai.addLegend(offset=(-10, -10))

        self.plot_err = pg.PlotWidget()
        self.plot_err.setBackground("w")
        self.plot_err.setTitle(tr("Fig. 5 — relative error Δ(j) of the iteration"))
        self.plot_err.setLabel("bottom", tr("iteration j"))
        self.plot_err.setLabel("left", "Δ = (θ_j+1 − θ_j)/θ_j+1")
        self.plot_err.showGrid(x=True, y=True, alpha=0.3)
        self.plot_err.addLegend(offset=(-10, 10))

        self.plot_path = pg.PlotWidget()
        self.plot_path.setBackground("w")
        self.plot_path.setTitle(tr("Path S of the forming point in the part's frame"))
        self.plot_path.setLabel("bottom", tr("x, mm"))
        self.plot_path.setLabel("left", tr("y, mm"))
        self.plot_path.setAspectLocked(True)
        self.plot_path.showGrid(x=True, y=True, alpha=0.3)

        grid = QGridLayout()
        grid.addWidget(self._boxed(tr("Tables 2/3 — A and iterations j over the slot length"), self.table), 0, 0)
        grid.addWidget(self.plot_ai, 0, 1)
        grid.addWidget(self.plot_err, 1, 0)
        grid.addWidget(self.plot_path, 1, 1)
        grid.setColumnStretch(0, 1)
        grid.setColumnStretch(1, 1)
        right_w = QWidget()
        right_w.setLayout(grid)

        outer = QHBoxLayout(self)
        outer.addWidget(left_w)
        outer.addWidget(right_w, 1)

        self._validate()
        if self._inputs is not None:
            self.compute()

    # -- helpers -------------------------------------------------------------------------------
    @staticmethod
    def _boxed(title: str, w: QWidget) -> QGroupBox:
        box = QGroupBox(title)
        lay = QVBoxLayout(box)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(w)
        return box

    def texts(self) -> dict[str, str]:
        """The current input texts by field key."""
        return {k: e.text() for k, e in self.edits.items()}

    def set_inputs(self, **texts: str | float) -> None:
        """Set input fields by key (for scripting and tests), e.g. ``set_inputs(rho=22, ratio=-1)``."""
        for k, v in texts.items():
            if k == "a_formula":
                self.formula.setCurrentIndex(self.formula.findData(str(v)))
            else:
                self.edits[k].setText(str(v))

    # -- validation ------------------------------------------------------------------------------
    def _validate(self, *_: object) -> bool:
        for e in self.edits.values():
            e.setStyleSheet("")
        try:
            inputs = parse_inputs(self.texts(), str(self.formula.currentData()))
        except InputError as exc:
            self._inputs = None
            self.error_label.setText(exc.message)
            self.error_label.setVisible(True)
            field = exc.location.field
            if field in self.edits:
                self.edits[field].setStyleSheet("border: 1px solid #b00020;")
            self.mode_label.setText("")
            self._update_buttons()
            return False
        self._inputs = inputs
        self.error_label.setText("")
        self.error_label.setVisible(False)
        s = inputs.setup
        kia = abs(s.k * s.ratio)
        mode = cutting_mode(s.ratio, s.tool_radius)
        extra = {
            "down-cut": tr("{mode}: the error of the iteration decays monotonically").format(
                mode=tr(CUT_MODE["down-cut"])),
            "up-cut": tr("{mode}: the error of the iteration alternates in sign").format(mode=tr(CUT_MODE["up-cut"])),
            "fixed part": tr("fixed part (i = 0): the iteration ends at the first step"),
        }[mode]
        text = tr("{scheme} scheme; {extra}. |ρ·i/R_u| = {kia:.3g}").format(
            scheme=tr(s.scheme.capitalize()), extra=extra, kia=kia)
        if kia >= 1.0:
            text += tr(" ≥ 1: the iteration is not sure to converge — the bracketing solver takes over.")
        self.mode_label.setText(text)
        if self.study is not None:
            self._stale = True
            self.status_label.setText(tr("Inputs changed: press Compute to refresh the results."))
        self._update_buttons()
        return True

    def _update_buttons(self) -> None:
        ok = self._inputs is not None
        self.compute_button.setEnabled(ok)
        self.export_button.setEnabled(ok and self.study is not None and not self._stale)

    # -- computing ---------------------------------------------------------------------------------
    def compute(self) -> None:
        """Start the computation for the current inputs in a worker (no-op when they are invalid)."""
        if not self._validate() or self._inputs is None:
            return
        inp = self._inputs
        self.status_label.setText(tr("Computing…"))
        self._runner.submit(
            slot_study, inp.setup, inp.lengths, inp.curve_lengths, inp.curve_ratios, inp.history_ratios,
            inp.focus_length,
        )

    def is_busy(self) -> bool:
        """True while a computation is running."""
        return self._runner.is_busy()

    def wait_idle(self, timeout_ms: int = 10000) -> bool:
        """Process events until no computation is running (tests, scripting); False on timeout."""
        deadline = time.monotonic() + timeout_ms / 1000.0
        while self._runner.is_busy():
            if time.monotonic() > deadline:
                return False
            QCoreApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 20)
            QThread.msleep(2)
        QCoreApplication.processEvents()
        return True

    def _on_busy(self, busy: bool) -> None:
        self.compute_button.setText(tr("Computing…") if busy else tr("Compute"))

    def _on_failed(self, exc: object, tb: str) -> None:
        del tb  # the traceback is for a log, never the user message
        if isinstance(exc, InputError):
            msg = str(exc)
        else:
            msg = f"The computation failed unexpectedly ({type(exc).__name__}: {exc}). Please report this."
        self.error_label.setText(msg)
        self.error_label.setVisible(True)
        self.status_label.setText("")
        self._update_buttons()

    def _on_finished(self, study: object) -> None:
        assert isinstance(study, SlotStudy)
        self.study = study
        self._stale = False
        self._show_table(study)
        self._show_curves(study)
        self._show_histories(study)
        self._show_path(study)
        self._show_reduced(study)
        self._update_buttons()
        self.computed.emit(study)

    # -- display -----------------------------------------------------------------------------------
    def _show_table(self, study: SlotStudy) -> None:
        rows = study.table.rows
        self.table.setRowCount(len(rows))
        grey = QBrush(QColor(255, 235, 235))
        amber = QBrush(QColor(255, 248, 220))

        def f(v: float, p: int) -> str:
            return f"{v:.{p}f}" if math.isfinite(v) else "—"

        for n, r in enumerate(rows):
            cells = (
                f(r.l, 3), f(r.A, 4), f(r.A_paper, 4), f(r.A_check, 4), f(math.degrees(r.theta), 4),
                str(r.iterations), "yes" if r.converged else "no", r.method, r.message,
            )
            for c, text in enumerate(cells):
                item = QTableWidgetItem(text)
                if c < 6:
                    item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
                if r.message:
                    item.setToolTip(r.message)
                if not r.ok:
                    item.setBackground(grey)
                elif r.method == "fallback":
                    item.setBackground(amber)
                self.table.setItem(n, c, item)
        n_fb = sum(r.method == "fallback" for r in rows)
        n_none = sum(not r.ok for r in rows)
        n_dis = sum(r.method == "iteration" and not r.agrees for r in rows)
        parts = [tr("{n} rows computed.").format(n=len(rows))]
        if n_fb:
            parts.append(tr("{n} row(s): the iteration did not converge — A from the bracketing solver.")
                         .format(n=n_fb))
        if n_none:
            parts.append(tr("{n} row(s): the slot length cannot be reached (see the note).").format(n=n_none))
        if n_dis:
            parts.append(tr("{n} row(s): iteration and bracketing solver disagree (see the note).").format(n=n_dis))
        self.status_label.setText(" ".join(parts))
        self.status_label.setStyleSheet(_ERR_STYLE if (n_none or n_dis) else _NOTE_STYLE)

    def _show_curves(self, study: SlotStudy) -> None:
        p = self.plot_ai
        p.clear()
        c = study.curves
        n = len(c.lengths)
        for m, l in enumerate(c.lengths):
            pen = pg.mkPen(pg.intColor(m, hues=max(n, 1), values=1, maxValue=200), width=2)
            p.plot(c.ratios, c.A[m], pen=pen, name=tr("l = {l:g} mm").format(l=l), connect="finite")
            fb = c.method[m] == "fallback"
            if np.any(fb):
                p.plot(c.ratios[fb], c.A[m][fb], pen=None, symbol="x", symbolSize=6,
                       symbolPen=pen, symbolBrush=None)
        setup = study.table.setup
        p.addItem(pg.InfiniteLine(pos=0.0, angle=90, pen=pg.mkPen((120, 120, 120), style=Qt.PenStyle.DashLine)))
        # label the two sides of i = 0 (down-cut where i·R_u > 0), low in the plot where it is empty
        finite = c.A[np.isfinite(c.A)]
        if finite.size and c.ratios.size:
            bottom = float(finite.min())
            neg_label = "← down-cut" if setup.tool_radius < 0 else "← up-cut"
            pos_label = "up-cut →" if setup.tool_radius < 0 else "down-cut →"
            lo, hi = float(c.ratios.min()), float(c.ratios.max())
            for text, anchor, show in ((neg_label, (1, 1), lo < 0), (pos_label, (0, 1), hi > 0)):
                if show:
                    t = pg.TextItem(text, color=(80, 80, 80), anchor=anchor)
                    t.setPos(0.0, bottom)
                    p.addItem(t)

    def _show_histories(self, study: SlotStudy) -> None:
        p = self.plot_err
        p.clear()
        tol = study.table.setup.tol
        items = sorted(study.histories.items())
        n = len(items)
        for m, (ratio, it) in enumerate(items):
            d = it.error_history
            if d.size == 0:
                continue
            color = pg.intColor(m, hues=max(n, 1), values=1, maxValue=200)
            mode = cutting_mode(ratio, study.table.setup.tool_radius)
            tag = tr(CUT_MODE_SHORT[mode])
            conv = "" if it.converged else tr(" (no conv.)")
            dd = np.clip(d, -2.0, 2.0)  # keep a divergent history from flattening the others
            p.plot(np.arange(d.size), dd, pen=pg.mkPen(color, width=2), symbol="o", symbolSize=5,
                   symbolBrush=color, name=f"i = {ratio:g} {tag}{conv}")
        dash = pg.mkPen((176, 0, 32), style=Qt.PenStyle.DashLine)
        for y in (tol, -tol):
            p.addItem(pg.InfiniteLine(pos=y, angle=0, pen=dash))

    def _show_path(self, study: SlotStudy) -> None:
        p = self.plot_path
        p.clear()
        s = study.table.setup
        t = np.linspace(0.0, 2.0 * math.pi, 361)
        p.plot(s.rho * np.cos(t), s.rho * np.sin(t), pen=pg.mkPen((90, 90, 90), width=1.5,
                                                                    style=Qt.PenStyle.DashLine))
        if s.part_radius is not None:
            p.plot(s.part_radius * np.cos(t), s.part_radius * np.sin(t), pen=pg.mkPen((150, 150, 150), width=1))
        traj, row = study.trajectory, study.trajectory_row
        focus = study.history_length
        if traj is None or row is None:
            p.setTitle(tr("Path S: slot length {focus:g} mm cannot be reached").format(focus=focus))
            p.autoRange()
            return
        p.plot(traj.x, traj.y, pen=pg.mkPen((0, 90, 200), width=2))
        h = traj.slot_half_angle
        if math.isfinite(h):
            ends_x = s.rho * np.cos([-h, h])
            ends_y = s.rho * np.sin([-h, h])
            p.plot(ends_x, ends_y, pen=None, symbol="o", symbolSize=8, symbolBrush=(200, 30, 30))
            arc = np.linspace(-h, h, 120)
            p.plot(s.rho * np.cos(arc), s.rho * np.sin(arc), pen=pg.mkPen((200, 30, 30), width=3))
        p.setTitle(tr("Path S (part frame): A = {A:.3f} mm → slot {slot_length:.3f} mm")
                   .format(A=row.A, slot_length=traj.slot_length))
        p.autoRange()

    def _show_reduced(self, study: SlotStudy) -> None:
        red = reduced_parameters(study.table.setup)
        rd = "ρ" if study.table.setup.part_radius is None else f"{study.table.setup.part_radius:g} mm"
        i_text = "—" if red.I is None else f"{red.I:.5g}"
        self.reduced_label.setText(
            tr("R_d = {rd}\ni1 = R_u/R_d = {i1:.5g}\nÃ = A/R_d = 1 − i1 = {A_tilde_nominal:.5g} "
               "(nominal)\ni = ω_d/ω_u = {i:g}\nI = V_u/V_d = i1/i = {i_text}\nρ̃ = ρ/R_d = "
               "{rho_tilde:.5g}")
            .format(rd=rd, i1=red.i1, A_tilde_nominal=red.A_tilde_nominal, i=red.i, i_text=i_text,
                    rho_tilde=red.rho_tilde)
        )

    # -- export --------------------------------------------------------------------------------------
    def export_csv(self, path: str | None = None) -> bool:
        """Write the shown table as CSV (atomic); ask for a file name when ``path`` is None."""
        if self.study is None or self._stale:
            return False
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self, tr("Export slot table"), "slot_table.csv", tr("CSV (*.csv)"))
            if not path:
                return False
        try:
            out = write_table_csv(path, self.study.table)
        except InputError as exc:
            self.error_label.setText(str(exc))
            self.error_label.setVisible(True)
            return False
        self.status_label.setText(tr("Table written to {out}").format(out=out))
        return True

    # -- shutdown ------------------------------------------------------------------------------------
    def done(self, result: int) -> None:  # noqa: D102 - Qt override
        self._runner.cancel()
        self._runner.wait(5000)
        super().done(result)

    def closeEvent(self, event) -> None:  # noqa: N802, ANN001, D102 - Qt override
        self._runner.cancel()
        self._runner.wait(5000)
        super().closeEvent(event)


__all__ = ["SlotDialog", "SlotInputs", "parse_inputs"]
