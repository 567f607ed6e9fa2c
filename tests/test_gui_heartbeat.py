"""The GUI thread never blocks for more than 100 ms while the engine works (issue 9), pytest-qt, offscreen.

A 10 ms QTimer heartbeat ticks all through a full pipeline run in the main window (the payout-law
comparison and every view update included) on the pipe and the pressure-vessel examples.  Between two
ticks, two things must stay under 100 ms:

* the GUI thread's own CPU time (what the window itself does in one event-loop turn), and
* the wall-clock gap, less the time this machine's other processes took from ours.

Why the correction: this machine is shared (two cores, often a load of 3-6 from other jobs), so a wall
gap mixes what the program does (GUI work; a worker holding the GIL) with waiting for a core.  A gap
counts as the program's own ("own gap") only as far as both of these account for it:

* the wall gap less the time the GUI thread was ready to run but waited for a CPU (Linux
  ``/proc/thread-self/schedstat``, second field; 0 where the kernel does not provide it), and
* the CPU time of the whole process in the gap: the GUI thread waiting for the GIL held by a running
  worker keeps the process busy (so an idle machine gets the plain wall-clock check), while a GIL holder
  that waits for a core, or the GUI thread itself waiting for one, does not.

The alternatives were weaker: a re-run when ``os.getloadavg()`` is high does not help under a sustained
load; summing every thread's schedstat per tick (tried first) reads a file per thread, and each read
releases the GIL, which the GUI thread then waits up to a switch interval to get back from a busy
worker: the measurement adds to the gaps it measures.  Here a tick reads one open file and three clocks.  What the
correction cannot see: the GUI thread blocked on I/O or a lock while the process idles (the GUI CPU
assertion does not see it either).

Before measuring, the engine's modules are imported as the app does in the background after start-up
(:func:`winder_gui.tasks.warm_engine_imports`): an import holds the GIL while it compiles (no ``.pyc``
here: ``PYTHONDONTWRITEBYTECODE``) and runs the module's code; done lazily inside the first run they
made gaps of 80-120 ms.  That is start-up, not engine work.

Kept fast: both examples together take ~7 s.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"
LIMIT_S = 0.100


def _schedstat_fd() -> int | None:
    """An open descriptor on this thread's ``schedstat`` (CPU time, time waited for a CPU, in ns)."""
    try:
        return os.open("/proc/thread-self/schedstat", os.O_RDONLY)
    except OSError:
        return None


def _waited_ns(fd: int | None) -> int:
    if fd is None:
        return 0
    try:
        return int(os.pread(fd, 128, 0).split()[1])
    except (OSError, IndexError, ValueError):
        return 0


@dataclass(frozen=True)
class Gap:
    """One interval between two heartbeat ticks (s)."""

    at: float
    """Start, from :meth:`Heartbeat.start`."""
    wall: float
    cpu: float
    """CPU time of the GUI thread."""
    waited: float
    """Time the GUI thread was ready to run but waited for a CPU (another process had it)."""
    process_cpu: float
    """CPU time of the whole process (all threads)."""
    where: str = ""
    """For gaps over 50 ms: where the other Python threads are at the tick that ends the gap."""

    @property
    def own(self) -> float:
        """The part of the gap this process accounts for (see the module docstring)."""
        return min(self.wall - self.waited, self.process_cpu)


def _where() -> str:
    """The innermost frames of every other Python thread (QThread workers are not in ``threading``)."""
    out = []
    for ident, frame in sys._current_frames().items():
        if ident == threading.main_thread().ident:
            continue
        frames = []
        while frame is not None and len(frames) < 3:
            frames.append(f"{Path(frame.f_code.co_filename).name}:{frame.f_lineno} {frame.f_code.co_name}")
            frame = frame.f_back
        out.append(" < ".join(frames))
    return " | ".join(out)


class Heartbeat:
    """A QTimer ticking every ``interval_ms`` on the GUI thread, recording every :class:`Gap`.

    Create, start and stop it on the GUI thread.  Also records the garbage collections (which hold the
    GIL throughout, whichever thread runs them).
    """

    def __init__(self, interval_ms: int = 10) -> None:
        self.gaps: list[Gap] = []
        self.collections: list[tuple[float, float, int, str]] = []
        """Garbage collections during the run: (start, duration (s), generation, thread name)."""
        self.timer = QTimer()
        self.timer.setInterval(interval_ms)
        self.timer.timeout.connect(self._tick)
        self._t0 = 0.0
        self._last = (0.0, 0.0, 0.0, 0)
        self._fd: int | None = None
        self._gc_start: dict[int, float] = {}

    def start(self) -> None:
        self.gaps.clear()
        self.collections.clear()
        self._fd = _schedstat_fd()
        self._t0 = time.perf_counter()
        self._last = (self._t0, time.thread_time(), time.process_time(), _waited_ns(self._fd))
        gc.callbacks.append(self._gc)
        self.timer.start()

    def stop(self) -> None:
        self.timer.stop()
        if self._gc in gc.callbacks:
            gc.callbacks.remove(self._gc)
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _gc(self, phase: str, info: dict) -> None:
        """A collection holds the GIL throughout, whichever thread triggers it."""
        key = threading.get_ident()
        if phase == "start":
            self._gc_start[key] = time.perf_counter()
        elif key in self._gc_start:
            t = self._gc_start.pop(key)
            self.collections.append((t - self._t0, time.perf_counter() - t, info["generation"],
                                     threading.current_thread().name))

    def _tick(self) -> None:
        now, cpu, pcpu, waited = time.perf_counter(), time.thread_time(), time.process_time(), _waited_ns(self._fd)
        t, c, pc, w = self._last
        where = _where() if now - t > 0.05 else ""
        self.gaps.append(Gap(t - self._t0, now - t, cpu - c, (waited - w) / 1e9, pcpu - pc, where))
        self._last = (now, cpu, pcpu, waited)

    def worst(self, n: int = 5) -> str:
        """The ``n`` largest gaps (by own time) and the longest garbage collections, for messages."""
        top = sorted(self.gaps, key=lambda g: -g.own)[:n]
        gaps = "; ".join(f"at {g.at:.2f} s wall {g.wall * 1e3:.0f} ms (own {g.own * 1e3:.0f}), GUI CPU "
                         f"{g.cpu * 1e3:.0f} ms, GUI waited for a CPU {g.waited * 1e3:.0f} ms, process CPU "
                         f"{g.process_cpu * 1e3:.0f} ms" + (f", other threads now in: {g.where}" if g.where else "")
                         for g in top)
        cols = ", ".join(f"gen {gen} in {name} at {t:.2f} s: {d * 1e3:.0f} ms"
                         for t, d, gen, name in sorted(self.collections, key=lambda c: -c[1])[:3])
        return f"{gaps}; longest garbage collections: {cols or '-'}"

    def summary(self) -> str:
        g = self.gaps
        return (f"{len(g)} ticks, max wall gap {max(x.wall for x in g) * 1e3:.0f} ms, max own gap "
                f"{max(x.own for x in g) * 1e3:.0f} ms, max GUI-thread CPU {max(x.cpu for x in g) * 1e3:.0f} ms")


def full_run_with_heartbeat(w, timeout_s: float = 180.0) -> Heartbeat:  # noqa: ANN001 - MainWindow
    """Run the whole pipeline in ``w`` (plus the law comparison and every view update) under a heartbeat."""
    hb = Heartbeat()
    hb.start()
    w.run_pipeline_now()
    deadline = time.monotonic() + timeout_s
    while (w.busy() or w.views_pending()) and time.monotonic() < deadline:
        QApplication.processEvents()
        time.sleep(0.001)
    hb.stop()
    return hb


@pytest.mark.parametrize("example", ["pipe", "pressure_vessel"])
def test_gui_thread_heartbeat_during_a_full_run(qtbot, example: str) -> None:
    """Between two 10 ms ticks: GUI-thread CPU < 100 ms and wall gap less load < 100 ms (see the module)."""
    from winder_gui.main_window import MainWindow
    from winder_gui.tasks import warm_engine_imports
    from winder_gui.workers import GUI_SWITCH_INTERVAL_S

    warm_engine_imports()
    w = MainWindow(EXAMPLES / f"{example}.toml")
    assert sys.getswitchinterval() <= GUI_SWITCH_INTERVAL_S  # set by the window's JobRunners
    w.confirm_discard = False
    w.auto_run = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    # as the app does once its imports are warm (winder_gui.app): long-lived objects leave the cyclic
    # collector; here also the earlier tests' (a timed full collection took 540 ms with them under load)
    gc.collect()
    gc.freeze()
    hb = full_run_with_heartbeat(w)
    try:
        assert not w.busy() and w.result is not None and w.result.nc_text
        assert len(hb.gaps) > 50
        print(f"heartbeat {example}: {hb.summary()}")
        assert max(g.cpu for g in hb.gaps) < LIMIT_S, hb.worst()
        assert max(g.own for g in hb.gaps) < LIMIT_S, hb.worst()
    finally:
        gc.unfreeze()
        w.wait_idle(120000)
        w.close()
