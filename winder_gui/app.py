"""Application entry point (``winder`` without a sub-command)."""

from __future__ import annotations

import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    """Start the Qt application; ``argv`` may hold a job file and ``--selftest``."""
    from PySide6.QtWidgets import QApplication

    from winder_gui.main_window import MainWindow

    args = list(sys.argv[1:] if argv is None else argv)
    app = QApplication.instance() or QApplication([sys.argv[0], *[a for a in args if a.startswith("-platform")]])
    app.setApplicationName("winder")
    app.setOrganizationName("winder")
    window = MainWindow()
    jobs = [a for a in args if not a.startswith("-")]
    if jobs:
        window.open_job(jobs[0])
    window.show()
    return app.exec()
