"""User-visible texts of the GUI in one place (so that a translation can be added later).

Messages built from data (numbers, names) are functions here; fixed labels are constants.  Engine
messages (:class:`engine.errors.InputError`) are shown as they are, with their place.
"""

from __future__ import annotations

from engine.errors import InputError

NO_DATA = "No data yet: run the pipeline (F5)."
STALE_RESULTS = "Out of date: the job changed since this run. Run again (F5)."
EXPORT_NO_PROGRAM = "there is no NC program yet: run the pipeline (F5)"
EXPORT_STALE = "the NC program is out of date: the job changed since the last run (run again, F5)"
EXPORT_RUNNING = "the pipeline is still running on the current job"
COMPUTING_TIMELAW = "Computing the time law (tube iterations, single DP, TOPP-RA bound) in the background…"
NOTHING_CHANGED = "Nothing was changed: the current job is still loaded."

CUT_MODE = {"down-cut": "down-cut (climb milling: the tool turns with the feed)",
            "up-cut": "up-cut (conventional milling: the tool turns against the feed)",
            "fixed part": "fixed part (i = 0)"}
"""Milling directions of the slot dialog: the seeds' ПР (попутное) is down-cut, ВР (встречное) up-cut."""
CUT_MODE_SHORT = {"down-cut": "down-cut", "up-cut": "up-cut", "fixed part": "fixed part"}


def program_times(total_s: float, without_jumps_s: float) -> str:
    """The NC step's program time (s): with every limit, and without the speed-jump limits (the paper's
    eq. (17) times; eq. (18) adds the jumps)."""
    return (f"Program time <b>{total_s:.2f} s</b> ({total_s / 60:.2f} min); without the speed-jump limits "
            f"{without_jumps_s:.2f} s")


def export_refused(reason: str) -> str:
    """Status-bar text when NC export is refused."""
    return f"Export disabled: {reason}"


def describe_error(exc: BaseException) -> str:
    """A user message for ``exc``: the place (file, line, field) and what is wrong; no traceback."""
    if isinstance(exc, InputError):
        loc = exc.location
        lines = []
        if loc.file:
            lines.append(f"File: {loc.file}")
        if loc.line is not None:
            lines.append(f"Line: {loc.line}")
        if loc.field:
            lines.append(f"Field: {loc.field}")
        lines.append("")
        lines.append(exc.message)
        return "\n".join(lines).strip()
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror or exc}"
    return f"Internal error ({type(exc).__name__}): {exc}\n\nPlease report this; the details are on the console."
