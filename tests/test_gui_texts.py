"""Every visible string of the GUI is English (issue 18, point 5): the seeds' Russian terms are
translated (ПР -> down-cut, ВР -> up-cut), and user-visible texts have one home (winder_gui.texts)."""

from __future__ import annotations

import re
from pathlib import Path

import pyqtgraph as pg

ROOT = Path(__file__).resolve().parents[1]
CYRILLIC = re.compile("[\u0400-\u04ff]")


def test_no_cyrillic_in_the_gui_sources_outside_the_glossary() -> None:
    bad = []
    for p in sorted((ROOT / "winder_gui").rglob("*.py")):
        if p.name == "texts.py":  # the glossary names the seeds' terms in comments
            continue
        for n, line in enumerate(p.read_text("utf-8").splitlines(), 1):
            if CYRILLIC.search(line):
                bad.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not bad, "\n".join(bad)


def _widget_texts(root) -> list[str]:
    from PySide6.QtWidgets import QAbstractButton, QComboBox, QLabel, QTableWidget, QWidget

    out = []
    for w in root.findChildren(QWidget):
        out.append(w.toolTip())
        if isinstance(w, QLabel | QAbstractButton):
            out.append(w.text())
        if isinstance(w, QComboBox):
            out += [w.itemText(i) for i in range(w.count())]
        if isinstance(w, QTableWidget):
            out += [w.horizontalHeaderItem(j).text() for j in range(w.columnCount()) if w.horizontalHeaderItem(j)]
            out += [w.item(i, j).text() for i in range(w.rowCount()) for j in range(w.columnCount()) if w.item(i, j)]
    for item in root.findChildren(pg.PlotWidget):
        pi = item.getPlotItem()
        out += [pi.titleLabel.text, *[pi.getAxis(s).labelText for s in ("left", "bottom")]]
        if pi.legend is not None:
            out += [lab.text for _s, lab in pi.legend.items]
        out += [it.textItem.toPlainText() for it in pi.items if isinstance(it, pg.TextItem)]
    return [t for t in out if t]


def test_slot_dialog_shows_english_cut_directions(qtbot) -> None:
    from winder_gui.dialogs.slotting import SlotDialog

    d = SlotDialog()
    qtbot.addWidget(d)
    assert d.wait_idle()
    texts = _widget_texts(d)
    assert not [t for t in texts if CYRILLIC.search(t)]
    joined = " ".join(texts)
    assert "down-cut" in joined and "up-cut" in joined
    d.wait_idle()
