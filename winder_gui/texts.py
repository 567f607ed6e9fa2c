"""Shared user-visible messages of the GUI (translated through :mod:`winder_gui.i18n`).

Messages built from data (numbers, names) are functions here; fixed labels are constants marked
``QT_TR_NOOP`` and shown through ``tr(texts.NAME)``.  Engine
messages (:class:`engine.errors.InputError`) are shown as they are, with their place.
"""

from __future__ import annotations

from engine.errors import InputError
from winder_gui.i18n import QT_TR_NOOP, tr

NO_DATA = QT_TR_NOOP("No data yet: run the pipeline (F5).")
STALE_RESULTS = QT_TR_NOOP("Out of date: the job changed since this run. Run again (F5).")
EXPORT_NO_PROGRAM = QT_TR_NOOP("there is no NC program yet: run the pipeline (F5)")
EXPORT_STALE = QT_TR_NOOP("the NC program is out of date: the job changed since the last run (run again, F5)")
EXPORT_RUNNING = QT_TR_NOOP("the pipeline is still running on the current job")
COMPUTING_TIMELAW = QT_TR_NOOP("Computing the time law (tube iterations, single DP, TOPP-RA) in the background…")
NOTHING_CHANGED = QT_TR_NOOP("Nothing was changed: the current job is still loaded.")

CUT_MODE = {"down-cut": QT_TR_NOOP("down-cut (climb milling: the tool turns with the feed)"),
            "up-cut": QT_TR_NOOP("up-cut (conventional milling: the tool turns against the feed)"),
            "fixed part": QT_TR_NOOP("fixed part (i = 0)")}
"""Milling directions of the slot dialog: the seeds' ПР (попутное) is down-cut, ВР (встречное) up-cut."""
CUT_MODE_SHORT = {"down-cut": QT_TR_NOOP("down-cut"), "up-cut": QT_TR_NOOP("up-cut"),
                  "fixed part": QT_TR_NOOP("fixed part")}


def program_times(total_s: float, without_jumps_s: float) -> str:
    """The NC step's program time (s): with every limit, and without the speed-jump limits (the paper's
    eq. (17) times; eq. (18) adds the jumps)."""
    return tr("Program time <b>{total_s:.2f} s</b> ({total_min:.2f} min); without the speed-jump limits "
              "{without_jumps_s:.2f} s").format(total_s=total_s, total_min=total_s / 60,
                                                 without_jumps_s=without_jumps_s)


def export_refused(reason: str) -> str:
    """Status-bar text when NC export is refused."""
    return tr("Export disabled: {reason}").format(reason=reason)


def describe_error(exc: BaseException) -> str:
    """A user message for ``exc``: the place (file, line, field) and what is wrong; no traceback."""
    if isinstance(exc, InputError):
        loc = exc.location
        lines = []
        if loc.file:
            lines.append(tr("File: {file}").format(file=loc.file))
        if loc.line is not None:
            lines.append(tr("Line: {line}").format(line=loc.line))
        if loc.field:
            lines.append(tr("Field: {field}").format(field=loc.field))
        lines.append("")
        lines.append(exc.message)
        return "\n".join(lines).strip()
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror or exc}"
    return tr("Internal error ({kind}): {exc}\n\nPlease report this; the details are on the console.").format(
        kind=type(exc).__name__, exc=exc)
