"""The layer table's model (:class:`LayerTableModel`: one row per layer of the job, figures matched by layer
key, drag-and-drop reordering), the layer colours and the short definition of a layer; the table and the
layer's fields are :class:`winder_gui.panels.layers_panel.LayersPanel`."""

from __future__ import annotations

import json
from typing import Any

from PySide6.QtCore import QAbstractTableModel, QMimeData, QModelIndex, QPersistentModelIndex, Qt, Signal
from PySide6.QtGui import QColor

from engine.job import HelicalLayer, HoopLayer, PolarLayer, SkipLayer, layer_name
from winder_gui.i18n import QT_TR_NOOP

LAYER_CLASSES: dict[str, type] = {"hoop": HoopLayer, "helical": HelicalLayer, "polar": PolarLayer, "skip": SkipLayer}
LAYER_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
                 "#bcbd22", "#7f7f7f")
"""Colour of job layer i: ``LAYER_COLOURS[i % len]`` (table swatch, plots)."""
MIME = "application/x-winder-layer-rows"
COLUMNS: tuple[tuple[str, str], ...] = (
    (QT_TR_NOOP("on"), ""), ("name", "Name"), ("kind", "Kind"), ("time_s", "Time [s]"), ("fibre_length_m", "Fibre [m]"),
    ("thickness_cyl_mm", "t cyl [mm]"), ("definition", "Definition"),
)
COL = {key: i for i, (key, _t) in enumerate(COLUMNS)}


def layer_colour(index: int) -> str:
    """The colour of job layer ``index`` (0-based) in the table and the plots."""
    return LAYER_COLOURS[index % len(LAYER_COLOURS)]


def _g(v: Any) -> str:
    return "" if v is None else format(float(v), ".6g")


def describe_layer(layer: Any) -> str:
    """A one-line definition of ``layer`` for the table (inherited values are not repeated)."""
    band = layer.band
    extra = []
    if band.width_mm is not None:
        extra.append(f"b {_g(band.width_mm)} mm")
    if band.thickness_mm is not None:
        extra.append(f"t {_g(band.thickness_mm)} mm")
    if isinstance(layer, HoopLayer):
        zr = f"z {_g(layer.z_range_mm[0])}…{_g(layer.z_range_mm[1])} mm" if layer.z_range_mm else "cylinder"
        parts = [zr, f"overlap {_g(layer.overlap)}", "terminal" if layer.terminal else f"{layer.passes} pass(es)"]
    elif isinstance(layer, HelicalLayer):
        if layer.angle_deg is not None:
            parts = [f"{_g(layer.angle_deg)}°"]
        elif layer.pole_c_mm is not None:
            parts = [f"C {_g(layer.pole_c_mm[0])}/{_g(layer.pole_c_mm[1])} mm"]
        elif layer.angles:
            parts = [", ".join(f"{_g(a.angle_deg)}° at z {_g(a.z_mm)}" for a in layer.angles)]
        else:
            parts = ["openings" if layer.kind == "polar" else "[winding]"]
        if layer.mode:
            parts.append(layer.mode)
        if layer.pattern_p is not None or layer.pattern_q is not None:
            parts.append(f"p/q {layer.pattern_p or '–'}/{layer.pattern_q or '–'}")
        if layer.repeat:
            parts.append(f"×{layer.repeat}")
    else:
        parts = [f"rotate {_g(layer.angle_deg)}°"]
    return ", ".join(parts + extra)


class LayerTableModel(QAbstractTableModel):
    """The job's layers as table rows; edits (check box, name, drop) are asked for by :attr:`edit_requested`
    (``(layers, undo text, row to select)``); the panel applies them to the job."""

    edit_requested = Signal(object, str, int)

    def __init__(self, parent: Any = None) -> None:
        super().__init__(parent)
        self.layers: list[Any] = []
        self.keys: list[str] = []
        self.figures: dict[str, dict[str, Any]] = {}

    def set_layers(self, layers: list[Any], keys: list[str]) -> None:
        self.beginResetModel()
        self.layers = list(layers)
        self.keys = list(keys)
        self.endResetModel()

    def set_figures(self, figures: dict[str, dict[str, Any]]) -> None:
        """Per-layer figures by layer key (an empty dict: none)."""
        self.figures = dict(figures)
        if self.layers:
            self.dataChanged.emit(self.index(0, 0), self.index(len(self.layers) - 1, len(COLUMNS) - 1))

    def figures_of(self, row: int) -> dict[str, Any] | None:
        """The figures shown for ``row`` (None when it has none that describe it)."""
        if not (0 <= row < len(self.keys)):
            return None
        return self.figures.get(self.keys[row])

    # -- Qt model ------------------------------------------------------------------------------------
    def rowCount(self, parent: QModelIndex | QPersistentModelIndex = QModelIndex()) -> int:  # noqa: B008, N802
        return 0 if parent.isValid() else len(self.layers)

    def columnCount(self, parent: QModelIndex | QPersistentModelIndex = QModelIndex()) -> int:  # noqa: B008, N802
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(self, section: int, orientation: Qt.Orientation,  # noqa: N802
                   role: int = Qt.ItemDataRole.DisplayRole) -> Any:
        if role != Qt.ItemDataRole.DisplayRole:
            return None
        if orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section][1]
        return str(section + 1)

    def data(self, index: QModelIndex | QPersistentModelIndex, role: int = Qt.ItemDataRole.DisplayRole) -> Any:
        if not index.isValid():
            return None
        row, key = index.row(), COLUMNS[index.column()][0]
        lay = self.layers[row]
        if key == QT_TR_NOOP("on"):
            if role == Qt.ItemDataRole.CheckStateRole:
                return Qt.CheckState.Checked if lay.enabled else Qt.CheckState.Unchecked
            if role == Qt.ItemDataRole.DecorationRole:
                return QColor(layer_colour(row))
            if role == Qt.ItemDataRole.ToolTipRole:
                return "wound" if lay.enabled else "disabled: kept in the job, neither wound nor counted"
            return None
        if role == Qt.ItemDataRole.ForegroundRole and not lay.enabled:
            return QColor("#999999")
        if role == Qt.ItemDataRole.TextAlignmentRole and key in ("time_s", "fibre_length_m", "thickness_cyl_mm"):
            return int(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        if role == Qt.ItemDataRole.EditRole and key == "name":
            return lay.name
        if role not in (Qt.ItemDataRole.DisplayRole, Qt.ItemDataRole.ToolTipRole):
            return None
        if key == "name":
            return layer_name(lay, row)
        if key == "kind":
            return lay.kind
        if key == "definition":
            return describe_layer(lay)
        f = self.figures_of(row)
        if f is None:
            return "off" if not lay.enabled and key == "time_s" else ""
        v = f.get(key)
        if v is None:
            return ""
        return f"{float(v):.2f}" if key != "thickness_cyl_mm" else f"{float(v):.3f}"

    def flags(self, index: QModelIndex | QPersistentModelIndex) -> Qt.ItemFlag:
        base = Qt.ItemFlag.ItemIsDropEnabled
        if not index.isValid():
            return base
        f = base | Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsSelectable | Qt.ItemFlag.ItemIsDragEnabled
        key = COLUMNS[index.column()][0]
        if key == QT_TR_NOOP("on"):
            f |= Qt.ItemFlag.ItemIsUserCheckable
        if key == "name":
            f |= Qt.ItemFlag.ItemIsEditable
        return f

    def setData(self, index: QModelIndex | QPersistentModelIndex, value: Any,  # noqa: N802
                role: int = Qt.ItemDataRole.EditRole) -> bool:
        if not index.isValid():
            return False
        row, key = index.row(), COLUMNS[index.column()][0]
        lay = self.layers[row]
        if key == QT_TR_NOOP("on") and role == Qt.ItemDataRole.CheckStateRole:
            on = Qt.CheckState(value) == Qt.CheckState.Checked if not isinstance(value, bool) else value
            new = [*self.layers]
            new[row] = lay.model_copy(update={"enabled": bool(on)})
            self.edit_requested.emit(new, f"{'Enable' if on else 'Disable'} layer {row + 1}", row)
            return True
        if key == "name" and role == Qt.ItemDataRole.EditRole:
            name = str(value).strip()
            if name == lay.name:
                return False
            new = [*self.layers]
            new[row] = lay.model_copy(update={"name": name})
            self.edit_requested.emit(new, f"Rename layer {row + 1}", row)
            return True
        return False

    # -- drag and drop (reorder) ------------------------------------------------------------------------
    def supportedDropActions(self) -> Qt.DropAction:  # noqa: N802
        return Qt.DropAction.MoveAction

    def supportedDragActions(self) -> Qt.DropAction:  # noqa: N802
        return Qt.DropAction.MoveAction

    def mimeTypes(self) -> list[str]:  # noqa: N802
        return [MIME]

    def mimeData(self, indexes: Any) -> QMimeData:  # noqa: N802
        rows = sorted({i.row() for i in indexes if i.isValid()})
        md = QMimeData()
        md.setData(MIME, json.dumps(rows).encode())
        return md

    def dropMimeData(self, data: QMimeData, action: Qt.DropAction, row: int, column: int,  # noqa: N802
                     parent: QModelIndex | QPersistentModelIndex) -> bool:
        if action == Qt.DropAction.IgnoreAction:
            return True
        if not data.hasFormat(MIME):
            return False
        rows = json.loads(bytes(data.data(MIME).data()).decode())
        if not rows:
            return False
        dest = row if row >= 0 else (parent.row() if parent.isValid() else len(self.layers))
        new_order = move_rows(len(self.layers), rows, dest)
        if new_order == list(range(len(self.layers))):
            return False
        moved = [self.layers[i] for i in new_order]
        first = new_order.index(rows[0])
        text = f"Move layer {rows[0] + 1} to position {first + 1}" if len(rows) == 1 else "Move layers"
        self.edit_requested.emit(moved, text, first)
        return False  # the panel rebuilds the rows from the new job; nothing for the view to remove


def move_rows(n: int, rows: list[int], dest: int) -> list[int]:
    """The order of ``range(n)`` after moving ``rows`` (kept in their order) before position ``dest``
    (an index of the original order; ``n``: to the end)."""
    moving = [r for r in sorted(set(rows)) if 0 <= r < n]
    rest = [i for i in range(n) if i not in moving]
    at = sum(1 for i in rest if i < dest)
    return rest[:at] + moving + rest[at:]
