"""The run controller: every worker of a window and when the computations run.

:class:`RunController` owns the :class:`~winder_gui.workers.JobRunner` threads (mandrel build, file
I/O, pipeline, payout-law comparison, time law, NC writing), the debounce of edits and of automatic
re-runs, and records outcomes in the :class:`~winder_gui.document.JobDocument` (the result, the job
it was computed for, whether a run or an edit is in flight — hence the staleness of the results).
Views react to its signals; it never touches a widget.

Every mandrel edit makes a *candidate* job; the mandrel is built from it in a worker (never on the
GUI thread), and only a candidate that builds is committed to the document.  Run (F5) calls
:func:`engine.pipeline.run_pipeline` in a worker with ``previous=result``, so only the stages
downstream of an edit re-run; after the first run, edits re-run automatically (debounced,
superseding the run in flight).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QEventLoop, QObject, QTimer, Signal
from PySide6.QtWidgets import QApplication

from engine.job import Job
from winder_gui.document import JobDocument
from winder_gui.tasks import build_task, export_task, job_timelaw_task
from winder_gui.workers import JobRunner

EDIT_DEBOUNCE_MS = 150
"""Quiet time after the last mandrel edit before the candidate is built."""
RUN_DEBOUNCE_MS = 300
"""Quiet time after the last edit before the pipeline re-runs."""


class RunController(QObject):
    """The workers of one document and the run state (see the module docstring).

    ``block_reason`` returns why the job may not run ('' when it may): the first bad field shown
    by any panel.

    Signals
    -------
    built(purpose, BuildResult), build_failed(purpose, exc, traceback):
        A mandrel build (open, new, import, edit, points, undo, restore) finished / failed.
    run_started(), run_done(RunOutput), run_failed(exc, traceback), run_cancelled(), partial(result):
        The pipeline.
    progress(fraction, message):
        Progress of the pipeline or time law.
    busy_changed():
        A worker started or stopped.
    laws_done(dict), laws_failed(exc, tb), timelaw_done(result), timelaw_failed(exc, tb):
        Payout-law comparison and time-law computations.
    nc_written(Path), exported(Path), io_failed(title, exc, tb):
        File writes.
    """

    built = Signal(str, object)
    build_failed = Signal(str, object, str)
    build_progress = Signal(float, str)
    run_started = Signal()
    run_done = Signal(object)
    run_failed = Signal(object, str)
    run_cancelled = Signal()
    partial = Signal(object)
    progress = Signal(float, str)
    busy_changed = Signal()
    laws_done = Signal(object)
    laws_failed = Signal(object, str)
    timelaw_done = Signal(object)
    timelaw_failed = Signal(object, str)
    nc_written = Signal(object)
    layer_data_done = Signal(object)
    nc_read = Signal(object)
    exported = Signal(object)
    io_failed = Signal(str, object, str)

    def __init__(self, doc: JobDocument, block_reason: Callable[[], str], parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.block_reason = block_reason
        self.auto_run = True
        """Re-run the pipeline after every edit once it has run for this job."""
        self.purpose = ""
        self.explicit = False
        """The run in flight was asked for (F5), not started by an edit."""
        self._pending: tuple[Job, str] | None = None
        self._run_after_build = False
        self._superseding = False
        self._run_job: Job | None = None
        self._partial: Any = None
        self._laws_key = ""
        self.last_output: Any = None
        """The worker's output of the last finished run (a layered job re-uses its layer views)."""
        self.run_t0 = 0.0
        self._closed = False

        self.runner = self._runner(self._on_built, self._on_build_failed)
        self.runner.progress.connect(self.build_progress)
        self.io_runner = self._runner(self.exported.emit,
                                      lambda exc, tb: self.io_failed.emit("Export failed", exc, tb))
        self.pipe_runner = self._runner(self._on_pipe_done, self._on_pipe_failed)
        self.pipe_runner.cancelled.connect(self._on_pipe_cancelled)
        self.pipe_runner.partial.connect(self._on_pipe_partial)
        self.pipe_runner.progress.connect(self.progress)
        self.laws_runner = self._runner(self.laws_done.emit, self.laws_failed.emit)
        self.tl_runner = self._runner(self.timelaw_done.emit, self.timelaw_failed.emit)
        self.layer_runner = self._runner(self.layer_data_done.emit,
                                         lambda exc, tb: self.io_failed.emit("Layer view not computed", exc, tb))
        """Views of one laminate layer computed on demand (its coverage map) -- winder_gui.laminate_view."""
        self.layer_runner.progress.connect(self.progress)
        self.tl_runner.progress.connect(self.progress)
        self.nc_runner = self._runner(self.nc_written.emit,
                                      lambda exc, tb: self.io_failed.emit("NC program not written", exc, tb))
        self.read_runner = self._runner(self.nc_read.emit,
                                        lambda exc, tb: self.io_failed.emit("NC program not read", exc, tb))
        self.edit_timer = self._timer(EDIT_DEBOUNCE_MS, self.submit_pending)
        self.run_timer = self._timer(RUN_DEBOUNCE_MS, lambda: self.run_now(explicit=False))
        doc.edited.connect(self.after_edit)
        doc.rebuild_requested.connect(lambda job: self.build("undo", build_task, job, self.doc.path))

    def _runner(self, done: Callable[..., Any], failed: Callable[..., Any]) -> JobRunner:
        r = JobRunner(self)
        r.finished.connect(done)
        r.failed.connect(failed)
        r.busy.connect(self._on_busy)
        return r

    def _timer(self, ms: int, slot: Callable[[], Any]) -> QTimer:
        t = QTimer(self)
        t.setSingleShot(True)
        t.setInterval(ms)
        t.timeout.connect(slot)
        return t

    def runners(self) -> tuple[JobRunner, ...]:
        return (self.runner, self.io_runner, self.pipe_runner, self.laws_runner, self.tl_runner, self.nc_runner,
                self.read_runner, self.layer_runner)

    def _on_busy(self, _busy: bool = False) -> None:
        self.doc.set_running(self.pipe_runner.is_busy())
        self.doc.set_edits_pending(self._pending is not None or self.runner.is_busy() or self._run_after_build)
        self.busy_changed.emit()

    # -- mandrel builds --------------------------------------------------------------------------
    def build(self, purpose: str, fn: Callable[..., Any], *args: Any) -> None:
        """Build a candidate job in the worker (``fn`` returns a :class:`~winder_gui.tasks.BuildResult`)."""
        if purpose in ("open", "new", "import", "restore", "undo"):
            self.drop_pending()
        self.purpose = purpose
        self.runner.submit(fn, *args)
        self._on_busy()

    def queue_edit(self, job: Job, purpose: str) -> None:
        """Build ``job`` after :data:`EDIT_DEBOUNCE_MS` of quiet (a newer edit replaces it)."""
        self._pending = (job, purpose)
        self.edit_timer.start()
        self.doc.set_edits_pending(True)

    def drop_pending(self) -> None:
        self.edit_timer.stop()
        self._pending = None

    def submit_pending(self) -> None:
        if self._pending is None:
            return
        job, purpose = self._pending
        self._pending = None
        self.build(purpose, build_task, job, self.doc.path)

    def _on_built(self, res: Any) -> None:
        purpose = self.purpose
        self.built.emit(purpose, res)
        self._on_busy()
        if self._run_after_build:
            self._run_after_build = False
            self.run_now(explicit=self.explicit)

    def _on_build_failed(self, exc: BaseException, tb: str) -> None:
        self._run_after_build = False
        self.build_failed.emit(self.purpose, exc, tb)
        self._on_busy()

    def export_mandrel(self, mandrel: Any, path: Path) -> None:
        self.io_runner.submit(export_task, mandrel, path)

    # -- pipeline --------------------------------------------------------------------------------
    def after_edit(self) -> None:
        """After an edit: re-run (debounced) when automatic runs are on and the job has results."""
        self._on_busy()
        if self.auto_run and self.doc.result is not None and not self.block_reason():
            self.run_timer.start()

    def run_now(self, upto: str = "nc", explicit: bool = True) -> bool:
        """Run the pipeline on the current job in the worker, re-using the last result's valid stages.

        Returns False when a field is bad (:attr:`block_reason`).  A mandrel edit still being
        applied runs first.
        """
        if self.block_reason():
            return False
        self.run_timer.stop()
        self.explicit = explicit
        if self.edit_timer.isActive() or self.runner.is_busy():
            self._run_after_build = True
            return True
        doc = self.doc
        self._run_job = doc.job
        self.run_t0 = time.monotonic()
        self._partial = None
        self._superseding = True
        try:
            from winder_gui.laminate_tasks import run_task  # single line or laminate

            self.pipe_runner.submit(run_task, doc.job, doc.path, doc.result, upto, previous_views=self.last_output)
        finally:
            self._superseding = False
        self._on_busy()
        self.run_started.emit()
        return True

    def cancel(self) -> None:
        """Stop every computation in flight (pipeline, law comparison, time law); results are dropped."""
        self.run_timer.stop()
        self._run_after_build = False
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner, self.layer_runner):
            if r.is_busy():
                r.cancel()
        self._on_busy()

    def clear(self) -> None:
        """Forget the results (a new document): computations cancelled."""
        self.cancel()
        self._partial = None
        self._laws_key = ""
        self.last_output = None

    def _on_pipe_partial(self, res: Any) -> None:
        from engine.pipeline import PipelineResult

        if isinstance(res, PipelineResult) and self._run_job is not None and self._run_job.is_single_line:
            self._partial = res  # (a laminate's layers report their own partial results: not the job's)
            self.partial.emit(res)

    def _on_pipe_done(self, out: Any) -> None:
        res = out.result
        self._partial = None
        self.last_output = out
        self.doc.set_running(False)
        self.doc.set_result(res, self._run_job, list(out.warnings), list(out.violations))
        eye_key = getattr(res, "keys", {}).get("payout", "")  # a laminate has no single eye path to compare
        if eye_key and eye_key != self._laws_key and res.eye_circuit is not None and not self._closed:
            self._laws_key = eye_key
            from winder_gui.tasks import laws_task

            self.laws_runner.submit(laws_task, res)
        self._on_busy()
        self.run_done.emit(out)

    def _keep_partial(self) -> None:
        if self._partial is not None:
            self.doc.set_result(self._partial, self._run_job)
            self._partial = None

    def _on_pipe_failed(self, exc: BaseException, tb: str) -> None:
        self._keep_partial()
        self.run_failed.emit(exc, tb)
        self._on_busy()

    def _on_pipe_cancelled(self) -> None:
        if self._superseding:
            return
        self._keep_partial()
        self.run_cancelled.emit()
        self._on_busy()

    # -- time law, NC --------------------------------------------------------------------------------
    def compute_job_timelaw(self, index: int, result: Any = None) -> None:
        """DP and TOPP-RA on the time law ``index`` of ``result`` (default: the current single-line
        result; for a laminate, the shown layer's) in the worker."""
        self.tl_runner.submit(job_timelaw_task, self.doc.result if result is None else result, index)

    def compute_paper_timelaw(self) -> None:
        """The tube, DP and TOPP-RA laws of the paper's example with the job's settings (worker)."""
        from winder_gui.tasks import timelaw_task

        self.tl_runner.submit(timelaw_task, self.doc.job.timelaw)

    def write_nc(self, path: Path, force: bool) -> None:
        """Write the NC program of the (current) result to ``path`` in the worker."""
        from winder_gui.laminate_tasks import is_laminate, write_laminate_task
        from winder_gui.tasks import write_task

        task = write_laminate_task if is_laminate(self.doc.result) else write_task
        self.nc_runner.submit(task, self.doc.result, path, bool(force))

    def read_nc(self, path: Path) -> None:
        """Read the NC program ``path`` back on the job's machine in the worker (File > Open NC program)."""
        from winder_gui.tasks import readback_task

        self.read_runner.submit(readback_task, Path(path), self.doc.job, self.doc.path, self.doc.result)

    def write_report(self, path: Path) -> None:
        """Write the job report of the (current) result to ``path`` (.pdf/.html) in the worker."""
        from winder_gui.tasks import report_task

        self.nc_runner.submit(report_task, self.doc.result, path, self.doc.path)

    def export_block_reason(self) -> str:
        """Why Export NC is refused now ('' when allowed): a bad field, no program, or stale results."""
        reason = self.block_reason()
        if reason:
            return f"the job is invalid ({reason})"
        if self._pending is not None or self.runner.is_busy() or self._run_after_build:
            return "an edit is still being applied"
        return self.doc.export_block_reason()

    # -- waiting, shutdown -------------------------------------------------------------------------
    def busy(self) -> bool:
        """True while any worker computes or writes."""
        return any(r.is_busy() for r in self.runners())

    def wait_idle(self, timeout_ms: int = 30000, pipeline: bool = True,
                  views_pending: Callable[[], bool] = lambda: False) -> bool:
        """Apply a debounced edit now and wait for the workers (saving, tests, shutdown).

        ``pipeline=False`` waits for the mandrel build and file writes only (not for computations).
        """
        deadline = time.monotonic() + timeout_ms / 1000.0
        while True:
            if self.edit_timer.isActive():
                self.edit_timer.stop()
                self.submit_pending()
            if pipeline and self.run_timer.isActive():
                self.run_timer.stop()
                self.run_now(explicit=False)
            if not (self.busy() or views_pending() if pipeline
                    else (self.runner.is_busy() or self.io_runner.is_busy())):
                return True
            if time.monotonic() > deadline:
                return False
            QApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 20)
            time.sleep(0.002)

    def shutdown(self) -> None:
        """Stop the timers, cancel computations and wait for file writes (window closing)."""
        self._closed = True
        self.edit_timer.stop()
        self.run_timer.stop()
        self.runner.cancel()
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner, self.layer_runner):
            r.cancel()
        self.io_runner.wait(30000)  # never leave a half-written export behind
        self.nc_runner.wait(30000)
        self.runner.wait(5000)
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner, self.layer_runner):
            r.wait(30000)
