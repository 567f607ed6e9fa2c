"""The workflow step bar on the left of the main window.

Mandrel → Winding → Payout → Machine → Time law → NC.  Each step owns one properties panel (a page
of the main window's properties stack); steps without a panel yet are shown disabled.
"""

from __future__ import annotations

from PySide6.QtCore import QSize, Qt, Signal
from PySide6.QtWidgets import QListWidget, QListWidgetItem, QWidget

from winder_gui.i18n import QT_TR_NOOP, tr

STEPS: tuple[tuple[str, str], ...] = (
    ("mandrel", QT_TR_NOOP("Mandrel")),
    ("winding", QT_TR_NOOP("Winding")),
    ("payout", QT_TR_NOOP("Payout")),
    ("machine", QT_TR_NOOP("Machine")),
    ("timelaw", QT_TR_NOOP("Time law")),
    ("nc", "NC"),
)


class StepBar(QListWidget):
    """A vertical list of the workflow steps; ``step_selected(key)`` when the user picks one."""

    step_selected = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("stepBar")
        self.setFixedWidth(118)
        self.setSpacing(2)
        self.setIconSize(QSize(0, 0))
        self.setStyleSheet(
            "QListWidget#stepBar { background: #2b3340; color: #e8ecf2; border: none; font-size: 11pt; }"
            "QListWidget#stepBar::item { padding: 10px 8px; border-bottom: 1px solid #3a4456; }"
            "QListWidget#stepBar::item:selected { background: #3f6fb5; color: white; }"
            "QListWidget#stepBar::item:disabled { color: #7b8596; }"
        )
        for i, (key, title) in enumerate(STEPS):
            item = QListWidgetItem(f"{i + 1}  {tr(title)}")
            item.setData(Qt.ItemDataRole.UserRole, key)
            self.addItem(item)
        self.set_available({"mandrel"})
        self.setCurrentRow(0)
        self.currentItemChanged.connect(self._on_current)

    def set_available(self, keys: set[str]) -> None:
        """Enable the steps in ``keys`` (those with a panel); the others are greyed out."""
        for i in range(self.count()):
            item = self.item(i)
            key = item.data(Qt.ItemDataRole.UserRole)
            flags = Qt.ItemFlag.ItemIsSelectable | Qt.ItemFlag.ItemIsEnabled
            item.setFlags(flags if key in keys else Qt.ItemFlag.NoItemFlags)
            item.setToolTip("" if key in keys else tr("{v0}: coming in a later version").format(v0=item.text()[3:]))

    def available(self) -> list[str]:
        """Keys of the enabled steps, in order."""
        return [
            self.item(i).data(Qt.ItemDataRole.UserRole)
            for i in range(self.count())
            if self.item(i).flags() & Qt.ItemFlag.ItemIsEnabled
        ]

    def current_step(self) -> str:
        """Key of the selected step."""
        item = self.currentItem()
        return str(item.data(Qt.ItemDataRole.UserRole)) if item is not None else "mandrel"

    def _on_current(self, cur: QListWidgetItem | None, _prev: QListWidgetItem | None) -> None:
        if cur is not None:
            self.step_selected.emit(str(cur.data(Qt.ItemDataRole.UserRole)))
