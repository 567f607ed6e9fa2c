"""Tools → Turning optimiser: spindle speed and feed for one-pass turning (engine/turning.py, MATH.md §C).

Inputs on the left (units in every label), the report and the constraint table in the middle, and
the feasible region in the (n, S) plane on log axes on the right: every constraint a labelled,
coloured line (in log-log coordinates every row ``n^a S^b <= c`` is straight), the feasible region
shaded, the objective line ``n S = const`` through the optimum, the optimum marked (and the best pair
of the machine's discrete series when *Snap* is on) — the paper's Fig. 2, but for any set-up.

Every edit is validated at once (a bad value gets an inline message next to its field, nothing
runs); valid edits are debounced and computed by :func:`engine.turning.optimise_with_plot` through a
:class:`winder_gui.workers.JobRunner`, so the GUI thread never computes.  An infeasible set-up shows
the conflicting constraints instead of a result.

Expert mode edits the LP rows ``a x1 + b x2 <= rhs`` (x1 = ln n, x2 = ln S) directly, as in the
paper's Mathcad sheet; *Rows → expert* copies the current physical rows there.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QDialog,
    QFormLayout,
    QGraphicsPolygonItem,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QScrollArea,
    QSplitter,
    QTableWidget,
    QVBoxLayout,
    QWidget,
)

from engine.errors import InputError
from engine.turning import (
    CONSTRAINT_NAMES,
    CuttingData,
    TurningCase,
    case_from_dict,
    example_case_path,
    load_case,
    load_data,
    optimise_with_plot,
)
from winder_gui.dialogs.turning_views import COLOURS, TurningViewsMixin, _fmt  # noqa: F401 - COLOURS: API
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.workers import JobRunner

_ERR_STYLE = "color: #b00020;"
_DEBOUNCE_MS = 150

# (section, key, label with unit, tooltip)
_NUM_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("machine", "n_min_rpm", QT_TR_NOOP("n min, rpm"), QT_TR_NOOP("Lowest spindle speed, constraint (12).")),
    ("machine", "n_max_rpm", QT_TR_NOOP("n max, rpm"), QT_TR_NOOP("Highest spindle speed, constraint (13).")),
    ("machine", "s_min_mm_rev", QT_TR_NOOP("S min, mm/rev"), QT_TR_NOOP("Smallest feed, constraint (10).")),
    ("machine", "s_max_mm_rev", QT_TR_NOOP("S max, mm/rev"), QT_TR_NOOP("Largest feed, constraint (11).")),
    ("machine", "power_kw", QT_TR_NOOP("Drive power N, kW"), QT_TR_NOOP("Main drive power, constraint (4).")),
    ("machine", "efficiency", QT_TR_NOOP("Efficiency η, –"), QT_TR_NOOP("Drive efficiency, constraint (4).")),
    ("machine", "feed_force_max_n", QT_TR_NOOP("Max feed force, N"),
     QT_TR_NOOP("Strength of the weakest feed-mechanism link, (5).")),
    ("workpiece", "hb", QT_TR_NOOP("Hardness, HB"), QT_TR_NOOP("Brinell hardness (K_mv, K_mp of cast irons).")),
    ("workpiece", "sigma_b_mpa", QT_TR_NOOP("Tensile strength σ_b, MPa"), QT_TR_NOOP("K_mv, K_mp of steels.")),
    ("workpiece", "diameter_mm", QT_TR_NOOP("Diameter D, mm"), QT_TR_NOOP("Workpiece diameter before the pass.")),
    ("workpiece", "depth_mm", QT_TR_NOOP("Depth of cut t, mm"), QT_TR_NOOP("One pass removes the whole allowance.")),
    ("workpiece", "length_mm", QT_TR_NOOP("Part length L, mm"), QT_TR_NOOP("Span for the deflection check (9).")),
    ("workpiece", "machined_length_mm", QT_TR_NOOP("Machined length l, mm"),
     QT_TR_NOOP("Path length of the pass: t_m = l/(n S).")),
    ("workpiece", "tolerance_mm", QT_TR_NOOP("Diameter tolerance, mm"), QT_TR_NOOP("E.g. IT11 at 83 mm = 0.22 mm.")),
    ("workpiece", "deflection_share", QT_TR_NOOP("Deflection share of tolerance, –"),
     QT_TR_NOOP("Admissible part deflection = share × tolerance, (9).")),
    ("tool", "tool_life_min", QT_TR_NOOP("Tool life T, min"),
     QT_TR_NOOP("Economic tool life in the Taylor constraint (3).")),
    ("tool", "phi_deg", QT_TR_NOOP("Approach angle φ, deg"),
     QT_TR_NOOP("Main cutting-edge angle (K_φv, K_φp, insert (7)).")),
    ("tool", "phi1_deg", QT_TR_NOOP("Minor angle φ1, deg"),
     QT_TR_NOOP("Minor cutting-edge angle (empirical roughness).")),
    ("tool", "gamma_deg", QT_TR_NOOP("Rake angle γ, deg"), QT_TR_NOOP("K_γp.")),
    ("tool", "lambda_deg", QT_TR_NOOP("Inclination λ, deg"), QT_TR_NOOP("K_λp.")),
    ("tool", "nose_radius_mm", QT_TR_NOOP("Nose radius r, mm"), QT_TR_NOOP("Roughness (8).")),
    ("tool", "insert_thickness_mm", QT_TR_NOOP("Insert thickness c, mm"), QT_TR_NOOP("Insert strength (7).")),
    ("tool", "holder_b_mm", QT_TR_NOOP("Holder width B, mm"), QT_TR_NOOP("Holder strength (6).")),
    ("tool", "holder_h_mm", QT_TR_NOOP("Holder height H, mm"), QT_TR_NOOP("Holder strength (6).")),
    ("tool", "holder_overhang_mm", QT_TR_NOOP("Holder overhang, mm"), QT_TR_NOOP("Holder strength (6).")),
    ("tool", "holder_stress_mpa", QT_TR_NOOP("Holder stress [σ], MPa"),
     QT_TR_NOOP("Admissible bending stress of the shank (6).")),
    ("requirements", "rz_um", QT_TR_NOOP("Roughness Rz, µm"), QT_TR_NOOP("Required surface roughness (8).")),
)
_EXPERT_KEEP = {"diameter_mm", "machined_length_mm"}  # still used in expert mode (V and t_m)
_SURFACES = {"no_crust": QT_TR_NOOP("no crust"), "rolled": QT_TR_NOOP("rolled"), "forging": QT_TR_NOOP("forging"),
             "casting_crust": QT_TR_NOOP("casting crust"), "casting_dirty_crust": QT_TR_NOOP("casting dirty crust")}
_TABLE_COLS = (QT_TR_NOOP("on"), QT_TR_NOOP("row"), QT_TR_NOOP("constraint"), "a", "b", QT_TR_NOOP("rhs = ln c"),
               QT_TR_NOOP("limit ×"), QT_TR_NOOP("slack"), QT_TR_NOOP("use"), QT_TR_NOOP("status"))


class TurningDialog(TurningViewsMixin, QDialog):
    """The turning-mode optimiser (Tools → Turning optimiser); usable on its own.

    Signals
    -------
    computed(dict):
        a computation finished and is shown: ``{"result", "plot", "error"}`` as returned by
        :func:`engine.turning.optimise_with_plot`.
    """

    computed = Signal(object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle(tr("Turning optimiser — spindle speed and feed for minimum machine time"))
        self.resize(1500, 900)
        self.data: CuttingData = load_data()
        self.result: Any = None  # the last TurningResult shown (None when infeasible)
        self.plot: dict[str, Any] | None = None
        self.error: str = ""
        self._loading = False
        self._runner = JobRunner(self)
        self._runner.finished.connect(self._on_finished)
        self._runner.failed.connect(self._on_failed)
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(_DEBOUNCE_MS)
        self._timer.timeout.connect(self.compute)

        # ---- inputs --------------------------------------------------------------------------
        self.edits: dict[str, QLineEdit] = {}
        self.field_errors: dict[str, QLabel] = {}
        left = QWidget()
        lv = QVBoxLayout(left)
        top = QFormLayout()
        self.example = QComboBox()
        for p in sorted((example_case_path("paper").parent).glob("*.toml")):
            self.example.addItem(p.stem, str(p))
        load_btn = QPushButton(tr("Load"))
        load_btn.clicked.connect(lambda: self.load_case_file(self.example.currentData()))
        row = QHBoxLayout()
        row.addWidget(self.example, 1)
        row.addWidget(load_btn)
        top.addRow(tr("Example case"), row)
        self.mode = QComboBox()
        self.mode.addItem(tr("Physical model (handbook data)"), "physical")
        self.mode.addItem(tr("Expert (edit LP rows b1…b11)"), "expert")
        self.mode.currentIndexChanged.connect(self._mode_changed)
        top.addRow(tr("Mode"), self.mode)
        lv.addLayout(top)

        self.machine = self._combo(self.data.machines, tr("Lathe (resources/cutting/machines.toml)"))
        self.machine.currentIndexChanged.connect(self._machine_changed)
        self.material = self._combo(self.data.materials, tr("Workpiece material (materials.toml)"))
        self.material.currentIndexChanged.connect(self._material_changed)
        self.tool = self._combo(self.data.tools, tr("Tool material (tools.toml)"))
        self.fixture = QComboBox()
        for k, lab in (("centres", tr("between centres")), ("chuck", tr("in a chuck")),
                       ("chuck_tailstock", tr("chuck + tailstock"))):
            self.fixture.addItem(lab, k)
        self.surface = QComboBox()
        for k in _SURFACES:
            self.surface.addItem(tr(_SURFACES[k]), k)
        self.roughness_model = QComboBox()
        self.roughness_model.addItem(tr("geometric Rz = S²/8r"), "geometric")
        self.roughness_model.addItem(tr("empirical (paper's (8); uncertain data)"), "empirical")
        self.speed_bands = QComboBox()
        self.speed_bands.addItem(tr("per feed band (handbook)"), "auto")
        self.speed_bands.addItem(tr("first band for all S (as the paper)"), "first")
        self.snap = QCheckBox(tr("Snap to the machine's speed/feed series"))
        self.groups: dict[str, QGroupBox] = {}
        forms: dict[str, QFormLayout] = {}
        for sec, title in (("machine", tr("Machine")), ("workpiece", tr("Workpiece")), ("tool", tr("Tool")),
                           ("requirements", tr("Requirements and options"))):
            g = QGroupBox(title)
            forms[sec] = QFormLayout(g)
            self.groups[sec] = g
            lv.addWidget(g)
        forms["machine"].addRow(tr("Lathe"), self.machine)
        forms["workpiece"].addRow(tr("Material"), self.material)
        forms["workpiece"].addRow(tr("Fixture"), self.fixture)
        forms["workpiece"].addRow(tr("Surface"), self.surface)
        forms["tool"].addRow(tr("Tool material"), self.tool)
        for sec, key, label, tip in _NUM_FIELDS:
            ed = QLineEdit()
            ed.setObjectName(key)
            ed.setToolTip(tr(tip))
            ed.textChanged.connect(self._changed)
            err = QLabel()
            err.setStyleSheet(_ERR_STYLE)
            err.setWordWrap(True)
            err.hide()
            box = QVBoxLayout()
            box.setSpacing(0)
            box.addWidget(ed)
            box.addWidget(err)
            lab = QLabel(tr(label))
            lab.setToolTip(tr(tip))
            forms[sec].addRow(lab, box)
            self.edits[key] = ed
            self.field_errors[key] = err
        forms["requirements"].addRow(tr("Roughness model"), self.roughness_model)
        forms["requirements"].addRow(tr("Taylor coefficients"), self.speed_bands)
        forms["requirements"].addRow(self.snap)
        for w in (self.fixture, self.surface, self.tool, self.roughness_model, self.speed_bands):
            w.currentIndexChanged.connect(self._changed)
        self.snap.toggled.connect(self._changed)
        lv.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidget(left)
        scroll.setWidgetResizable(True)
        scroll.setMinimumWidth(400)
        for combo in left.findChildren(QComboBox):  # long catalogue names: elide, the full text as tooltip
            combo.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
            combo.setMinimumContentsLength(14)
            combo.setToolTip(combo.currentText())
            combo.currentTextChanged.connect(combo.setToolTip)

        # ---- report and constraint table --------------------------------------------------------
        mid = QWidget()
        mv = QVBoxLayout(mid)
        self.summary = QLabel()
        self.summary.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.summary.setWordWrap(True)
        self.summary.setObjectName("summary")
        self.message = QLabel()
        self.message.setStyleSheet(_ERR_STYLE)
        self.message.setWordWrap(True)
        self.message.setObjectName("message")
        mv.addWidget(self.summary)
        mv.addWidget(self.message)
        self.table = QTableWidget(0, len(_TABLE_COLS))
        self.table.setHorizontalHeaderLabels([tr(c) for c in _TABLE_COLS])
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.itemChanged.connect(self._table_changed)
        mv.addWidget(self.table, 1)
        btns = QHBoxLayout()
        add = QPushButton(tr("Add row n^a·S^b ≤ c"))
        add.clicked.connect(self.add_user_row)
        rem = QPushButton(tr("Remove user row"))
        rem.clicked.connect(self.remove_user_row)
        to_exp = QPushButton(tr("Rows → expert"))
        to_exp.setToolTip(tr("Copy the current LP rows (of the feed band in use) into expert mode."))
        to_exp.clicked.connect(self.rows_to_expert)
        for b in (add, rem, to_exp):
            btns.addWidget(b)
        mv.addLayout(btns)

        # ---- plot --------------------------------------------------------------------------------
        self.plot_view = pg.GraphicsLayoutWidget()
        self.plot_view.setBackground("w")
        from winder_gui.views.plots import LogTickAxis

        self.plot_widget = self.plot_view.addPlot(  # a PlotItem; decade ticks labelled 1, 2, 5 only
            row=0, col=0, axisItems={"bottom": LogTickAxis("bottom"), "left": LogTickAxis("left")})
        self.plot_widget.setLogMode(True, True)
        self.plot_widget.showGrid(x=True, y=True, alpha=0.25)
        self.plot_widget.setLabel("bottom", tr("spindle speed n, rpm"))
        self.plot_widget.setLabel("left", tr("feed S, mm/rev"))
        self.plot_widget.setTitle(tr("Feasible region in the (n, S) plane (log axes)"))
        self.legend = pg.LegendItem(labelTextColor="k", colCount=2)  # below the plot, never over it
        self.plot_view.addItem(self.legend, row=1, col=0)
        self.plot_view.ci.layout.setRowStretchFactor(0, 4)
        self._pools: dict[str, list[Any]] = {}
        self._legend_key: list[tuple[int, str]] = []
        self.curves: dict[str, list[pg.PlotDataItem]] = {}
        self.region_items: list[QGraphicsPolygonItem] = []
        self.label_items: list[pg.TextItem] = []
        self.objective_item = pg.PlotDataItem(pen=pg.mkPen("#d62728", width=2, style=Qt.PenStyle.DashLine),
                                              name=tr("objective n·S = max"))
        self.optimum_item = pg.PlotDataItem(pen=None, symbol="star", symbolSize=18,
                                            symbolBrush=pg.mkBrush("#d62728"), symbolPen=pg.mkPen("k"))
        self.snapped_item = pg.PlotDataItem(pen=None, symbol="x", symbolSize=14, symbolBrush=pg.mkBrush("k"),
                                            symbolPen=pg.mkPen("k"))
        for it in (self.objective_item, self.optimum_item, self.snapped_item):
            self.plot_widget.addItem(it)

        split = QSplitter()
        split.addWidget(scroll)
        split.addWidget(mid)
        split.addWidget(self.plot_view)
        split.setSizes([410, 450, 640])
        outer = QVBoxLayout(self)
        outer.addWidget(split)

        # rows of the constraint table: name -> dict(a, b, rhs, on, factor, user)
        self._rows: list[dict[str, Any]] = []
        self._case: TurningCase | None = None
        self.load_case_file(str(example_case_path("paper")))

    # ------------------------------------------------------------------------------ construction
    def _combo(self, table: Any, tip: str) -> QComboBox:
        c = QComboBox()
        c.setToolTip(tip)
        for k, v in table.items():
            c.addItem(f"{k} — {v.get('name', '')}", k)
        return c

    @staticmethod
    def _set_combo(combo: QComboBox, key: str) -> None:
        i = combo.findData(key)
        if i >= 0:
            combo.setCurrentIndex(i)

    # ------------------------------------------------------------------------------ case <-> fields
    def load_case_file(self, path: str) -> None:
        """Fill every input from a case file (TOML), then compute."""
        try:
            case = load_case(path)
        except InputError as exc:
            self.message.setText(str(exc))
            return
        i = self.example.findData(str(path))
        if i >= 0:
            self.example.blockSignals(True)
            self.example.setCurrentIndex(i)
            self.example.blockSignals(False)
        self.set_case(case)

    def set_case(self, case: TurningCase) -> None:
        """Show ``case`` in the inputs (machine/material values filled from the database)."""
        self._loading = True
        try:
            self._set_combo(self.mode, case.mode)
            self._set_combo(self.machine, case.machine)
            self._fill_machine(case.machine)
            self._set_combo(self.material, case.material)
            self._fill_material(case.material)
            self._set_combo(self.tool, case.tool)
            self._set_combo(self.fixture, case.fixture)
            self._set_combo(self.surface, case.surface)
            self._set_combo(self.roughness_model, case.roughness_model)
            self._set_combo(self.speed_bands, case.speed_bands)
            vals = {
                "n_min_rpm": case.n_min_rpm, "n_max_rpm": case.n_max_rpm, "s_min_mm_rev": case.s_min_mm_rev,
                "s_max_mm_rev": case.s_max_mm_rev, "power_kw": case.power_kw, "efficiency": case.efficiency,
                "feed_force_max_n": case.feed_force_max_n, "hb": case.hb, "sigma_b_mpa": case.sigma_b_mpa,
                "diameter_mm": case.diameter_mm, "depth_mm": case.depth_mm, "length_mm": case.length_mm,
                "machined_length_mm": case.machined_length_mm, "tolerance_mm": case.tolerance_mm,
                "deflection_share": case.deflection_share, "tool_life_min": case.tool_life_min,
                "phi_deg": math.degrees(case.phi), "phi1_deg": math.degrees(case.phi1),
                "gamma_deg": math.degrees(case.gamma), "lambda_deg": math.degrees(case.lam),
                "nose_radius_mm": case.nose_radius_mm, "insert_thickness_mm": case.insert_thickness_mm,
                "holder_b_mm": case.holder_b_mm, "holder_h_mm": case.holder_h_mm,
                "holder_overhang_mm": case.holder_overhang_mm, "holder_stress_mpa": case.holder_stress_mpa,
                "rz_um": case.rz_um,
            }
            for k, v in vals.items():
                if v is not None:
                    self.edits[k].setText(f"{v:.6g}")
            self._rows = []
            if case.mode == "expert":
                for name, a, b, rhs, en in case.expert_rows:
                    self._rows.append({"name": name, "a": a, "b": b, "rhs": rhs, "on": en and name not in
                                       case.disabled, "factor": dict(case.limit_factor).get(name, 1.0),
                                       "user": name not in CONSTRAINT_NAMES})
            else:
                for name in CONSTRAINT_NAMES:
                    self._rows.append({"name": name, "a": None, "b": None, "rhs": None,
                                       "on": name not in case.disabled,
                                       "factor": dict(case.limit_factor).get(name, 1.0), "user": False})
            for u in case.user_rows:
                self._rows.append({"name": u.name, "a": u.a, "b": u.b, "rhs": math.log(u.c),
                                   "on": u.name not in case.disabled, "factor": 1.0, "user": True})
            self._refill_table()
            self._apply_mode_enabling()
        finally:
            self._loading = False
        self._changed()

    def _fill_machine(self, key: str) -> None:
        m = self.data.machines.get(key, {})
        for k in ("n_min_rpm", "n_max_rpm", "s_min_mm_rev", "s_max_mm_rev", "power_kw", "efficiency",
                  "feed_force_max_n"):
            if k in m:
                self.edits[k].setText(f"{float(m[k]):.6g}")

    def _fill_material(self, key: str) -> None:
        m = self.data.materials.get(key, {})
        for k in ("hb", "sigma_b_mpa"):
            if k in m:
                self.edits[k].setText(f"{float(m[k]):.6g}")

    def _machine_changed(self) -> None:
        if not self._loading:
            self._loading = True
            try:
                self._fill_machine(self.machine.currentData())
            finally:
                self._loading = False
            self._changed()

    def _material_changed(self) -> None:
        if not self._loading:
            self._loading = True
            try:
                self._fill_material(self.material.currentData())
            finally:
                self._loading = False
            self._changed()

    def _mode_changed(self) -> None:
        if self._loading:
            return
        self._apply_mode_enabling()
        if self.current_mode() == "expert" and any(r["a"] is None for r in self._rows if not r["user"]):
            self.rows_to_expert()
            return
        if self.current_mode() == "physical":
            users = [r for r in self._rows if r["user"]]
            old = {r["name"]: r for r in self._rows}
            self._rows = [{"name": n, "a": None, "b": None, "rhs": None, "on": old.get(n, {}).get("on", True),
                           "factor": 1.0, "user": False} for n in CONSTRAINT_NAMES] + users
            self._refill_table()
        self._changed()

    def current_mode(self) -> str:
        """``"physical"`` or ``"expert"``."""
        return str(self.mode.currentData())

    def _apply_mode_enabling(self) -> None:
        expert = self.current_mode() == "expert"
        for w in (self.machine, self.material, self.tool, self.fixture, self.surface, self.roughness_model,
                  self.speed_bands):
            w.setEnabled(not expert)
        for key, ed in self.edits.items():
            ed.setEnabled(not expert or key in _EXPERT_KEEP)

    def case_document(self) -> dict[str, Any]:
        """The inputs as a case document (the TOML layout); raises :class:`InputError` naming the field."""
        doc: dict[str, Any] = {"mode": self.current_mode(), "machine": {"id": self.machine.currentData()},
                               "workpiece": {"material": self.material.currentData(),
                                             "fixture": self.fixture.currentData(),
                                             "surface": self.surface.currentData()},
                               "tool": {"material": self.tool.currentData()},
                               "requirements": {},
                               "options": {"roughness_model": self.roughness_model.currentData(),
                                           "speed_bands": self.speed_bands.currentData()}}
        expert = self.current_mode() == "expert"
        for sec, key, label, _tip in _NUM_FIELDS:
            if expert and key not in _EXPERT_KEEP:
                continue
            text = self.edits[key].text().strip()
            if not text:
                raise InputError(tr("{label}: a value is required").format(label=tr(label)), field=f"{sec}.{key}")
            try:
                v = float(text.replace(",", "."))
            except ValueError:
                raise InputError(f"{label}: {text!r} is not a number", field=f"{sec}.{key}") from None
            doc[sec][key] = v
        cons: dict[str, Any] = {"disable": [r["name"] for r in self._rows if not r["on"]],
                                "limit_factor": {r["name"]: r["factor"] for r in self._rows
                                                 if not r["user"] and r["factor"] != 1.0},
                                "user": []}
        if expert:
            doc["rows"] = [{"name": r["name"], "a": r["a"], "b": r["b"], "rhs": r["rhs"], "enabled": r["on"]}
                           for r in self._rows if not r["user"]]
            cons["user"] = [{"name": r["name"], "a": r["a"], "b": r["b"], "c": math.exp(r["rhs"])}
                            for r in self._rows if r["user"]]
        else:
            cons["user"] = [{"name": r["name"], "a": r["a"], "b": r["b"], "c": math.exp(r["rhs"])}
                            for r in self._rows if r["user"]]
        doc["constraints"] = cons
        return doc

    # ------------------------------------------------------------------------------ computing
    def _changed(self) -> None:
        if self._loading:
            return
        for lab in self.field_errors.values():
            lab.hide()
        try:
            self._case = case_from_dict(self.case_document())
        except InputError as exc:
            self._timer.stop()
            self._show_input_error(exc)
            return
        self.message.setText("")
        self._timer.start()

    def _show_input_error(self, exc: InputError) -> None:
        self.error = str(exc)
        self.message.setText(tr("Input: {exc}").format(exc=exc))
        fld = exc.location.field or ""
        key = fld.split(".")[-1]
        if key in self.field_errors:
            self.field_errors[key].setText(exc.message)
            self.field_errors[key].show()

    def compute(self) -> None:
        """Submit the current (validated) case to the worker now."""
        self._timer.stop()
        if self._case is None:
            return
        self._runner.submit(optimise_with_plot, self._case, self.data, snap=self.snap.isChecked())

    def flush(self) -> None:
        """Run a pending debounced computation immediately (for tests and scripts)."""
        if self._timer.isActive():
            self.compute()

    def _on_failed(self, exc: object, tb: str) -> None:
        if isinstance(exc, InputError):
            self._show_input_error(exc)
        else:  # a bug: show it, never crash the dialog
            self.message.setText(tr("Internal error: {exc!r}").format(exc=exc))
        self.result = None
        self.plot = None
        self.summary.setText(tr("<b>No result</b> — see the message below."))
        self._draw(None)
        self.computed.emit({"result": None, "plot": None, "error": exc})

    def _on_finished(self, out: dict[str, Any]) -> None:
        self.result = out["result"]
        self.plot = out["plot"]
        err = out["error"]
        self.error = str(err) if err is not None else ""
        self.message.setText(tr("Infeasible: {message}").format(message=err.message) if err is not None else "")
        self._show_result()
        self._draw(self.plot)
        self.computed.emit(out)

    # ------------------------------------------------------------------------------ Qt
    def closeEvent(self, event: Any) -> None:  # noqa: N802 - Qt override
        """Stop the worker before the dialog goes away."""
        self._timer.stop()
        self._runner.cancel()
        self._runner.wait(5000)
        super().closeEvent(event)

    def done(self, r: int) -> None:  # noqa: D102 - Qt override
        self._timer.stop()
        self._runner.cancel()
        self._runner.wait(5000)
        super().done(r)


def main() -> int:
    """Run the dialog on its own: ``python -m winder_gui.dialogs.turning``."""
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv)
    dlg = TurningDialog()
    dlg.show()
    return int(app.exec())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
