"""The layer table of the Winding step: the laminate of a job (schema version 2, ``[[layer]]``).

One row per layer, in winding order: enabled (check box), name (editable in place), kind, a short
definition, and after a run the layer's program time, fibre length and thickness on the cylinder.
Buttons add a hoop / helical / polar / skip layer after the selected one, duplicate, delete and move
it; rows are reordered by dragging too.  Under the table the selected layer's own fields are edited
(hoop: z range, overlap, passes, terminal; helical/polar: angle or pole C, pattern, mode; skip: angle;
every kind: band width/thickness overrides, lead-in/out).  A blank optional field inherits ``[band]``
/ ``[winding]`` (shown below the table as the defaults).

Every change is validated by the job model itself and emitted as a whole new job
(:attr:`LayersPanel.job_edited`, with an undo text), so the window's undo covers it.  The figures
of a row are shown only while they describe the row: they are matched by the layer's key
(:func:`engine.laminate.layer_keys`, every input up to and including the layer), so an edit of layer
k blanks the figures of layers k… until the next run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QMenu,
    QPushButton,
    QTableView,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from engine.job import LAYER_KINDS, HelicalLayer, Job, layer_name
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.panels.layer_table import (  # noqa: F401 - COL, LAYER_COLOURS, layer_colour, move_rows: API
    COL,
    COLUMNS,
    LAYER_CLASSES,
    LAYER_COLOURS,
    MIME,
    LayerTableModel,
    _g,
    describe_layer,
    layer_colour,
    move_rows,
)


@dataclass(frozen=True)
class LayerField:
    """One editable value of a layer: ``key`` a dotted path (``band.width_mm``, ``z_range_mm.0``)."""

    key: str
    label: str
    kind: str = "float"
    optional: bool = False
    choices: tuple[str, ...] = ()
    tip: str = ""


_COMMON = (
    LayerField("name", QT_TR_NOOP("Name"), "str", optional=True,
               tip=QT_TR_NOOP("shown in the table, the NC comments and the report")),
    LayerField("band.width_mm", QT_TR_NOOP("Band width [mm]"), optional=True, tip=QT_TR_NOOP("blank: [band] width")),
    LayerField("band.thickness_mm", QT_TR_NOOP("Band thickness [mm]"), optional=True,
               tip=QT_TR_NOOP("blank: [band] thickness")),
    LayerField("lead_in_mm", QT_TR_NOOP("Lead-in [mm]"),
               tip=QT_TR_NOOP("carriage move before the first point of the layer")),
    LayerField("lead_out_deg", QT_TR_NOOP("Lead-out [deg]"),
               tip=QT_TR_NOOP("extra mandrel rotation after the last point (tie-off)")),
)
INHERITED = "(inherited)"
"""The choice that leaves a layer's value to ``[winding]``."""
_MODES = (INHERITED, "auto", "geodesic", "constant-lambda", "piecewise-lambda", "minimax")
_HELICAL = (
    LayerField("angle_deg", QT_TR_NOOP("Angle β [deg]"), optional=True,
               tip=QT_TR_NOOP("winding angle on the middle of the cylindrical part; "
                              "blank: pole C or [winding] angles")),
    LayerField("pole_c_mm.0", QT_TR_NOOP("Pole C left [mm]"), optional=True),
    LayerField("pole_c_mm.1", QT_TR_NOOP("Pole C right [mm]"), optional=True),
    LayerField("mode", QT_TR_NOOP("Line"), "choice", optional=True, choices=_MODES,
               tip=QT_TR_NOOP("blank: [winding] mode")),
    LayerField("pattern_p", QT_TR_NOOP("Pattern p [–]"), "int", optional=True),
    LayerField("pattern_q", QT_TR_NOOP("Pattern q [–]"), "int", optional=True),
    LayerField("circuits", QT_TR_NOOP("Circuits [–]"), "int", optional=True),
    LayerField("repeat", QT_TR_NOOP("Repeat [–]"), "int", optional=True,
               tip=QT_TR_NOOP("times the pattern is wound; blank: [winding] layers")),
)
KIND_FIELDS: dict[str, tuple[LayerField, ...]] = {
    "hoop": (
        LayerField("z_range_mm.0", QT_TR_NOOP("z from [mm]"), optional=True,
                   tip=QT_TR_NOOP("blank (both): the cylindrical part")),
        LayerField("z_range_mm.1", QT_TR_NOOP("z to [mm]"), optional=True),
        LayerField("overlap", QT_TR_NOOP("Overlap [–]"),
                   tip=QT_TR_NOOP("share of the band width laid over the previous turn")),
        LayerField("passes", QT_TR_NOOP("Passes [–]"), "int"),
        LayerField("terminal", QT_TR_NOOP("Terminal"), "bool"),
    ),
    "helical": _HELICAL,
    "polar": _HELICAL,
    "skip": (LayerField("angle_deg", QT_TR_NOOP("Mandrel rotation [deg]")),),
}


def _get(data: dict[str, Any], key: str) -> Any:
    parts = key.split(".")
    v: Any = data
    for p in parts:
        if v is None:
            return None
        v = v[int(p)] if p.isdigit() else v.get(p)
    return v


class LayersPanel(QWidget):
    """The layer table and the selected layer's fields (see the module docstring).

    Signals
    -------
    job_edited(Job, str):
        A valid job with the layers changed, and the undo text.
    layer_selected(int):
        The job layer shown (0-based; -1: none).
    validity_changed(str):
        ``""`` when the selected layer's fields are valid, else the first problem.
    """

    job_edited = Signal(object, str)
    layer_selected = Signal(int)
    validity_changed = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.job: Job | None = None
        self._loading = False
        self._problem = ""
        self._selected = -1
        self.model = LayerTableModel(self)
        self.model.edit_requested.connect(self._apply_layers)
        self.table = QTableView()
        self.table.setObjectName("layerTable")
        self.table.setModel(self.model)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setDragEnabled(True)
        self.table.setAcceptDrops(True)
        self.table.setDropIndicatorShown(True)
        self.table.setDragDropMode(QAbstractItemView.DragDropMode.InternalMove)
        self.table.setDragDropOverwriteMode(False)
        self.table.setDefaultDropAction(Qt.DropAction.MoveAction)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.DoubleClicked
                                   | QAbstractItemView.EditTrigger.EditKeyPressed)
        self.table.verticalHeader().setDefaultSectionSize(22)
        hh = self.table.horizontalHeader()
        hh.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        hh.setSectionResizeMode(COL["definition"], QHeaderView.ResizeMode.Stretch)
        self.table.setMinimumHeight(150)
        self.table.selectionModel().currentRowChanged.connect(lambda cur, _prev: self._on_row(cur.row()))

        self.add_button = QToolButton()
        self.add_button.setText(tr("Add"))
        self.add_button.setObjectName("addLayer")
        self.add_button.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        menu = QMenu(self.add_button)
        self.add_actions: dict[str, QAction] = {}
        for kind in LAYER_KINDS:
            act = menu.addAction(tr("{v0} layer").format(v0=kind.capitalize()))
            act.triggered.connect(lambda _c=False, k=kind: self.add_layer(k))
            self.add_actions[kind] = act
        self.add_button.setMenu(menu)
        self.dup_button = QPushButton(tr("Duplicate"))
        self.dup_button.clicked.connect(lambda: self.duplicate_layer())
        self.del_button = QPushButton(tr("Delete"))
        self.del_button.clicked.connect(lambda: self.delete_layer())
        self.up_button = QPushButton("▲")
        self.up_button.setToolTip(tr("Move the layer one up (wound earlier); or drag the row"))
        self.up_button.clicked.connect(lambda: self.move_layer(self._selected, self._selected - 1))
        self.down_button = QPushButton("▼")
        self.down_button.setToolTip(tr("Move the layer one down (wound later); or drag the row"))
        self.down_button.clicked.connect(lambda: self.move_layer(self._selected, self._selected + 1))
        for b in (self.up_button, self.down_button):
            b.setMaximumWidth(32)
        buttons = QHBoxLayout()
        for b in (self.add_button, self.dup_button, self.del_button, self.up_button, self.down_button):
            buttons.addWidget(b)
        buttons.addStretch(1)

        self.totals = QLabel("")
        self.totals.setObjectName("layupTotals")
        self.totals.setWordWrap(True)
        self.totals.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        self.editor_box = QGroupBox(tr("Layer"))
        box = QVBoxLayout(self.editor_box)
        self.kind_combo = QComboBox()
        self.kind_combo.setObjectName("layer.kind")
        self.kind_combo.addItems(list(LAYER_KINDS))
        self.kind_combo.setToolTip(tr("changing the kind keeps the name, band and lead-in/out"))
        self.kind_combo.activated.connect(lambda _i: self._on_kind())
        kind_row = QHBoxLayout()
        kind_row.addWidget(QLabel(tr("Kind")))
        kind_row.addWidget(self.kind_combo, 1)
        box.addLayout(kind_row)
        self.form = QFormLayout()
        self.form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        box.addLayout(self.form)
        self.editors: dict[str, QLineEdit | QComboBox | QCheckBox] = {}
        self.error_labels: dict[str, QLabel] = {}
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.status.setStyleSheet("color: #c01010;")

        lay = QVBoxLayout(self)
        lay.setContentsMargins(6, 6, 6, 6)
        title = QLabel(tr("<b>Laminate</b> — layers wound in this order on the growing surface"))
        title.setWordWrap(True)
        lay.addWidget(title)
        lay.addLayout(buttons)
        lay.addWidget(self.table)
        lay.addWidget(self.totals)
        lay.addWidget(self.editor_box)
        lay.addWidget(self.status)
        self._update_buttons()

    # -- public API ------------------------------------------------------------------------------------
    def set_job(self, job: Job) -> None:
        """Show ``job``'s layers (the selection stays on the same row where it can)."""
        from engine.laminate import layer_keys

        self.job = job
        sel = self._selected
        self._loading = True
        try:
            self.model.set_layers(list(job.layers), layer_keys(job))
            n = len(job.layers)
            sel = min(max(sel, 0), n - 1) if n else -1
            if sel >= 0:
                self.table.selectRow(sel)
                self.table.setCurrentIndex(self.model.index(sel, COL["name"]))
        finally:
            self._loading = False
        self._selected = -2  # force a refresh of the editor
        self._on_row(sel)

    def set_layup(self, layup: dict[str, Any] | None, figures_by_key: dict[str, dict[str, Any]] | None) -> None:
        """Fill the figures columns (``figures_by_key``: each layer's figures by its key) and the totals line
        from ``layup`` (:meth:`engine.laminate.LaminateResult.layup`); ``None`` clears them."""
        self.model.set_figures(figures_by_key or {})
        if not layup:
            self.totals.setText("")
            return
        t = layup["total"]
        self.totals.setText(
            tr("Total: program {v0:.1f} s (layers {v1:.1f} s + transitions {v2:.1f} s) · fibre "
               "{v3:.1f} m, {v4:.3f} kg · resin {v5:.3f} kg · thickness on the cylinder {v6:.3f} mm, "
               "max {v7:.3f} mm · volume check {v8:+.2f} %")
            .format(v0=t.get('program_time_s', 0.0), v1=t.get('time_s', 0.0), v2=t.get('transition_time_s', 0.0),
                    v3=t.get('fibre_length_m', 0.0), v4=t.get('fibre_mass_kg', 0.0), v5=t.get('resin_mass_kg', 0.0),
                    v6=t.get('thickness_cyl_mm', 0.0), v7=t.get('thickness_max_mm', 0.0),
                    v8=100.0 * float(layup.get('volume_error', 0.0))))

    def selected_layer(self) -> int:
        """The job layer selected (0-based; -1: none)."""
        return self._selected

    def select_layer(self, index: int) -> None:
        """Select job layer ``index`` (as a click on its row would)."""
        self.table.selectRow(index)
        self.table.setCurrentIndex(self.model.index(index, COL["name"]))

    def show_error(self, field_name: str | None, message: str) -> bool:
        """Show an engine error at its layer field (``"layer.<n>.<key>"``, n from 1): the layer is selected
        and the message shown under the field (or under the editor); True when it names a layer."""
        parts = (field_name or "").split(".")
        if len(parts) < 2 or parts[0] != "layer" or not parts[1].isdigit() or self.job is None:
            return False
        i = int(parts[1]) - 1
        if not (0 <= i < len(self.job.layers)):
            return False
        if i != self._selected:
            self.select_layer(i)
        key = ".".join(parts[2:])
        lab = self.error_labels.get(key) or next((lab for k, lab in self.error_labels.items() if key and
                                                  k.startswith(key)), None)
        if lab is not None:
            lab.setText(message)
            lab.show()
        else:
            self.status.setText(message)  # shown, not a field problem: Run stays enabled
        return True

    def errors(self) -> str:
        """The first problem shown at the layer's fields ('' when none)."""
        return self._problem

    def editor(self, key: str) -> QLineEdit | QComboBox | QCheckBox:
        """The editor of the selected layer's field ``key`` (e.g. ``overlap``, ``band.width_mm``)."""
        return self.editors[key]

    def set_value(self, key: str, value: Any) -> None:
        """Type ``value`` into the selected layer's field ``key`` as a user would."""
        ed = self.editors[key]
        if isinstance(ed, QCheckBox):
            ed.setChecked(bool(value))  # emits through toggled
            return
        if isinstance(ed, QComboBox):
            ed.setCurrentText(str(value))
        else:
            ed.setText(value if isinstance(value, str) else format(value, ".10g"))
        self._on_field_edited()

    # -- layer operations (each one undoable job edit) ---------------------------------------------
    def add_layer(self, kind: str) -> None:
        """Insert a new ``kind`` layer after the selected one (at the end when none)."""
        if self.job is None:
            return
        layers = list(self.job.layers)
        at = self._selected + 1 if self._selected >= 0 else len(layers)
        layers.insert(at, LAYER_CLASSES[kind]())
        self._apply_layers(layers, f"Add {kind} layer", at)

    def duplicate_layer(self, index: int | None = None) -> None:
        """Insert a copy of layer ``index`` (the selected one) after it."""
        i = self._selected if index is None else index
        if self.job is None or not (0 <= i < len(self.job.layers)):
            return
        layers = list(self.job.layers)
        src = layers[i]
        copy = src.model_copy(update={"name": f"{src.name} copy" if src.name else ""}, deep=True)
        layers.insert(i + 1, copy)
        self._apply_layers(layers, f"Duplicate layer {i + 1}", i + 1)

    def delete_layer(self, index: int | None = None) -> None:
        """Remove layer ``index`` (the selected one); the last layer of a job cannot be deleted."""
        i = self._selected if index is None else index
        if self.job is None or not (0 <= i < len(self.job.layers)):
            return
        if len(self.job.layers) == 1:
            self._set_status(tr("a job keeps at least one layer (disable it or change its kind instead)"))
            return
        layers = list(self.job.layers)
        del layers[i]
        self._apply_layers(layers, f"Delete layer {i + 1}", min(i, len(layers) - 1))

    def move_layer(self, src: int, dst: int) -> None:
        """Move layer ``src`` to position ``dst`` (0-based, in the new order)."""
        if self.job is None:
            return
        n = len(self.job.layers)
        if not (0 <= src < n and 0 <= dst < n) or src == dst:
            return
        layers = list(self.job.layers)
        lay = layers.pop(src)
        layers.insert(dst, lay)
        self._apply_layers(layers, f"Move layer {src + 1} to position {dst + 1}", dst)

    def set_enabled(self, index: int, on: bool) -> None:
        """Enable or disable layer ``index`` (as its check box does)."""
        self.model.setData(self.model.index(index, COL[QT_TR_NOOP("on")]),
                           Qt.CheckState.Checked if on else Qt.CheckState.Unchecked, Qt.ItemDataRole.CheckStateRole)

    # -- internals ---------------------------------------------------------------------------------------
    def _job_with(self, layers: list[Any]) -> Any:
        """The job with ``layers``, or ``None`` (no job, or the layers do not validate: said in the status)."""
        if self.job is None:
            return None
        try:
            return self.job.replace(layers=[lay.model_dump() for lay in layers])
        except ValidationError as exc:
            self._set_status(tr("not applied: {v0}").format(v0=exc.errors()[0].get('msg', exc)))
            return None

    def _apply_layers(self, layers: list[Any], text: str, select: int) -> None:
        job = self._job_with(layers)
        if job is None:
            return
        self._selected = select
        self.set_job(job)
        self.job_edited.emit(job, text)

    def _update_buttons(self) -> None:
        n = len(self.job.layers) if self.job is not None else 0
        i = self._selected
        ok = 0 <= i < n
        self.dup_button.setEnabled(ok)
        self.del_button.setEnabled(ok and n > 1)
        self.up_button.setEnabled(ok and i > 0)
        self.down_button.setEnabled(ok and i < n - 1)
        self.editor_box.setEnabled(ok)

    def _on_row(self, row: int) -> None:
        if self._loading:
            return
        changed = row != self._selected
        self._selected = row
        self._build_editor()
        self._update_buttons()
        if changed:
            self.layer_selected.emit(row)

    def _clear_form(self) -> None:
        while self.form.rowCount():
            self.form.removeRow(0)  # deletes the row's label and editor
        self.editors, self.error_labels = {}, {}

    def _build_editor(self) -> None:
        self._clear_form()
        job, i = self.job, self._selected
        if job is None or not (0 <= i < len(job.layers)):
            self.editor_box.setTitle(tr("Layer"))
            return
        lay = job.layers[i]
        self.editor_box.setTitle(tr("Layer {v0}: {v1}").format(v0=i + 1, v1=layer_name(lay, i)))
        self._loading = True
        try:
            self.kind_combo.setCurrentText(lay.kind)
            data = lay.model_dump(mode="python")
            for f in (*_COMMON[:1], *KIND_FIELDS[lay.kind], *_COMMON[1:]):
                if lay.kind == "skip" and f.key.startswith("band."):
                    continue
                ed: QLineEdit | QComboBox | QCheckBox
                v = _get(data, f.key)
                if f.kind == "bool":
                    ed = QCheckBox()
                    ed.setChecked(bool(v))
                    ed.toggled.connect(lambda _on: self._on_field_edited())
                elif f.kind == "choice":
                    ed = QComboBox()
                    ed.addItems(list(f.choices))
                    ed.setCurrentText(INHERITED if v is None else str(v))
                    ed.activated.connect(lambda _i: self._on_field_edited())
                else:
                    ed = QLineEdit()
                    if f.kind != "str":
                        ed.setAlignment(Qt.AlignmentFlag.AlignRight)
                    if f.optional:
                        inherited = f.key.startswith("band.") or f.key in (
                            "mode", "repeat", "pattern_p", "pattern_q", "circuits")
                        ed.setPlaceholderText(tr("inherited") if inherited else tr("default"))
                    ed.setText("" if v is None else (v if isinstance(v, str) else format(v, ".10g")))
                    ed.textEdited.connect(lambda _t: self._on_field_edited())
                ed.setObjectName(f"layer.{f.key}")
                if f.tip:
                    ed.setToolTip(tr(f.tip))
                err = QLabel("")
                err.setStyleSheet("color: #c01010; font-size: 9pt; padding-left: 12px;")
                err.setWordWrap(True)
                err.hide()
                self.form.addRow(tr(f.label), ed)
                self.form.addRow(err)
                self.editors[f.key] = ed
                self.error_labels[f.key] = err
        finally:
            self._loading = False
        self._set_status("")

    def _read(self, lay: Any) -> tuple[dict[str, Any], dict[str, str]]:
        data = lay.model_dump(mode="python")
        errs: dict[str, str] = {}
        pairs: dict[str, list[Any]] = {}
        fields = {f.key: f for f in (*_COMMON, *KIND_FIELDS[lay.kind])}
        for key, ed in self.editors.items():
            f = fields[key]
            if isinstance(ed, QCheckBox):
                val: Any = ed.isChecked()
            elif isinstance(ed, QComboBox):
                val = None if ed.currentText() in ("", INHERITED) else ed.currentText()
            else:
                text = ed.text().strip()
                if f.kind == "str":
                    val = text
                elif not text:
                    val = None
                    if not f.optional:
                        errs[key] = "a value is required"
                        continue
                else:
                    try:
                        val = int(text) if f.kind == "int" else float(text)
                    except ValueError:
                        errs[key] = "not a whole number" if f.kind == "int" else "not a number"
                        continue
            head, _, tail = key.partition(".")
            if tail.isdigit():
                pairs.setdefault(head, [None, None])[int(tail)] = val
            elif tail:
                data.setdefault(head, {})[tail] = val
            else:
                data[head] = val
        for head, (a, b) in pairs.items():
            if (a is None) != (b is None):
                errs[f"{head}.{1 if b is None else 0}"] = "give both ends, or neither"
                continue
            data[head] = None if a is None else (a, b)
        return data, errs

    def _on_field_edited(self) -> None:
        if self._loading or self.job is None or not (0 <= self._selected < len(self.job.layers)):
            return
        i = self._selected
        lay = self.job.layers[i]
        data, errs = self._read(lay)
        new_layer = None
        if not errs:
            try:
                new_layer = LAYER_CLASSES[lay.kind].model_validate(data)
            except ValidationError as exc:
                for e in exc.errors():
                    loc = [str(p) for p in e.get("loc", ())]
                    key = ".".join(loc)
                    key = key if key in self.editors else next((k for k in self.editors if k.startswith(key)), "")
                    errs[key or "name"] = e.get("msg", "invalid").removeprefix("Value error, ")
        for key, lab in self.error_labels.items():
            msg = errs.get(key, "")
            lab.setText(msg)
            lab.setVisible(bool(msg))
        if errs:
            k, m = next(iter(errs.items()))
            self._set_status(tr("layer {v0} {k}: {m}").format(v0=i + 1, k=k, m=m))
            return
        self._set_status("")
        assert new_layer is not None
        if new_layer == lay:
            return
        layers = list(self.job.layers)
        layers[i] = new_layer
        self._apply_layers_keep_editor(layers, f"Edit layer {i + 1}", i)

    def _apply_layers_keep_editor(self, layers: list[Any], text: str, select: int) -> None:
        """Like :meth:`_apply_layers` but keeps the field editors (what the user is typing)."""
        job = self._job_with(layers)
        if job is None:
            return
        from engine.laminate import layer_keys

        self.job = job
        self._loading = True
        try:
            self.model.set_layers(list(job.layers), layer_keys(job))
            self.table.selectRow(select)
            self.table.setCurrentIndex(self.model.index(select, COL["name"]))
        finally:
            self._loading = False
        self.editor_box.setTitle(tr("Layer {v0}: {v1}")
                                 .format(v0=select + 1, v1=layer_name(job.layers[select], select)))
        self.job_edited.emit(job, text)

    def _on_kind(self) -> None:
        if self._loading or self.job is None or not (0 <= self._selected < len(self.job.layers)):
            return
        i = self._selected
        lay = self.job.layers[i]
        kind = self.kind_combo.currentText()
        if kind == lay.kind:
            return
        keep = {"name": lay.name, "enabled": lay.enabled, "lead_in_mm": lay.lead_in_mm,
                "lead_out_deg": lay.lead_out_deg}
        if kind != "skip":
            keep["band"] = lay.band.model_dump()
        if isinstance(lay, HelicalLayer) and kind in ("helical", "polar"):  # helical <-> polar keeps the line
            keep = {**lay.model_dump(), "kind": kind}
        layers = list(self.job.layers)
        layers[i] = LAYER_CLASSES[kind].model_validate(keep)
        self._apply_layers(layers, f"Layer {i + 1}: {lay.kind} -> {kind}", i)

    def _set_status(self, problem: str) -> None:
        self.status.setText(problem)
        if problem != self._problem:
            self._problem = problem
            self.validity_changed.emit(problem)
