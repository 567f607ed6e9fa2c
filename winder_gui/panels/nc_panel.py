"""Properties pages of the Time law and NC steps.

Time law: the job's ``[timelaw]`` fields plus a button that runs :func:`engine.timeparam.parametrize`
(tube, single DP and TOPP-RA) in a worker on the law chosen above the plot — the paper's 7-axis
example, or one of the job's own laws; the plots show the tube iterations and the three final laws.

NC: Run / Cancel of the whole pipeline, the program summary (post, blocks, program time), the
warnings of every stage, a preview of the program text and the export button (the window asks
"write anyway?" when the program violates a limit).
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtGui import QFont, QFontDatabase
from PySide6.QtWidgets import (
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QPlainTextEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from winder_gui import texts
from winder_gui.i18n import tr
from winder_gui.panels.section_panel import TIMELAW_FIELDS, SectionPanel
from winder_gui.texts import STALE_RESULTS

PREVIEW_LINES = 400
"""Lines of NC text shown in the preview (the whole program is written on export)."""


class TimeLawPanel(SectionPanel):
    """The job's time-law fields and the "Compute time law" button (paper example)."""

    compute_requested = Signal()

    def __init__(self) -> None:
        super().__init__(tr("Time law"), TIMELAW_FIELDS)
        box = QGroupBox(tr("Tube iterations"))
        v = QVBoxLayout(box)
        note = QLabel(tr("Runs the DP tube algorithm, a single DP and the TOPP-RA reference on the law chosen above "
                      "the plot: the paper's 7-axis example (Tables 4–5 limits), or one of the job's own laws "
                      "(after a run with method tube/dp/toppra). The method above sets the NC program's block "
                      "times: a time law over the job's axis path (tube, the default) or (17)/(18) ('blocks')."))
        note.setWordWrap(True)
        note.setStyleSheet("color: #555;")
        v.addWidget(note)
        self.compute_button = QPushButton(tr("Compute time law"))
        self.compute_button.setObjectName("timelaw.compute")
        self.compute_button.clicked.connect(self.compute_requested)
        v.addWidget(self.compute_button)
        self.summary = QLabel("")
        self.summary.setWordWrap(True)
        v.addWidget(self.summary)
        self.program_label = QLabel("")
        self.program_label.setObjectName("timelaw.program")
        self.program_label.setWordWrap(True)
        v.addWidget(self.program_label)
        self.lay.addWidget(box)
        self.finish()


class NCPanel(QWidget):
    """Run/Cancel, program summary, warnings, NC preview and export."""

    run_requested = Signal()
    cancel_requested = Signal()
    export_requested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(6, 6, 6, 6)
        lay.addWidget(QLabel(tr("<b>NC program</b>")))
        row = QHBoxLayout()
        self.run_button = QPushButton(tr("Run (F5)"))
        self.run_button.setObjectName("nc.run")
        self.cancel_button = QPushButton(tr("Cancel (Esc)"))
        self.cancel_button.setObjectName("nc.cancel")
        self.cancel_button.setEnabled(False)
        self.export_button = QPushButton(tr("Export NC…"))
        self.export_button.setObjectName("nc.export")
        self.export_button.setEnabled(False)
        for b in (self.run_button, self.cancel_button, self.export_button):
            row.addWidget(b)
        lay.addLayout(row)
        self.run_reason = QLabel("")
        self.run_reason.setObjectName("nc.run_reason")
        self.run_reason.setWordWrap(True)
        self.run_reason.setStyleSheet("color: #c01010;")
        lay.addWidget(self.run_reason)
        self.stale = QLabel(tr(STALE_RESULTS))
        self.stale.setObjectName("nc.stale")
        self.stale.setWordWrap(True)
        self.stale.setStyleSheet("color: #a05a00; font-weight: bold;")
        self.stale.hide()
        lay.addWidget(self.stale)
        self.summary = QLabel(tr("Not run yet."))
        self.summary.setObjectName("nc.summary")
        self.summary.setWordWrap(True)
        lay.addWidget(self.summary)
        lay.addWidget(QLabel(tr("Warnings")))
        self.warnings = QListWidget()
        self.warnings.setObjectName("nc.warnings")
        self.warnings.setWordWrap(True)
        self.warnings.setMaximumHeight(140)
        lay.addWidget(self.warnings)
        lay.addWidget(QLabel(tr("Program preview")))
        self.preview = QPlainTextEdit()
        self.preview.setObjectName("nc.preview")
        self.preview.setReadOnly(True)
        self.preview.setLineWrapMode(QPlainTextEdit.LineWrapMode.NoWrap)
        font = QFontDatabase.systemFont(QFontDatabase.SystemFont.FixedFont)
        font.setStyleHint(QFont.StyleHint.Monospace)
        self.preview.setFont(font)
        lay.addWidget(self.preview, 1)
        self.run_button.clicked.connect(self.run_requested)
        self.cancel_button.clicked.connect(self.cancel_requested)
        self.export_button.clicked.connect(self.export_requested)

    def set_run_state(self, can_run: bool, reason: str, running: bool) -> None:
        """Enable Run unless a field is bad (``reason``); Cancel while running."""
        self.run_button.setEnabled(can_run and not running)
        self.run_button.setToolTip(reason)
        self.run_reason.setText(tr("Run disabled: {reason}").format(reason=reason) if reason else "")
        self.cancel_button.setEnabled(running)

    def set_stale(self, stale: bool, reason: str = "") -> None:
        """Grey and label the summary, warnings and preview while they describe an earlier job."""
        self.stale.setText(reason or tr(STALE_RESULTS))
        self.stale.setVisible(stale)
        for w in (self.summary, self.warnings, self.preview):
            w.setEnabled(not stale)

    def set_export_state(self, reason: str) -> None:
        """Enable Export unless ``reason`` says why not (shown as the tooltip)."""
        self.export_button.setEnabled(not reason)
        self.export_button.setToolTip(reason)

    def set_result(self, res: Any, warns: list[str] | None = None) -> None:
        """Show the program summary, ``warns`` and the first lines of the NC text of ``res``."""
        self.warnings.clear()
        if res is None or res.nc_text is None:
            self.summary.setText(tr("Not run yet.") if res is None else tr("The pipeline stopped before the NC stage."))
            self.preview.setPlainText("")
            return
        b = res.blocks
        text = res.nc_text
        lines = text.count("\n") + 1
        self.summary.setText(
            tr("Post <b>{post_name}</b> ({extension}) · machine {name} · {n} blocks · {lines} lines<br>{v5}")
            .format(post_name=res.post_name, extension=res.extension, name=res.machine.name, n=b.n, lines=lines,
                    v5=texts.program_times(b.total, b.total_t17))
        )
        warns = list(warns or [])
        for w in warns:
            self.warnings.addItem(w)
        if not warns:
            self.warnings.addItem(tr("none"))
        head = text.replace("\r\n", "\n").split("\n", PREVIEW_LINES)  # some dialects end lines with CR LF
        shown = "\n".join(head[:PREVIEW_LINES])
        if len(head) > PREVIEW_LINES:
            shown += f"\n… ({lines - PREVIEW_LINES} more lines)"
        self.preview.setPlainText(shown)
