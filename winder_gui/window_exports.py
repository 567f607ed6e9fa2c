"""NC and report export of the main window: what is exported is always the run on screen (refused,
with the reason in the status bar, while the job is invalid or changed since the run)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtWidgets import QMessageBox

from engine.errors import InputError
from winder_gui import texts, window_menus
from winder_gui.i18n import tr

if TYPE_CHECKING:
    from winder_gui.main_window import MainWindow


def export_nc(w: MainWindow, path: str | Path, force: bool | None = None) -> bool:
    """Write the NC program of the last run to ``path`` (in a worker, atomically).

    Refused, with the reason in the status bar, while the job is invalid or the program is out of
    date (an edit since the run).  When the program violates a limit, ``force=None`` asks "write
    anyway?"; ``True`` writes, ``False`` does not.  Returns True when the write was started.
    """
    why = w.export_block_reason()
    if why:
        w._status(texts.export_refused(why), error=True)
        if w.result is None or w.result.nc_text is None:
            w.report_dialog(tr("Export NC program"), InputError(why))
        return False
    res = w.result
    p = Path(path)
    if not p.suffix:
        p = p.with_suffix(res.extension)
    viol = w.doc.violations()
    if viol and force is None:
        ans = QMessageBox.question(
            w, tr("Write anyway?"),
            tr("The program violates {v0} limit(s), e.g.\n{v1}\n\nWrite it anyway?")
            .format(v0=len(viol), v1=getattr(viol[0], 'message', viol[0])),
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
        force = ans == QMessageBox.StandardButton.Yes
        if not force:
            w._status(tr("NC program not written (it violates limits)"))
            return False
    w.ctl.write_nc(p, bool(force))
    return True


def export_report(w: MainWindow, path: str | Path) -> bool:
    """Write the job report (PDF or HTML by suffix) of the run on screen, in a worker; refused, with
    the reason in the status bar, when there is no run or the job changed since (as NC export)."""
    why = w.export_block_reason()
    if why:
        w._status(texts.export_refused(why), error=True)
        return False
    p = Path(path)
    if p.suffix.lower() not in (".pdf", ".html", ".htm"):
        p = p.with_suffix(".pdf")
    w.ctl.write_report(p)
    w._status(tr("Writing the report {name}…").format(name=p.name))
    return True


def action_export_report(w: MainWindow) -> None:
    if w.export_block_reason():
        w.export_report("")
        return
    path = window_menus.ask_report_path(w)
    if path:
        w.export_report(path)


def action_export_nc(w: MainWindow) -> None:
    why = w.export_block_reason()
    if why:
        w.export_nc("")
        return
    path = window_menus.ask_nc_path(w, w.result.extension)
    if path:
        w.export_nc(path)
