"""Application entry point (``winder`` without a sub-command, or ``winder JOB.toml``).

Start-up is kept fast: only PySide6, pyqtgraph and the light engine modules load before the
window shows; VTK/pyvista load when the 3D view first appears, cadquery only for STEP work.

``--selftest`` runs the job given (default: the pipe example) end to end — mandrel, winding line,
payout, axes, blocks, NC text — in the window's worker, prints what it got and exits 0, or 1 on any
error (use ``-platform offscreen`` or ``QT_QPA_PLATFORM=offscreen`` without a display)::

    winder: window shown after 0.812 s
    winder: mandrel shown after 0.905 s
    winder: pipeline done after 4.1 s: 612 blocks, program time 797.35 s, 18638 characters of linuxcnc NC

The environment variable ``WINDER_QUIT_WHEN_SHOWN`` makes the application quit on its own:
``shown`` as soon as the window is painted, ``ready`` once the first mandrel is plotted too,
``full`` (what ``--selftest`` does) after the whole pipeline.

On a normal start, autosaved copies left by an earlier session (e.g. a killed process) are offered
for restoring; the live copies of another winder running at the same time are not (each copy is
locked by its instance, see :class:`winder_gui.main_window.AutosaveOwner`), and this instance's
locks are released when its window closes.  Times count from the process start (Linux),
or from ``WINDER_T0`` (seconds since the epoch) if the launcher sets it.
"""

from __future__ import annotations

import gc
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

QUIT_ENV = "WINDER_QUIT_WHEN_SHOWN"
EXAMPLE_JOB = Path(__file__).resolve().parents[1] / "resources" / "examples" / "pipe.toml"
SELFTEST_TIMEOUT_S = 600


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
    from engine.cli import _process_defaults

    _process_defaults()  # before the job schema is built; also when started as python -m winder_gui.app
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from winder_gui.main_window import MainWindow

    args = list(sys.argv[1:] if argv is None else argv)
    app = QApplication.instance() or QApplication([sys.argv[0], *[a for a in args if a.startswith("-platform")]])
    app.setApplicationName("winder")
    app.setOrganizationName("winder")
    app.setDesktopFileName("winder")  # matches installer/winder.desktop (Wayland window grouping)
    from winder_gui.i18n import install_translator

    install_translator()  # resources/i18n/winder_<lang>.qm for $WINDER_LANG or the system locale, if any
    from PySide6.QtGui import QIcon

    from engine.resources import resource_path

    icon = resource_path("icons", "winder.svg")
    if icon.exists():
        app.setWindowIcon(QIcon(str(icon)))
    quit_when = os.environ.get(QUIT_ENV, "") or ("full" if "--selftest" in args else "")
    skip = {i + 1 for i, a in enumerate(args) if a == "-platform"}
    jobs = [a for i, a in enumerate(args) if not a.startswith("-") and i not in skip]
    if quit_when == "full" and not jobs:
        jobs = [str(EXAMPLE_JOB)]
    window = MainWindow(jobs[0] if jobs else None)
    if quit_when:
        window.confirm_discard = False
        window.auto_run = False
        _arm_selftest(app, window, quit_when, QTimer)
    window.show()
    import threading

    from winder_gui.tasks import warm_engine_imports

    # after the first mandrel is on screen, so the imports do not compete with start-up for the GIL;
    # then, on this (the GUI) thread, one full collection and gc.freeze(): the ~100k long-lived
    # objects of start-up and imports leave the cyclic collector (40-60 ms per full collection with
    # them, holding the GIL, 0.1 ms without)
    warm = threading.Thread(target=warm_engine_imports, name="winder-warm-imports", daemon=True)
    poll = QTimer(app)
    poll.setInterval(250)

    def _freeze_when_warm() -> None:
        if warm.ident is not None and not warm.is_alive():
            poll.stop()
            gc.collect()
            gc.freeze()

    poll.timeout.connect(_freeze_when_warm)
    QTimer.singleShot(3000, lambda: (warm.start(), poll.start()))
    if not quit_when:
        QTimer.singleShot(0, window.offer_autosaves)
    try:
        return app.exec()
    finally:
        from winder_gui.autosave import process_autosave_owner

        process_autosave_owner().release_all()  # normally done by the window's close already


def _arm_selftest(app, window, mode: str, timer_cls) -> None:  # noqa: ANN001 - Qt objects, imported lazily
    """Quit once the window is painted (``shown``), the first mandrel plotted (``ready``) or the whole
    pipeline ran and produced NC text (``full``); exit code 1 on any reported error."""
    start = _process_start()
    seen = {"shown": False, "ready": False, "done": False}
    # the exit code is ours alone: closing the window must not post a quit(0) that overrides exit(1)
    app.setQuitOnLastWindowClosed(False)

    def finish(code: int) -> None:
        if seen["done"]:
            return
        seen["done"] = True
        window.close()
        app.exit(code)

    def maybe_finish() -> None:
        if mode == "shown" and seen["shown"]:
            finish(0)
        elif mode == "ready" and seen["shown"] and seen["ready"]:
            finish(0)

    def shown() -> None:
        window.repaint()  # paint synchronously: the window is really on screen now
        print(f"winder: window shown after {time.time() - start:.3f} s", file=sys.stderr, flush=True)
        seen["shown"] = True
        maybe_finish()

    def ready(_data: object = None) -> None:
        if seen["ready"]:
            return
        seen["ready"] = True
        print(f"winder: mandrel shown after {time.time() - start:.3f} s", file=sys.stderr, flush=True)
        if mode == "full":
            window.run_pipeline_now()
        maybe_finish()

    def pipeline_done(res: object) -> None:
        if mode != "full":
            return
        text = getattr(res, "nc_text", None)
        blocks = getattr(res, "blocks", None)
        if not text or blocks is None or blocks.n == 0:
            failed("the pipeline produced no NC program")
            return
        print(f"winder: pipeline done after {time.time() - start:.1f} s: {blocks.n} blocks, program time "
              f"{blocks.total:.2f} s, {len(text)} characters of {res.post_name} NC", file=sys.stderr, flush=True)
        for w in window.run_warnings:
            print(f"winder: warning: {w[:300]}", file=sys.stderr, flush=True)
        finish(0)

    def failed(msg: str) -> None:
        print(f"winder: selftest failed: {msg}", file=sys.stderr, flush=True)
        finish(1)

    window.mandrel_updated.connect(ready)
    window.pipeline_done.connect(pipeline_done)
    window.error_reported.connect(failed)
    timer_cls.singleShot(0, shown)
    limit = SELFTEST_TIMEOUT_S if mode == "full" else 60
    timer_cls.singleShot(limit * 1000, lambda: failed(f"timed out after {limit} s"))


if __name__ == "__main__":  # python -m winder_gui.app [JOB.toml] [--selftest]
    sys.exit(main())
