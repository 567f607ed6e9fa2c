"""Background execution of engine jobs.

The GUI thread never computes.  :class:`JobRunner` runs a plain engine function
``fn(*args, state=state)`` in a worker thread, where ``state`` implements
:class:`engine.state.State`; progress, partial results, completion and errors come back as Qt
signals, delivered on the GUI thread.  Starting a new job on a runner supersedes (cancels) the job in
flight, so rapid edits never queue up stale work.

cadquery/OCP is not thread-safe: every call into it goes through the single runner returned by
:func:`cad_runner`, whose jobs execute one at a time on one dedicated thread.

A worker shares the GIL with the GUI thread.  The GUI thread drops the GIL at most Qt calls and then
waits, while a worker runs Python code, until the worker is asked to let go: Python's switch interval,
5 ms by default.  Work with many Qt calls paid that wait many times over (the convoy effect: building a
pyqtgraph plot, 14 ms alone, took 93 ms next to a busy worker; 30 ms with a 1 ms interval, 24 ms with
0.2 ms).  :class:`JobRunner` lowers the interval to :data:`GUI_SWITCH_INTERVAL_S`.
"""

from __future__ import annotations

import gc
import itertools
import sys
import threading
import traceback
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QCoreApplication, QObject, QThread, QTimer, Signal, Slot

from engine.errors import Cancelled

GUI_SWITCH_INTERVAL_S = 0.0002
"""GIL switch interval (s) in the GUI process: how long a thread asking for the GIL waits before a worker
running Python code must hand it over.  Measured (benchmarks/bench_gui_pipeline.py, pressure vessel):
with 1 ms, one 128 ms heartbeat gap held 139 GIL waits of the GUI thread; with 0.2 ms the largest gap is
~60 ms.  The workers' run time did not change measurably."""


def _gui_friendly_switch_interval() -> None:
    if sys.getswitchinterval() > GUI_SWITCH_INTERVAL_S:
        sys.setswitchinterval(GUI_SWITCH_INTERVAL_S)


GC_INTERVAL_MS = 1000
"""How often the GUI thread runs Python's cyclic garbage collector (young generations; all of them
every :data:`GC_FULL_EVERY` ticks) -- see :func:`collect_garbage_on_the_gui_thread`."""
GC_FULL_EVERY = 30
_GC_TIMER: list[QTimer] = []


def collect_garbage_on_the_gui_thread() -> None:
    """Turn Python's automatic cyclic collector off and collect on a GUI-thread timer instead.

    The automatic collector runs in whichever thread allocates when a threshold is passed.  A worker
    that collects a cycle holding Qt wrappers (a closed window or dialog) destroys those Qt objects
    off the GUI thread, taking Qt's object mutexes while waiting for the GIL that the GUI thread holds
    as it deletes related objects: a deadlock (seen in the test suite: a worker deleting a QMenu while
    the GUI thread deleted its QActions).  Idempotent; call on the GUI thread with a QApplication.
    """
    app = QCoreApplication.instance()
    if _GC_TIMER or app is None or QThread.currentThread() is not app.thread():
        return
    gc.disable()
    timer = QTimer(app)
    timer.setInterval(GC_INTERVAL_MS)
    ticks = itertools.count(1)
    timer.timeout.connect(lambda: gc.collect(2 if next(ticks) % GC_FULL_EVERY == 0 else 1))
    timer.start()
    _GC_TIMER.append(timer)


class _WorkerState:
    """The engine ``state`` seen by a job running in a worker thread."""

    def __init__(self, emitter: _Emitter, job_id: int) -> None:
        self._emitter = emitter
        self._job_id = job_id
        self._cancel = threading.Event()

    def progress(self, fraction: float, message: str = "") -> None:
        self._emitter.progress.emit(self._job_id, float(fraction), str(message))

    def cancelled(self) -> bool:
        return self._cancel.is_set()

    def partial(self, result: Any) -> None:
        self._emitter.partial.emit(self._job_id, result)

    def cancel(self) -> None:
        self._cancel.set()


class _Emitter(QObject):
    progress = Signal(int, float, str)
    partial = Signal(int, object)
    done = Signal(int, object)
    failed = Signal(int, object, str)
    cancelled = Signal(int)


class _Thread(QThread):
    def __init__(self, target: Callable[[], None]) -> None:
        super().__init__()
        self._target = target

    def run(self) -> None:  # noqa: D102 - Qt override
        self._target()


class JobRunner(QObject):
    """Runs one engine job at a time in its own thread; a new job supersedes the current one.

    Signals carry only the results of the *current* job; those of superseded jobs are dropped.

    Signals
    -------
    progress(float, str), partial(object), finished(object), failed(BaseException, str traceback),
    cancelled(), busy(bool)
    """

    progress = Signal(float, str)
    partial = Signal(object)
    finished = Signal(object)
    failed = Signal(object, str)
    cancelled = Signal()
    busy = Signal(bool)

    _ids = itertools.count(1)

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        _gui_friendly_switch_interval()
        collect_garbage_on_the_gui_thread()
        self._emitter = _Emitter()
        self._emitter.progress.connect(self._on_progress)
        self._emitter.partial.connect(self._on_partial)
        self._emitter.done.connect(self._on_done)
        self._emitter.failed.connect(self._on_failed)
        self._emitter.cancelled.connect(self._on_cancelled)
        self._current: int | None = None
        self._state: _WorkerState | None = None
        self._threads: dict[int, _Thread] = {}

    # -- control -----------------------------------------------------------------------------
    def submit(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> int:
        """Start ``fn(*args, state=..., **kwargs)`` in a thread, cancelling the job in flight."""
        self.cancel()
        job_id = next(self._ids)
        st = _WorkerState(self._emitter, job_id)
        self._current, self._state = job_id, st

        def target() -> None:
            try:
                result = fn(*args, state=st, **kwargs)
            except Cancelled:
                self._emitter.cancelled.emit(job_id)
            except BaseException as exc:  # noqa: BLE001 - reported to the user, never swallowed
                self._emitter.failed.emit(job_id, exc, traceback.format_exc())
            else:
                if st.cancelled():
                    self._emitter.cancelled.emit(job_id)
                else:
                    self._emitter.done.emit(job_id, result)

        th = _Thread(target)
        th.finished.connect(lambda j=job_id: self._reap(j))
        self._threads[job_id] = th
        self.busy.emit(True)
        th.start()
        return job_id

    def cancel(self) -> None:
        """Ask the current job to stop; its results will be dropped."""
        if self._state is not None:
            self._state.cancel()
        if self._current is not None:
            cur = self._current
            self._current, self._state = None, None
            self.cancelled.emit()
            self.busy.emit(False)
            del cur

    def is_busy(self) -> bool:
        """True while a job whose results are still wanted is running."""
        return self._current is not None

    def wait(self, timeout_ms: int = 30000) -> bool:
        """Block until every thread of this runner has ended (for tests and shutdown)."""
        ok = True
        for th in list(self._threads.values()):
            ok = th.wait(timeout_ms) and ok
        return ok

    # -- signal plumbing (GUI thread) -----------------------------------------------------------
    @Slot(int, float, str)
    def _on_progress(self, job_id: int, fraction: float, message: str) -> None:
        if job_id == self._current:
            self.progress.emit(fraction, message)

    @Slot(int, object)
    def _on_partial(self, job_id: int, result: object) -> None:
        if job_id == self._current:
            self.partial.emit(result)

    @Slot(int, object)
    def _on_done(self, job_id: int, result: object) -> None:
        if job_id == self._current:
            self._current, self._state = None, None
            self.busy.emit(False)
            self.finished.emit(result)

    @Slot(int, object, str)
    def _on_failed(self, job_id: int, exc: object, tb: str) -> None:
        if job_id == self._current:
            self._current, self._state = None, None
            self.busy.emit(False)
            self.failed.emit(exc, tb)

    @Slot(int)
    def _on_cancelled(self, job_id: int) -> None:
        if job_id == self._current:
            self._current, self._state = None, None
            self.busy.emit(False)
            self.cancelled.emit()

    def _reap(self, job_id: int) -> None:
        th = self._threads.pop(job_id, None)
        if th is not None:
            th.deleteLater()


_CAD_LOCK = threading.Lock()


def cad_call(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Wrap ``fn`` so that calls into cadquery/OCP never overlap (OCP is not thread-safe)."""

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        with _CAD_LOCK:
            return fn(*args, **kwargs)

    wrapped.__name__ = getattr(fn, "__name__", "cad_call")
    wrapped.__doc__ = fn.__doc__
    return wrapped
