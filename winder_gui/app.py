"""Application entry point (``winder`` without a sub-command, or ``winder JOB.toml``).

Start-up is kept fast: only PySide6, pyqtgraph and the light engine modules load before the
window shows; VTK/pyvista load when the 3D view first appears, cadquery only for STEP work.

``--selftest`` (or the environment variable ``WINDER_QUIT_WHEN_SHOWN``) makes the application quit
on its own, printing start-up times to stderr::

    winder: window shown after 0.812 s
    winder: mandrel shown after 0.905 s

``WINDER_QUIT_WHEN_SHOWN=shown`` quits as soon as the window is painted, ``ready`` (the default for
``--selftest``) once the first mandrel is plotted too.  Times count from the process start (Linux),
or from ``WINDER_T0`` (seconds since the epoch) if the launcher sets it.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence

QUIT_ENV = "WINDER_QUIT_WHEN_SHOWN"


def _process_start() -> float:
    """Wall-clock time (s since the epoch) when this process started."""
    t0 = os.environ.get("WINDER_T0")
    if t0:
        try:
            return float(t0)
        except ValueError:
            pass
    try:  # Linux: start time in clock ticks after boot
        with open("/proc/self/stat", encoding="ascii") as f:
            ticks = float(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/stat", encoding="ascii") as f:
            btime = next(float(line.split()[1]) for line in f if line.startswith("btime"))
        return btime + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return time.time() - time.process_time()


def main(argv: Sequence[str] | None = None) -> int:
    """Start the Qt application; ``argv`` may hold a job file and ``--selftest``."""
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from winder_gui.main_window import MainWindow

    args = list(sys.argv[1:] if argv is None else argv)
    app = QApplication.instance() or QApplication([sys.argv[0], *[a for a in args if a.startswith("-platform")]])
    app.setApplicationName("winder")
    app.setOrganizationName("winder")
    quit_when = os.environ.get(QUIT_ENV, "") or ("ready" if "--selftest" in args else "")
    jobs = [a for a in args if not a.startswith("-")]
    window = MainWindow(jobs[0] if jobs else None)
    if quit_when:
        window.confirm_discard = False
        _arm_selftest(app, window, quit_when, QTimer)
    window.show()
    return app.exec()


def _arm_selftest(app, window, mode: str, timer_cls) -> None:  # noqa: ANN001 - Qt objects, imported lazily
    """Quit once the window is painted (``shown``) or also the first mandrel plotted (``ready``)."""
    start = _process_start()
    seen = {"shown": False, "ready": False}

    def finish(code: int) -> None:
        window.close()
        app.exit(code)

    def shown() -> None:
        window.repaint()  # paint synchronously: the window is really on screen now
        print(f"winder: window shown after {time.time() - start:.3f} s", file=sys.stderr, flush=True)
        seen["shown"] = True
        if mode == "shown" or seen["ready"]:
            finish(0)

    def ready(_data: object = None) -> None:
        if seen["ready"]:
            return
        seen["ready"] = True
        print(f"winder: mandrel shown after {time.time() - start:.3f} s", file=sys.stderr, flush=True)
        if seen["shown"]:
            finish(0)

    def failed(msg: str) -> None:
        print(f"winder: selftest failed: {msg}", file=sys.stderr, flush=True)
        finish(1)

    window.mandrel_updated.connect(ready)
    window.error_reported.connect(failed)
    timer_cls.singleShot(0, shown)
    timer_cls.singleShot(60_000, lambda: failed("timed out after 60 s"))
