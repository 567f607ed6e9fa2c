"""The main window: step bar, 3D view, plot tabs, properties panel, menus and status bar.

Layout (grown step by step by later issues)::

    ┌──────────┬─────────────────────────────────┬──────────────────┐
    │ Steps    │ 3D view of the revolved mandrel  │ Properties of    │
    │ Mandrel  │                                  │ the current step │
    │ Winding  ├─────────────────────────────────┤ (Mandrel: kind + │
    │ Payout   │ Plot tabs: r(z) + r''(z), …      │ parameters)      │
    │ …        │                                  │                  │
    ├──────────┴─────────────────────────────────┴──────────────────┤
    │ status: message                        mandrel summary  [busy] │
    └────────────────────────────────────────────────────────────────┘

The window holds the :class:`engine.job.Job` (``job``), its path, the built mandrel and its view
data, and the latest :class:`engine.pipeline.PipelineResult` (``result``).

The workflow (issue 9): every step has a properties page (fields with units, validated by the job
model; a bad value shows a message at the field and disables Run with the reason), the plot tabs
show the engine's arrays, and Run (F5) calls :func:`engine.pipeline.run_pipeline` in a worker with
``previous=result``, so only the stages downstream of an edit re-run; after the first run, edits
re-run automatically (debounced, superseding the run in flight).  Cancel (Esc) drops the run at
once; errors are shown as a readable dialog.  Edits of the job are undoable (a QUndoStack of job
snapshots), settings and the window layout persist (QSettings), recent files are remembered, and a
dirty job is autosaved atomically every :data:`AUTOSAVE_MS` to
``AppDataLocation/autosave/<name>.toml``; a leftover autosave is offered on the next start.  Each copy
is locked (:class:`AutosaveOwner`, a QLockFile) by the running instance writing it: a second instance
neither offers, restores, deletes nor overwrites it (it writes ``<name>-2.toml``), while the copy of
a killed instance (stale lock: its PID is gone) is offered as before.

Every mandrel edit makes a *candidate* job; the mandrel is built from it in a
:class:`~winder_gui.workers.JobRunner` worker (never on the GUI thread), and only a candidate that
builds is committed to ``job``.  So a failed open, import or edit leaves the current job loaded and
unchanged, and the error is shown at its place (a dialog naming file/line/field for files, a red
message at the field or on the plot for edits).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import (
    QByteArray,
    QEventLoop,
    QLockFile,
    QPoint,
    QRect,
    QSettings,
    QStandardPaths,
    Qt,
    QTimer,
    Signal,
)
from PySide6.QtGui import QAction, QCloseEvent, QImage, QKeySequence, QPainter, QUndoCommand, QUndoStack
from PySide6.QtWidgets import (
    QApplication,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSplitter,
    QStackedWidget,
    QTabWidget,
    QToolBar,
    QWidget,
)

from engine import __version__
from engine.errors import InputError
from engine.fileio import atomic_write_text
from engine.job import FileSpec, Job, PointsSpec, build_mandrel, default_job, load_job
from engine.job import save_job as _write_job
from engine.state import check_cancel
from winder_gui.panels.mandrel_panel import MandrelPanel
from winder_gui.panels.section_panel import SectionPanel, payout_panel, winding_panel
from winder_gui.panels.steps import STEPS, StepBar
from winder_gui.views.geometry import MandrelViewData, mandrel_view_data, sketch_points
from winder_gui.views.plots import AxesPlot, CoveragePlot, EyePlot, PullSpeedPlot, TimeLawPlot, WindingPlots
from winder_gui.views.profile_plot import ProfilePlot
from winder_gui.views.view3d import MandrelView3D
from winder_gui.workers import JobRunner, cad_call

if TYPE_CHECKING:  # engine.mandrel (scipy) is first imported by the build worker, off the start-up path
    from engine.mandrel import Mandrel

EDIT_DEBOUNCE_MS = 150
RUN_DEBOUNCE_MS = 300
"""Quiet time after the last edit before the pipeline re-runs."""
AUTOSAVE_MS = int(os.environ.get("WINDER_AUTOSAVE_MS", "30000") or 30000)
"""How often a job with unsaved changes is written to the autosave folder."""
MAX_RECENT = 8
NC_FILTER = "NC programs (*.ngc *.nc *.gcode *.mpf *.csv *.txt);;All files (*)"
SETTINGS_ENV = "WINDER_SETTINGS"
"""An .ini file to keep the settings in instead of the user's (tests, portable use)."""
AUTOSAVE_ENV = "WINDER_AUTOSAVE_DIR"
"""A folder for autosave copies instead of AppDataLocation/autosave."""
AUTOSAVE_HEADER = "# winder autosave of: "
STEP_TABS = {"mandrel": "generatrix", "winding": "winding", "payout": "pull_speed", "machine": "axes",
             "timelaw": "time_law", "nc": "axes"}
JOB_FILTER = "Winding jobs (*.toml);;All files (*)"
PROFILE_FILTER = "Generatrix profiles (*.csv *.txt *.dxf *.step *.stp);;All files (*)"
EXPORT_FILTER = "STEP solid (*.step *.stp);;STL mesh (*.stl)"
NO_PROMPT_ENV = "WINDER_NO_PROMPT"
"""Set to 1 to close/replace a job with unsaved changes without asking (tests, scripts)."""


# ------------------------------------------------------------------------------------------------
# Worker tasks (run in a JobRunner thread; no widgets here)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BuildResult:
    """A job whose mandrel was built, with the data the views show."""

    job: Job
    path: Path | None
    mandrel: Mandrel
    data: MandrelViewData


@dataclass(frozen=True)
class JobTimeLawResult:
    """One of the job's own time laws (``PipelineResult.timelaw_laws[index]``) with the classical DP
    and TOPP-RA laws on the same path and limits."""

    source: str
    index: int
    law: Any
    dp: Any
    toppra: Any
    s_offset: float
    key: str


def job_timelaw_task(result: Any, index: int, *, state: Any) -> JobTimeLawResult:
    """:func:`engine.pipeline.compare_time_laws` of the job's law ``index`` (DP and TOPP-RA)."""
    from engine.pipeline import compare_time_laws

    state.progress(0.0, "time law: DP and TOPP-RA on the job's path")
    cmp = compare_time_laws(result, index, ("dp", "toppra"), state=state)
    state.progress(1.0, "")
    law = result.timelaw_laws[index]
    n = int(result.timelaw_paths[index].s.size)
    return JobTimeLawResult(f"job: {result.timelaw_labels[index]} ({law.method}, N = {n})", index, law,
                            cmp["dp"], cmp["toppra"], float(result.timelaw_paths[index].iteration_s_offset),
                            str(result.keys.get("blocks", "")))


def mandrel_io_available() -> bool:
    """True when :mod:`engine.mandrel_io` (CSV/DXF/STEP import, STEP/STL export) is installed."""
    return importlib.util.find_spec("engine.mandrel_io") is not None


def build_task(job: Job, path: Path | None, *, state: Any) -> BuildResult:
    """Build ``job``'s mandrel and sample it for the views (worker thread)."""
    state.progress(0.0, "building the mandrel")
    spec = job.mandrel
    if isinstance(spec, FileSpec):
        if not mandrel_io_available():
            raise InputError(
                "reading profile files needs engine.mandrel_io, which this build does not have yet",
                file=path,
                field="mandrel.path",
            )
        step = Path(spec.path).suffix.lower() in (".step", ".stp")
        mandrel = (cad_call(build_mandrel) if step else build_mandrel)(job, path)
    else:
        mandrel = build_mandrel(job, path)
    check_cancel(state)
    sketch = (list(spec.z_mm), list(spec.r_mm)) if isinstance(spec, PointsSpec) else None
    data = mandrel_view_data(mandrel, sketch)
    state.progress(1.0, "")
    return BuildResult(job, path, mandrel, data)


def convert_task(job: Job, mandrel: Mandrel, path: Path | None, *, state: Any) -> BuildResult:
    """``job`` with its mandrel replaced by a sketch whose spline is within 0.01 mm of ``mandrel``
    (:func:`winder_gui.views.geometry.sketch_points`), built (worker thread)."""
    state.progress(0.0, "converting the generatrix to sketch points")
    z, r, _dev = sketch_points(mandrel, state=state)
    spec = PointsSpec(z_mm=[float(v) for v in z], r_mm=[float(v) for v in r])
    return build_task(job.replace(mandrel=spec), path, state=state)


def open_task(path: Path, *, state: Any) -> BuildResult:
    """Read a job file and build its mandrel (worker thread)."""
    return build_task(load_job(path), path, state=state)


def export_task(mandrel: Mandrel, path: Path, *, state: Any) -> Path:
    """Write the mandrel solid as STEP or mesh as STL, by suffix (worker thread, CAD lock)."""
    from engine import mandrel_io

    state.progress(0.0, f"exporting {path.name}")
    fn = mandrel_io.export_stl if path.suffix.lower() == ".stl" else mandrel_io.export_step
    cad_call(fn)(mandrel, path)
    return path


def profile_ref(profile: Path, job_path: Path | None) -> str:
    """How a job refers to a profile file: relative to the job's folder if saved, else absolute."""
    profile = profile.resolve()
    if job_path is None:
        return profile.as_posix()
    try:
        return Path(os.path.relpath(profile, job_path.resolve().parent)).as_posix()
    except ValueError:  # another drive (Windows)
        return profile.as_posix()


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


def app_settings() -> QSettings:
    """The persistent settings (``WINDER_SETTINGS``: an .ini file instead of the user's)."""
    path = os.environ.get(SETTINGS_ENV, "")
    if path:
        return QSettings(path, QSettings.Format.IniFormat)
    return QSettings("winder", "winder")


def autosave_dir() -> Path:
    """The folder of autosave copies (``WINDER_AUTOSAVE_DIR`` or AppDataLocation/autosave)."""
    env = os.environ.get(AUTOSAVE_ENV, "")
    if env:
        return Path(env)
    base = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.AppDataLocation)
    return Path(base or Path.home() / ".winder") / "autosave"


def _slug(name: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_." else "_" for c in name.strip())
    return keep.strip("._") or "untitled"


def autosave_origin(path: Path) -> Path | None:
    """The job file an autosave copy was made of (from its first line), or ``None`` (never saved)."""
    try:
        first = path.read_text("utf-8").split("\n", 1)[0]
    except OSError:
        return None
    if first.startswith(AUTOSAVE_HEADER):
        rest = first[len(AUTOSAVE_HEADER):].strip()
        return Path(rest) if rest and rest != "(not saved)" else None
    return None


AUTOSAVE_LOCK_SUFFIX = ".lock"
"""An autosave copy ``x.toml`` is owned by whoever holds the lock file ``x.toml.lock`` (a QLockFile)."""


class AutosaveOwner:
    """The autosave copies one running winder holds, each by a :class:`QLockFile` next to it.

    A copy whose lock is held by another running winder is that instance's live autosave: it is
    never offered, restored, deleted or overwritten here.  A lock left by a process that died (the
    PID in the lock file no longer runs) is stale: Qt removes it on the next try, so the copy of a
    killed session is offered again.  Locks never go stale by age alone (``setStaleLockTime(0)``).
    All windows of one process share :func:`process_autosave_owner`; tests give windows their own.
    """

    def __init__(self) -> None:
        self._locks: dict[Path, QLockFile] = {}

    @staticmethod
    def lock_path(copy: Path) -> Path:
        return copy.with_name(copy.name + AUTOSAVE_LOCK_SUFFIX)

    def holds(self, copy: Path) -> bool:
        """True when this owner holds the lock of ``copy``."""
        return Path(copy) in self._locks

    def claim(self, copy: Path) -> bool:
        """Take the lock of ``copy`` (True), or False when another running instance holds it."""
        copy = Path(copy)
        if copy in self._locks:
            return True
        try:
            copy.parent.mkdir(parents=True, exist_ok=True)
        except OSError:
            return False
        lock = QLockFile(str(self.lock_path(copy)))
        lock.setStaleLockTime(0)  # stale only when its process is gone, however old
        if not lock.tryLock(0):
            return False
        self._locks[copy] = lock
        return True

    def is_free(self, copy: Path) -> bool:
        """True when nobody else holds ``copy`` (this owner does, or its lock is free or stale)."""
        if self.holds(copy):
            return True
        lock = QLockFile(str(self.lock_path(Path(copy))))
        lock.setStaleLockTime(0)
        if lock.tryLock(0):
            lock.unlock()
            return True
        return False

    def release(self, copy: Path | None) -> None:
        """Give up the lock of ``copy`` (removes the lock file)."""
        lock = self._locks.pop(Path(copy), None) if copy is not None else None
        if lock is not None:
            lock.unlock()

    def release_all(self) -> None:
        for copy in list(self._locks):
            self.release(copy)


_PROCESS_OWNER: AutosaveOwner | None = None


def process_autosave_owner() -> AutosaveOwner:
    """The :class:`AutosaveOwner` of this process (made on first use)."""
    global _PROCESS_OWNER
    if _PROCESS_OWNER is None:
        _PROCESS_OWNER = AutosaveOwner()
    return _PROCESS_OWNER


class _JobSnapshot(QUndoCommand):
    """One edit of the job: the job before and after (immutable pydantic models)."""

    def __init__(self, window: MainWindow, before: Job, after: Job, text: str) -> None:
        super().__init__(text)
        self._w = window
        self.before = before
        self.after = after
        self._first = True

    def redo(self) -> None:  # noqa: D102 - Qt override
        if self._first:  # the edit is already applied when the command is pushed
            self._first = False
            return
        self._w._restore_job(self.after)

    def undo(self) -> None:  # noqa: D102 - Qt override
        self._w._restore_job(self.before)


# ------------------------------------------------------------------------------------------------
# Main window
# ------------------------------------------------------------------------------------------------
class MainWindow(QMainWindow):
    """The winder main window.

    Parameters
    ----------
    job_path:
        A job file to open at start; ``None`` starts a new job (:func:`engine.job.default_job`).

    Signals
    -------
    job_loaded():
        A job was opened or created (after its mandrel was built).
    mandrel_updated(MandrelViewData):
        The views show a newly built mandrel.
    error_reported(str):
        An error message was shown to the user (dialog, field or plot).
    """

    job_loaded = Signal()
    mandrel_updated = Signal(object)
    error_reported = Signal(str)
    pipeline_done = Signal(object)
    laws_done = Signal(object)
    timelaw_done = Signal(object)
    nc_written = Signal(object)

    def __init__(self, job_path: str | Path | None = None) -> None:
        super().__init__()
        self.job: Job = default_job()
        self.job_path: Path | None = None
        self.mandrel: Mandrel | None = None
        self.view_data: MandrelViewData | None = None
        self.dirty = False
        self.confirm_discard = os.environ.get(NO_PROMPT_ENV, "") in ("", "0")
        """Ask before closing or replacing a job with unsaved changes (tests set it False)."""
        self.last_error = ""
        self.error_box: QMessageBox | None = None
        self.dialogs: dict[str, QWidget] = {}
        self._purpose = ""
        self._pending: tuple[Job, str] | None = None

        self.runner = JobRunner(self)
        self.runner.finished.connect(self._on_built)
        self.runner.failed.connect(self._on_failed)
        self.runner.busy.connect(self._on_busy)
        self.runner.progress.connect(self._on_progress)
        self.io_runner = JobRunner(self)
        self.io_runner.finished.connect(self._on_exported)
        self.io_runner.failed.connect(lambda exc, tb: self._report_dialog("Export failed", exc, tb))
        self.io_runner.busy.connect(self._on_busy)
        self._edit_timer = QTimer(self)
        self._edit_timer.setSingleShot(True)
        self._edit_timer.setInterval(EDIT_DEBOUNCE_MS)
        self._edit_timer.timeout.connect(self._submit_pending)

        # the pipeline and its companions
        self.result: Any = None
        """Latest :class:`engine.pipeline.PipelineResult` (possibly partial, after a cancel or error)."""
        self.laws: dict[str, Any] | None = None
        self.timelaw: Any = None
        """The paper example's time laws (Time law step, "paper example")."""
        self.job_timelaw: JobTimeLawResult | None = None
        """The chosen job time law with its DP / TOPP-RA comparison (Time law step, "job: …")."""
        self._tl_laws: tuple[Any, ...] = ()
        self.auto_run = True
        """Re-run the pipeline after every edit once it has run for this job."""
        self._partial: Any = None
        self.run_warnings: list[str] = []
        self.run_violations: list[Any] = []
        self._checked: Any = None
        self._run_job: Job | None = None
        self._run_after_build = False
        self._explicit_run = False
        self._superseding = False
        self._run_t0 = 0.0
        self._shown: dict[str, str] = {}
        self._laws_key = ""
        self._paths_key: str | None = None
        self._autosaved: Path | None = None
        self.autosave_owner: AutosaveOwner = process_autosave_owner()
        """Holds the locks of this window's autosave copies (see :class:`AutosaveOwner`)."""
        self.undo_stack = QUndoStack(self)
        self.pipe_runner = JobRunner(self)
        self.pipe_runner.finished.connect(self._on_pipe_done)
        self.pipe_runner.failed.connect(self._on_pipe_failed)
        self.pipe_runner.cancelled.connect(self._on_pipe_cancelled)
        self.pipe_runner.partial.connect(self._on_pipe_partial)
        self.pipe_runner.progress.connect(self._on_pipe_progress)
        self.pipe_runner.busy.connect(self._on_busy)
        self.laws_runner = JobRunner(self)
        self.laws_runner.finished.connect(self._on_laws_done)
        self.laws_runner.failed.connect(lambda exc, tb: self._report_dialog("Payout law comparison failed", exc, tb))
        self.laws_runner.busy.connect(self._on_busy)
        self.tl_runner = JobRunner(self)
        self.tl_runner.finished.connect(self._on_timelaw_done)
        self.tl_runner.failed.connect(self._on_timelaw_failed)
        self.tl_runner.progress.connect(self._on_pipe_progress)
        self.tl_runner.busy.connect(self._on_busy)
        self.nc_runner = JobRunner(self)
        self.nc_runner.finished.connect(self._on_nc_written)
        self.nc_runner.failed.connect(lambda exc, tb: self._report_dialog("NC program not written", exc, tb))
        self.nc_runner.busy.connect(self._on_busy)
        self._run_timer = QTimer(self)
        self._run_timer.setSingleShot(True)
        self._run_timer.setInterval(RUN_DEBOUNCE_MS)
        self._run_timer.timeout.connect(lambda: self.run_pipeline_now(explicit=False))
        self._autosave_timer = QTimer(self)
        self._autosave_timer.setInterval(AUTOSAVE_MS)
        self._autosave_timer.timeout.connect(self.autosave_now)
        self._autosave_timer.start()
        self._view_queue: list[Any] = []
        self._view_timer = QTimer(self)
        self._view_timer.setInterval(0)
        self._view_timer.timeout.connect(self._next_view_update)

        self._build_ui()
        self._build_menus()
        self._build_toolbar()
        self.resize(1400, 880)
        self._restore_settings()
        self._update_title()
        self._update_run_state()
        if job_path is not None:
            self.open_job(job_path)
        else:
            self._submit("new", build_task, self.job, None)

    # -- UI construction -------------------------------------------------------------------------
    def _build_ui(self) -> None:
        self.steps = StepBar()
        self.view3d = MandrelView3D()
        self.plot = ProfilePlot()
        self.plot_tabs = QTabWidget()
        self.plot_tabs.setDocumentMode(True)
        self.plot_tabs.addTab(self.plot, "Generatrix r(z)")
        self.winding_plots = WindingPlots()
        self.eye_plot = EyePlot()
        self.pull_plot = PullSpeedPlot()
        self.axes_plot = AxesPlot()
        self.timelaw_plot = TimeLawPlot()
        self.coverage_plot = CoveragePlot()
        self.tabs: dict[str, QWidget] = {"generatrix": self.plot}
        for key, w, title in (("winding", self.winding_plots, "Winding β, C, λ (z)"),
                              ("eye", self.eye_plot, "Eye path Z–R"),
                              ("pull_speed", self.pull_plot, "Pull speed u(x)"),
                              ("axes", self.axes_plot, "Axes q(t), v(t)"),
                              ("time_law", self.timelaw_plot, "Time law ṡ"),
                              ("coverage", self.coverage_plot, "Coverage v(z)")):
            self.plot_tabs.addTab(w, title)
            self.tabs[key] = w

        center = QSplitter(Qt.Orientation.Vertical)
        center.addWidget(self.view3d)
        center.addWidget(self.plot_tabs)
        center.setStretchFactor(0, 3)
        center.setStretchFactor(1, 2)
        center.setSizes([470, 380])
        self.center_splitter = center

        self.mandrel_panel = MandrelPanel()
        self.properties = QStackedWidget()
        self.step_pages: dict[str, int] = {}
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.mandrel_panel)
        self.step_pages["mandrel"] = self.properties.addWidget(scroll)
        from winder_gui.panels.machine_panel import MachinePanel
        from winder_gui.panels.nc_panel import NCPanel, TimeLawPanel

        self.winding_panel = winding_panel()
        self.payout_panel = payout_panel()
        self.machine_panel = MachinePanel()
        self.timelaw_panel = TimeLawPanel()
        self.nc_panel = NCPanel()
        self.section_panels: dict[str, SectionPanel] = {
            "winding": self.winding_panel, "payout": self.payout_panel, "machine": self.machine_panel,
            "timelaw": self.timelaw_panel,
        }
        for key, panel in (*self.section_panels.items(), ("nc", self.nc_panel)):
            sc = QScrollArea()
            sc.setWidgetResizable(True)
            sc.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
            sc.setWidget(panel)
            self.step_pages[key] = self.properties.addWidget(sc)
        for key, panel in self.section_panels.items():
            panel.job_edited.connect(lambda job, k=key: self._on_job_edited(job, k))
            panel.validity_changed.connect(lambda _m: self._update_run_state())
        self.timelaw_panel.compute_requested.connect(self.compute_timelaw)
        self.timelaw_plot.law_selected.connect(lambda _i: self._show_chosen_law())
        self.nc_panel.run_requested.connect(self.run_pipeline_now)
        self.nc_panel.cancel_requested.connect(self.cancel_run)
        self.nc_panel.export_requested.connect(self._action_export_nc)
        self.properties.setMinimumWidth(330)

        main = QSplitter(Qt.Orientation.Horizontal)
        main.addWidget(self.steps)
        main.addWidget(center)
        main.addWidget(self.properties)
        main.setStretchFactor(1, 1)
        main.setCollapsible(0, False)
        main.setSizes([118, 940, 340])
        self.setCentralWidget(main)

        self.status_msg = QLabel("")
        self.status_msg.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.summary_label = QLabel("")
        self.busy_bar = QProgressBar()
        self.busy_bar.setMaximumWidth(140)
        self.busy_bar.setTextVisible(False)
        self.busy_bar.hide()
        self.progress_bar = QProgressBar()
        self.progress_bar.setObjectName("pipelineProgress")
        self.progress_bar.setRange(0, 1000)
        self.progress_bar.setMaximumWidth(220)
        self.progress_bar.setFormat("%p%")
        self.progress_bar.hide()
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setObjectName("cancelRun")
        self.cancel_button.setToolTip("Stop the computation (Esc)")
        self.cancel_button.clicked.connect(self.cancel_run)
        self.cancel_button.hide()
        sb = self.statusBar()
        sb.addWidget(self.status_msg, 1)
        sb.addPermanentWidget(self.summary_label)
        sb.addPermanentWidget(self.progress_bar)
        sb.addPermanentWidget(self.cancel_button)
        sb.addPermanentWidget(self.busy_bar)
        self.steps.set_available({k for k, _ in STEPS})

        self.steps.step_selected.connect(self._on_step)
        self.mandrel_panel.spec_edited.connect(self._on_spec_edited)
        self.mandrel_panel.checked.connect(self._update_run_state)
        self.mandrel_panel.points_requested.connect(self._convert_to_points)
        self.mandrel_panel.import_requested.connect(self._action_import)
        self.plot.points_edited.connect(self._on_points_edited)
        self.mandrel_panel.attach_plot(self.plot)  # live table while dragging, shared selection
        self.plot.message.connect(lambda m: self._status(m, error=True) if m else None)

    def _build_menus(self) -> None:
        mb = self.menuBar()
        self.menu_file = mb.addMenu("&File")
        self.actions: dict[str, QAction] = {}

        def add(menu: Any, key: str, text: str, slot: Any, shortcut: Any = None) -> QAction:
            act = QAction(text, self)
            if shortcut is not None:
                act.setShortcut(QKeySequence(shortcut))
            act.triggered.connect(slot)
            menu.addAction(act)
            self.actions[key] = act
            return act

        add(self.menu_file, "new", "&New", self._action_new, QKeySequence.StandardKey.New)
        add(self.menu_file, "open", "&Open…", self._action_open, QKeySequence.StandardKey.Open)
        self.menu_recent = self.menu_file.addMenu("Open &Recent")
        add(self.menu_file, "save", "&Save", lambda: self.save_job(), QKeySequence.StandardKey.Save)
        add(self.menu_file, "save_as", "Save &As…", self._action_save_as, QKeySequence.StandardKey.SaveAs)
        self.menu_file.addSeparator()
        add(self.menu_file, "import", "&Import generatrix…", self._action_import, "Ctrl+I")
        add(self.menu_file, "export", "&Export mandrel…", self._action_export, "Ctrl+E")
        add(self.menu_file, "export_nc", "Export &NC program…", self._action_export_nc, "Ctrl+Shift+E")
        add(self.menu_file, "export_plot", "Export current &plot…", self._action_export_plot, "Ctrl+Shift+P")
        self.menu_file.addSeparator()
        add(self.menu_file, "quit", "&Quit", self.close, QKeySequence.StandardKey.Quit)

        self.menu_edit = mb.addMenu("&Edit")
        undo = self.undo_stack.createUndoAction(self, "&Undo")
        undo.setShortcut(QKeySequence.StandardKey.Undo)
        redo = self.undo_stack.createRedoAction(self, "&Redo")
        redo.setShortcuts([QKeySequence.StandardKey.Redo, QKeySequence("Ctrl+Shift+Z")])
        self.menu_edit.addAction(undo)
        self.menu_edit.addAction(redo)
        self.actions["undo"], self.actions["redo"] = undo, redo

        self.menu_run = mb.addMenu("&Run")
        add(self.menu_run, "run", "&Run pipeline", lambda: self.run_pipeline_now(), "F5")
        add(self.menu_run, "cancel", "&Cancel", self.cancel_run, "Esc")
        add(self.menu_run, "timelaw", "Compute &time law", self.compute_timelaw, "F6")
        auto = add(self.menu_run, "auto_run", "Re-run &automatically after edits", self._toggle_auto_run)
        auto.setCheckable(True)
        auto.setChecked(True)

        self.menu_view = mb.addMenu("&View")
        for i, (key, title) in enumerate(STEPS):
            add(self.menu_view, f"step_{key}", f"&{i + 1} {title}", lambda _c=False, k=key: self.go_to_step(k),
                f"Ctrl+{i + 1}")
        self.menu_view.addSeparator()
        add(self.menu_view, "play", "&Play / pause the winding", self._toggle_play, "Space")

        self.menu_tools = mb.addMenu("&Tools")
        add(self.menu_tools, "turning", "&Turning optimiser…",
            lambda: self.open_tool("turning", "winder_gui.dialogs.turning", "TurningDialog"))
        add(self.menu_tools, "slotting", "&Slot forming…",
            lambda: self.open_tool("slotting", "winder_gui.dialogs.slotting", "SlotDialog"))

        self.menu_help = mb.addMenu("&Help")
        add(self.menu_help, "shortcuts", "&Keyboard shortcuts", self._action_shortcuts, "F1")
        add(self.menu_help, "about", "&About winder", self._action_about)

    def _build_toolbar(self) -> None:
        tb = QToolBar("Main")
        tb.setObjectName("mainToolbar")
        tb.setMovable(False)
        for key in ("new", "open", "save", None, "undo", "redo", None, "run", "cancel", "export_nc"):
            if key is None:
                tb.addSeparator()
            else:
                tb.addAction(self.actions[key])
        self.toolbar = tb
        self.addToolBar(tb)
        self._rebuild_recent_menu()

    # -- document --------------------------------------------------------------------------------
    def open_job(self, path: str | Path) -> None:
        """Open a job file; the mandrel is built in a worker and the job replaced only on success.

        On failure a dialog names the file, line and field; the current job stays as it was.
        """
        p = Path(path)
        self._edit_timer.stop()
        self._pending = None
        self._status(f"Opening {p.name}…")
        self._submit("open", open_task, p)

    def new_job(self) -> None:
        """Replace the job by a new default one (no prompt; see the File menu action)."""
        self._edit_timer.stop()
        self._pending = None
        self._submit("new", build_task, default_job(), None)

    def save_job(self, path: str | Path | None = None) -> bool:
        """Write the job (atomically) to ``path``, or to its own file; asks for a name if it has none.

        Pending edits are applied first.  Returns True when the file was written.
        """
        self.wait_idle(pipeline=False)
        if path is None:
            if self.job_path is None:
                return self._action_save_as()
            target = self.job_path
        else:
            target = Path(path)
        if target.suffix == "":
            target = target.with_suffix(".toml")
        job = self.job
        if isinstance(job.mandrel, FileSpec):
            base = self.job_path.parent if self.job_path is not None else Path.cwd()
            ref = profile_ref(base / job.mandrel.path, target)
            if ref != job.mandrel.path:
                job = job.replace(mandrel=FileSpec(path=ref))
        try:
            _write_job(job, target)
        except (InputError, OSError) as exc:
            self._report_dialog("Could not save the job", exc)
            return False
        self.job = job
        self.job_path = target
        self._sync_panels(None)
        self.set_dirty(False)
        self.drop_autosave()
        self.add_recent(target)
        self._status(f"Saved {target}")
        return True

    def set_dirty(self, dirty: bool) -> None:
        """Mark the job as changed since it was opened or saved (shown as '*' in the title)."""
        self.dirty = dirty
        self._update_title()

    def _update_title(self) -> None:
        where = self.job_path.name if self.job_path is not None else "not saved"
        self.setWindowTitle(f"{self.job.name}{'*' if self.dirty else ''} — {where} — winder {__version__}")

    def import_generatrix(self, path: str | Path) -> None:
        """Make the job's mandrel the profile in ``path`` (.csv/.txt/.dxf/.step/.stp).

        The profile is read in a worker; on any error a dialog names the place and the job is kept.
        """
        p = Path(path)
        if not mandrel_io_available():
            self._report_dialog(
                "Import generatrix",
                InputError("importing profiles needs engine.mandrel_io, which this build does not have yet", file=p),
            )
            return
        try:
            spec = FileSpec(path=profile_ref(p, self.job_path))
        except ValueError as exc:
            msg = exc.errors()[0]["msg"] if hasattr(exc, "errors") else str(exc)  # pydantic ValidationError
            self._report_dialog("Import generatrix", InputError(msg.removeprefix("Value error, "), file=p))
            return
        self._edit_timer.stop()
        self._pending = None
        self._status(f"Importing {p.name}…")
        self._submit("import", build_task, self.job.replace(mandrel=spec), self.job_path)

    def export_mandrel(self, path: str | Path) -> None:
        """Write the current mandrel as STEP (solid) or STL (mesh) by suffix, in the CAD worker."""
        p = Path(path)
        if self.mandrel is None:
            self._report_dialog("Export mandrel", InputError("there is no valid mandrel to export yet"))
            return
        if not mandrel_io_available():
            self._report_dialog(
                "Export mandrel",
                InputError("exporting needs engine.mandrel_io, which this build does not have yet", file=p),
            )
            return
        if p.suffix.lower() not in (".step", ".stp", ".stl"):
            p = p.with_suffix(".step")
        self._status(f"Exporting {p.name}…")
        self.io_runner.submit(export_task, self.mandrel, p)

    def wait_idle(self, timeout_ms: int = 30000, pipeline: bool = True) -> bool:
        """Apply a debounced edit now and wait for the workers (saving, tests, shutdown).

        ``pipeline=False`` waits for the mandrel build and file writes only (not for computations).
        """
        if self._edit_timer.isActive():
            self._edit_timer.stop()
            self._submit_pending()
        deadline = time.monotonic() + timeout_ms / 1000.0
        while True:
            if self._edit_timer.isActive():
                self._edit_timer.stop()
                self._submit_pending()
            if pipeline and self._run_timer.isActive():
                self._run_timer.stop()
                self.run_pipeline_now(explicit=False)
            if not (self.busy() or self._view_queue if pipeline
                    else (self.runner.is_busy() or self.io_runner.is_busy())):
                return True
            if time.monotonic() > deadline:
                return False
            QApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 20)
            time.sleep(0.002)

    def busy(self) -> bool:
        """True while any worker of the window computes or writes."""
        return any(r.is_busy() for r in (self.runner, self.io_runner, self.pipe_runner, self.laws_runner,
                                         self.tl_runner, self.nc_runner))

    # -- runner plumbing -------------------------------------------------------------------------
    def _submit(self, purpose: str, fn: Any, *args: Any) -> None:
        self._purpose = purpose
        self.runner.submit(fn, *args)

    def _queue_edit(self, job: Job, purpose: str) -> None:
        self._pending = (job, purpose)
        self._edit_timer.start()

    def _submit_pending(self) -> None:
        if self._pending is None:
            return
        job, purpose = self._pending
        self._pending = None
        self._submit(purpose, build_task, job, self.job_path)

    def _on_built(self, res: BuildResult) -> None:
        purpose = self._purpose
        old_kind = self.job.mandrel.kind
        before = self.job
        self.job = res.job
        self.mandrel = res.mandrel
        self.view_data = res.data
        reset = purpose in ("open", "new", "import", "restore")
        fresh = purpose in ("open", "new", "restore")
        if fresh:
            self.job_path = res.path
            self.dirty = purpose == "restore"
            self.undo_stack.clear()
            self._clear_results()
            if purpose == "open" and res.path is not None:
                self.add_recent(res.path)
        else:
            self.dirty = True
            if purpose != "undo" and before != res.job:
                self.undo_stack.push(_JobSnapshot(self, before, res.job, f"Edit mandrel ({purpose})"))
        self._sync_panels(None)
        if purpose != "edit":  # the panel already shows what the user typed
            self.mandrel_panel.set_spec(res.job.mandrel)
        else:
            self.mandrel_panel.clear_errors()
        self.mandrel_panel.spec = res.job.mandrel
        self.mandrel_panel.hint = (res.mandrel.r_max, res.mandrel.length)
        sketch = isinstance(res.job.mandrel, PointsSpec)
        self.plot.set_data(res.data, sketch=sketch, reset_view=reset)
        self.plot.show_message("")
        self.view3d.set_data(res.data, reset_camera=reset)
        m = res.mandrel
        zones = len(res.data.concave)
        self.summary_label.setText(
            f"L {m.length:.1f} mm · r {m.r_min:.1f}…{m.r_max:.1f} mm · poles {m.pole_radii[0]:.1f}/"
            f"{m.pole_radii[1]:.1f} mm · {zones} concave zone{'s' if zones != 1 else ''}"
        )
        self._update_title()
        if purpose == "open":
            self._status(f"Opened {res.path}")
        elif purpose == "new":
            self._status("New job")
        elif purpose == "import":
            self._status(f"Imported the generatrix from {res.job.mandrel.path}")  # type: ignore[union-attr]
        elif purpose == "points" and old_kind != "points":
            self._status(
                f"The mandrel is now a sketched generatrix (kind \"points\", {len(res.job.mandrel.z_mm)} points); "  # type: ignore[union-attr]
                f"it was a \"{old_kind}\" template"
            )
        else:
            self._status("Mandrel updated")
        if purpose == "restore":
            self._status(f"Restored the autosaved copy of {res.job.name} (not saved yet)")
        if fresh:
            self.job_loaded.emit()
        self.mandrel_updated.emit(res.data)
        self._update_run_state()
        if self._run_after_build:
            self._run_after_build = False
            self.run_pipeline_now(explicit=self._explicit_run)
        elif not fresh:
            self._after_edit()

    def _on_failed(self, exc: BaseException, tb: str) -> None:
        purpose = self._purpose
        if not isinstance(exc, InputError):
            print(tb, file=sys.stderr)
        self._run_after_build = False
        self._update_run_state()
        if purpose == "edit" and isinstance(exc, InputError):
            self.mandrel_panel.show_error(exc.location.field, exc.message)
            self._update_run_state()
            self._status(f"Not applied: {exc.message}", error=True)
            self.error_reported.emit(exc.message)
        elif purpose == "points" and isinstance(exc, InputError):
            self.plot.revert_points()
            self.plot.show_message(f"Not applied: {exc.message}")
            self._status(f"Not applied: {exc.message}", error=True)
            self.error_reported.emit(exc.message)
        else:
            titles = {"open": "Could not open the job", "import": "Could not import the generatrix",
                      "new": "Could not create a job", "restore": "Could not restore the autosaved job",
                      "undo": "Could not undo"}
            self._report_dialog(titles.get(purpose, "Error"), exc)
            if self.mandrel is not None:
                self.mandrel_panel.set_spec(self.job.mandrel)

    def _on_exported(self, path: Path) -> None:
        self._status(f"Exported the mandrel to {path}")

    def _on_busy(self, _busy: bool = False) -> None:
        io_busy = self.runner.is_busy() or self.io_runner.is_busy() or self.nc_runner.is_busy()
        self.busy_bar.setRange(0, 0 if io_busy else 1)
        self.busy_bar.setVisible(io_busy)
        computing = self.pipe_runner.is_busy() or self.tl_runner.is_busy() or self.laws_runner.is_busy()
        self.progress_bar.setVisible(computing)
        self.cancel_button.setVisible(computing)
        self.actions["cancel"].setEnabled(computing)
        self.view3d.set_busy(self.busy())
        self._update_run_state()

    def _on_progress(self, fraction: float, message: str) -> None:
        if message:
            self.busy_bar.setToolTip(message)

    # -- job edits, undo -------------------------------------------------------------------------
    def _sync_panels(self, source: str | None) -> None:
        """Show the job in every section panel (the ``source`` panel keeps what the user typed)."""
        for key, panel in self.section_panels.items():
            if key == source:
                panel.job = self.job
            else:
                panel.set_job(self.job)

    def _on_job_edited(self, job: Job, source: str) -> None:
        if job == self.job:
            return
        before = self.job
        self.job = job
        self.undo_stack.push(_JobSnapshot(self, before, job, f"Edit {source}"))
        self._sync_panels(source)
        self.set_dirty(True)
        self._after_edit()

    def _restore_job(self, job: Job) -> None:
        """Make ``job`` current again (undo/redo); the mandrel is rebuilt in the worker if it differs."""
        if job.mandrel != self.job.mandrel:
            self._edit_timer.stop()
            self._pending = None
            self._submit("undo", build_task, job, self.job_path)
            return
        self.job = job
        self._sync_panels(None)
        self.set_dirty(True)
        self._after_edit()

    def _after_edit(self) -> None:
        self._update_run_state()
        if self.auto_run and self.result is not None and not self.run_block_reason():
            self._run_timer.start()

    def _toggle_auto_run(self, on: bool) -> None:
        self.auto_run = bool(on)

    # -- run state ---------------------------------------------------------------------------------
    def mandrel_problem(self) -> str:
        """The first message shown at a mandrel field ('' when none)."""
        for (kind, key), row in self.mandrel_panel.rows.items():
            if kind == self.mandrel_panel.current_kind() and not row.error.isHidden() and row.error.text():
                return f"mandrel {key}: {row.error.text()}"
        return self.mandrel_panel.status.text()

    def run_block_reason(self) -> str:
        """Why Run is disabled ('' when it may run): the first bad field of any step."""
        reason = self.mandrel_problem()
        if reason:
            return reason
        for key, panel in self.section_panels.items():
            if panel.errors():
                return f"{key} {panel.errors()}"
        return ""

    def _update_run_state(self) -> None:
        if not hasattr(self, "nc_panel"):
            return
        reason = self.run_block_reason()
        running = self.pipe_runner.is_busy()
        self.actions["run"].setEnabled(not reason)
        self.actions["run"].setToolTip(f"Run disabled: {reason}" if reason else "Run the pipeline (F5)")
        self.nc_panel.set_run_state(not reason, reason, running)
        self.timelaw_panel.compute_button.setEnabled(not self.timelaw_panel.errors())
        if "export_nc" in self.actions:
            ok = self.result is not None and self.result.nc_text is not None
            self.actions["export_nc"].setEnabled(ok)

    # -- pipeline ----------------------------------------------------------------------------------
    def run_pipeline_now(self, upto: str = "nc", explicit: bool = True) -> bool:
        """Run the pipeline on the current job in the worker, re-using the last result's valid stages.

        Returns False (and says why in the status bar) when a field is bad.  A mandrel edit still
        being applied runs first.
        """
        reason = self.run_block_reason()
        if reason:
            self._status(f"Run disabled: {reason}", error=True)
            return False
        self._run_timer.stop()
        if self._edit_timer.isActive() or self.runner.is_busy():
            self._run_after_build = True
            self._explicit_run = explicit
            return True
        self._explicit_run = explicit
        self._run_job = self.job
        self._run_t0 = time.monotonic()
        self._partial = None
        self.progress_bar.setValue(0)
        self._superseding = True
        try:
            from winder_gui.tasks import pipeline_task

            self.pipe_runner.submit(pipeline_task, self.job, self.job_path, self.result, upto)
        finally:
            self._superseding = False
        self._status("Running the pipeline…")
        self._update_run_state()
        return True

    def cancel_run(self) -> None:
        """Stop every computation in flight (pipeline, law comparison, time law); results are dropped."""
        self._run_timer.stop()
        self._run_after_build = False
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner):
            if r.is_busy():
                r.cancel()
        self._on_busy()

    def _on_pipe_progress(self, fraction: float, message: str) -> None:
        self.progress_bar.setValue(int(round(1000 * min(max(fraction, 0.0), 1.0))))
        if message:
            self.progress_bar.setToolTip(message)
            self.progress_bar.setFormat(f"{message} %p%")

    def _on_pipe_partial(self, res: Any) -> None:
        from engine.pipeline import PipelineResult

        if isinstance(res, PipelineResult):
            self._partial = res
            self._show_result(res)

    def _on_pipe_done(self, out: Any) -> None:
        res = out.result
        self.result = res
        self.run_warnings = list(out.warnings)
        self.run_violations = list(out.violations)
        self._checked = res
        self._partial = None
        self._show_result(res)
        if out.paths is not None and (self.view3d.paths is None or self._paths_key != res.keys.get("payout")):
            self._paths_key = res.keys.get("payout")
            self._view_queue.append(lambda: self.view3d.set_paths(out.paths))
        self._view_queue.append(lambda: self.nc_panel.set_result(res, self.run_warnings))
        self._view_timer.start()
        took = time.monotonic() - self._run_t0
        reused = f" (re-used: {', '.join(res.reused)})" if res.reused else ""
        warn = len(self.run_warnings)
        program = f"; program time {res.blocks.total:.2f} s" if res.blocks is not None else ""
        self._status(f"Pipeline done in {took:.1f} s{reused}{program}"
                     + (f"; {warn} warning{'s' if warn != 1 else ''} (NC step)" if warn else ""))
        info = getattr(res, "timelaw", None)  # the time law that set the block times (method tube/dp/toppra)
        self.timelaw_panel.program_label.setText(
            f"Program block times: {info.get('method')} law over the job's axis path, "
            f"{float(info.get('total_time_s', 0.0)):.2f} s, {info.get('iterations', 0)} iterations"
            if isinstance(info, dict) else
            f"Program block times: (17)/(18), {res.blocks.total:.2f} s" if res.blocks is not None else "")
        self._offer_job_laws(res)
        eye_key = res.keys.get("payout", "")
        if eye_key != self._laws_key and res.eye_circuit is not None:
            self._laws_key = eye_key
            from winder_gui.tasks import laws_task

            self.laws_runner.submit(laws_task, res)
        self._update_run_state()
        self.pipeline_done.emit(res)

    def _keep_partial(self) -> None:
        if self._partial is not None:
            self.result = self._partial
            self._partial = None

    def _on_pipe_failed(self, exc: BaseException, tb: str) -> None:
        self._keep_partial()
        shown = False
        if isinstance(exc, InputError) and exc.location.field:
            fld = exc.location.field
            for panel in self.section_panels.values():
                shown = panel.show_error(fld, exc.message) or shown
            if fld.startswith("mandrel"):
                self.mandrel_panel.show_error(fld, exc.message)
                shown = True
        self.nc_panel.summary.setText(f"<span style='color:#c01010'>Not computed: "
                                      f"{exc.message if isinstance(exc, InputError) else exc}</span>")
        if self._explicit_run or not shown:
            self._report_dialog("The pipeline stopped", exc, tb)
        else:
            msg = exc.message if isinstance(exc, InputError) else str(exc)
            self._status(f"Pipeline stopped: {msg}", error=True)
            self.error_reported.emit(msg)
        self._update_run_state()

    def _on_pipe_cancelled(self) -> None:
        if self._superseding:
            return
        self._keep_partial()
        self._status("Cancelled; the results of the finished stages are kept.")
        self._update_run_state()

    def _clear_results(self) -> None:
        self.cancel_run()
        self.result = None
        self._partial = None
        self.laws = None
        self._laws_key = ""
        self._paths_key = None
        self._shown.clear()
        self._view_queue.clear()
        for page in (self.winding_plots, self.eye_plot, self.axes_plot, self.coverage_plot):
            page.clear_data("No data yet: run the pipeline (F5).")
        self.pull_plot.set_laws({}, "", "s")
        self.pull_plot.set_message("No data yet: run the pipeline (F5).")
        self.nc_panel.set_result(None)
        self.view3d.set_paths(None)
        self._tl_laws = ()
        self.job_timelaw = None
        self.timelaw_plot.set_law_choices([], -1)

    def _show_result(self, res: Any) -> None:
        """Update the views of every stage of ``res`` that changed since they were last drawn.

        The updates are queued and run one per event-loop turn, so the window stays responsive.
        """
        keys = res.keys
        todo: list[Any] = []

        def fresh(stage: str, have: Any) -> bool:
            if have is None or stage not in keys or self._shown.get(stage) == keys[stage]:
                return False
            self._shown[stage] = keys[stage]
            return True

        if fresh("winding", res.line):
            todo += [lambda: self.winding_plots.set_line(res.line), lambda: self.coverage_plot.set_line(res.line)]
        if fresh("payout", res.eye):
            todo.append(lambda: self.eye_plot.set_eye(res.eye_circuit, res.mandrel))
        if fresh("blocks", res.blocks):
            todo += self.axes_plot.updates(res.blocks, res.machine)
        if todo:
            self._view_queue.extend(todo)
            self._view_timer.start()

    def _next_view_update(self) -> None:
        if self._view_queue:
            self._view_queue.pop(0)()
        if not self._view_queue:
            self._view_timer.stop()

    def views_pending(self) -> bool:
        """True while queued view updates are still to be drawn."""
        return bool(self._view_queue)

    def _on_laws_done(self, laws: dict[str, Any]) -> None:
        self.laws = laws
        res = self.result
        job_law = res.eye_circuit.law if res is not None and res.eye_circuit is not None else ""
        param = res.job.payout.parameter if res is not None else "s"
        self._view_queue.extend([*self.pull_plot.plan(list(laws)),
                                 *self.pull_plot.updates(laws, job_law, param),
                                 lambda: self.laws_done.emit(laws)])
        self._view_timer.start()

    # -- time law ------------------------------------------------------------------------------------
    def _offer_job_laws(self, res: Any) -> None:
        """Offer the job's time laws of ``res`` in the Law chooser (default: the main law); the chosen
        law is shown at once when the Time law step is open."""
        laws = tuple(getattr(res, "timelaw_laws", ()) or ())
        if len(laws) == len(self._tl_laws) and all(a is b for a, b in zip(laws, self._tl_laws, strict=True)):
            return
        self._tl_laws = laws
        self.timelaw_plot.set_law_choices(res.timelaw_labels if laws else [], res.timelaw_main if laws else -1)
        if laws and self.steps.current_step() == "timelaw":
            self._show_chosen_law()

    def _show_chosen_law(self) -> None:
        """Show the law of the chooser: a job law is (re-)computed unless shown already."""
        i = self.timelaw_plot.selected_law()
        if i < 0:
            if self.timelaw is not None:
                self._on_timelaw_done(self.timelaw)
            return
        jt = self.job_timelaw
        if (jt is not None and jt.index == i and self.result is not None and i < len(self.result.timelaw_laws)
                and jt.law is self.result.timelaw_laws[i]):
            self._on_timelaw_done(jt)
            return
        self.compute_timelaw()

    def compute_timelaw(self) -> None:
        """Run the time parametrization (tube, DP, TOPP-RA) of the chosen law in the worker: the paper
        example, or the job's law with the classical DP and TOPP-RA on its path and limits."""
        i = self.timelaw_plot.selected_law()
        res = self.result
        if i >= 0 and res is not None and i < len(getattr(res, "timelaw_laws", ())):
            self.timelaw_panel.summary.setText("computing…")
            self.tl_runner.submit(job_timelaw_task, res, i)
            self._status("Computing DP and TOPP-RA on the job's time-law path…")
            return
        if self.timelaw_panel.errors():
            self._status(f"Time law: {self.timelaw_panel.errors()}", error=True)
            return
        from winder_gui.tasks import timelaw_task

        self.timelaw_panel.summary.setText("computing…")
        self.tl_runner.submit(timelaw_task, self.job.timelaw)
        self._status("Computing the time law…")

    def _on_timelaw_done(self, r: Any) -> None:
        if isinstance(r, JobTimeLawResult):
            self.job_timelaw = r
            name = f"job {r.law.method}"
            self._view_queue.extend(self.timelaw_plot.updates(r.law, r.dp, r.toppra, r.source, name, r.s_offset))
            self._view_timer.start()
            self.timelaw_panel.summary.setText(
                f"{r.source}: {r.law.method} {r.law.total_time_s:.3f} s in {len(r.law.iterations)} iterations; "
                f"single DP {r.dp.total_time_s:.3f} s; TOPP-RA bound {r.toppra.total_time_s:.3f} s")
            self._status("Time law comparison computed")
            self._view_queue.append(lambda: self.timelaw_done.emit(r))
            return
        self.timelaw = r
        self._view_queue.extend(self.timelaw_plot.updates(r.tube, r.dp, r.toppra, r.source))
        self._view_timer.start()
        self.timelaw_panel.summary.setText(
            f"{r.source}: tube {r.tube.total_time_s:.3f} s in {len(r.tube.iterations)} iterations; "
            f"single DP {r.dp.total_time_s:.3f} s; TOPP-RA bound {r.toppra.total_time_s:.3f} s")
        self._status("Time law computed")
        self._view_queue.append(lambda: self.timelaw_done.emit(r))

    def _on_timelaw_failed(self, exc: BaseException, tb: str) -> None:
        self.timelaw_panel.summary.setText("")
        self._report_dialog("Time law failed", exc, tb)

    # -- NC export -----------------------------------------------------------------------------------
    def export_nc(self, path: str | Path, force: bool | None = None) -> bool:
        """Write the NC program of the last run to ``path`` (in a worker, atomically).

        When the program violates a limit, ``force=None`` asks "write anyway?"; ``True`` writes,
        ``False`` does not.  Returns True when the write was started.
        """
        res = self.result
        if res is None or res.nc_text is None:
            self._report_dialog("Export NC program", InputError("there is no NC program yet: run the pipeline (F5)"))
            return False
        p = Path(path)
        if not p.suffix:
            p = p.with_suffix(res.extension)
        viol = self.run_violations if self._checked is res else list(res.violations)
        if viol and force is None:
            ans = QMessageBox.question(
                self, "Write anyway?",
                f"The program violates {len(viol)} limit(s), e.g.\n{getattr(viol[0], 'message', viol[0])}\n\n"
                "Write it anyway?",
                QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
            force = ans == QMessageBox.StandardButton.Yes
            if not force:
                self._status("NC program not written (it violates limits)")
                return False
        from winder_gui.tasks import write_task

        self.nc_runner.submit(write_task, res, p, bool(force))
        return True

    def _on_nc_written(self, path: Path) -> None:
        self._status(f"Wrote the NC program to {path}")
        self.nc_written.emit(path)

    def _action_export_nc(self) -> None:
        res = self.result
        if res is None or res.nc_text is None:
            self.export_nc("")
            return
        stem = self.job_path.stem if self.job_path else _slug(self.job.name)
        path, _ = QFileDialog.getSaveFileName(self, "Export NC program",
                                              str(Path(self._start_dir()) / f"{stem}{res.extension}"), NC_FILTER)
        if path:
            self.export_nc(path)

    def _action_export_plot(self) -> None:
        page = self.plot_tabs.currentWidget()
        if hasattr(page, "_ask_export"):
            page._ask_export()

    # -- steps, view -------------------------------------------------------------------------------
    def go_to_step(self, key: str) -> None:
        """Select step ``key`` in the step bar (its page and plot tab are shown)."""
        for i in range(self.steps.count()):
            if self.steps.item(i).data(Qt.ItemDataRole.UserRole) == key:
                self.steps.setCurrentRow(i)
        self._on_step(key)

    def _toggle_play(self) -> None:
        if self.view3d.is_playing():
            self.view3d.pause()
        else:
            self.view3d.play()

    # -- recent files, settings, autosave ------------------------------------------------------------
    def recent_files(self) -> list[str]:
        val = app_settings().value("recent", [])
        if isinstance(val, str):
            val = [val]
        return [str(v) for v in (val or [])]

    def add_recent(self, path: Path) -> None:
        p = str(Path(path).resolve())
        rec = [p, *[r for r in self.recent_files() if r != p]][:MAX_RECENT]
        app_settings().setValue("recent", rec)
        self._rebuild_recent_menu()

    def _rebuild_recent_menu(self) -> None:
        self.menu_recent.clear()
        rec = self.recent_files()
        for i, p in enumerate(rec):
            act = self.menu_recent.addAction(f"&{i + 1} {Path(p).name}")
            act.setToolTip(p)
            act.triggered.connect(lambda _c=False, path=p: self._open_recent(path))
        self.menu_recent.setEnabled(bool(rec))

    def _open_recent(self, path: str) -> None:
        if self._may_discard():
            self.open_job(path)

    def _restore_settings(self) -> None:
        st = app_settings()
        geo = st.value("window/geometry")
        if isinstance(geo, QByteArray | bytes):
            self.restoreGeometry(QByteArray(geo))
        state = st.value("window/state")
        if isinstance(state, QByteArray | bytes):
            self.restoreState(QByteArray(state))
        for name, spl in (("main", self.centralWidget()), ("center", self.center_splitter)):
            val = st.value(f"window/splitter_{name}")
            if isinstance(val, QByteArray | bytes) and isinstance(spl, QSplitter):
                spl.restoreState(QByteArray(val))
        auto = st.value("run/auto", True)
        self.auto_run = str(auto).lower() not in ("false", "0")
        self.actions["auto_run"].setChecked(self.auto_run)
        colour = st.value("view/colour_by", "")
        if colour:
            try:
                self.view3d.set_colour_by(str(colour))
            except ValueError:
                pass
        tab = st.value("window/plot_tab", 0)
        try:
            self.plot_tabs.setCurrentIndex(int(tab))
        except (TypeError, ValueError):
            pass

    def save_settings(self) -> None:
        """Write the window layout and options to the settings."""
        st = app_settings()
        st.setValue("window/geometry", self.saveGeometry())
        st.setValue("window/state", self.saveState())
        st.setValue("window/splitter_main", self.centralWidget().saveState())
        st.setValue("window/splitter_center", self.center_splitter.saveState())
        st.setValue("window/plot_tab", self.plot_tabs.currentIndex())
        st.setValue("run/auto", self.auto_run)
        st.setValue("view/colour_by", self.view3d.colour_by)
        st.sync()

    def autosave_path(self) -> Path:
        """Where this job's autosave copy goes: ``<name>.toml``, or ``<name>-2.toml``, … when that name
        is taken (another running instance's live copy, or a leftover copy not yet offered)."""
        name = self.job_path.stem if self.job_path is not None else self.job.name
        stem = _slug(name)
        d = autosave_dir()
        names = [f"{stem}.toml", *(f"{stem}-{k}.toml" for k in range(2, 1000))]
        mine = self._autosaved
        if mine is not None and mine.parent == d and mine.name in names and self.autosave_owner.holds(mine):
            return mine
        for name in names:
            p = d / name
            if p.exists() or self.lock_taken(p):
                continue
            if self.autosave_owner.claim(p):
                return p
        raise OSError(f"no free autosave name for {stem!r} in {d}")

    def lock_taken(self, p: Path) -> bool:
        """True when the lock of autosave copy ``p`` is held by another running instance."""
        return AutosaveOwner.lock_path(p).exists() and not self.autosave_owner.is_free(p)

    def autosave_now(self) -> Path | None:
        """Write the job to the autosave folder (atomically) if it has unsaved changes."""
        if not self.dirty:
            return None
        p = None
        try:
            p = self.autosave_path()
            p.parent.mkdir(parents=True, exist_ok=True)
            origin = str(self.job_path.resolve()) if self.job_path is not None else "(not saved)"
            atomic_write_text(p, f"{AUTOSAVE_HEADER}{origin}\n{self.job.to_toml()}")
        except OSError as exc:
            if p is not None and p != self._autosaved and not p.exists():
                self.autosave_owner.release(p)      # a name locked for a copy that was never written
            self._status(f"Autosave failed: {exc}", error=True)
            return None
        if self._autosaved is not None and self._autosaved != p:
            self._drop_copy(self._autosaved)
        self._autosaved = p
        return p

    def _drop_copy(self, p: Path) -> None:
        """Delete autosave copy ``p`` and release its lock, if this window's owner holds it."""
        if not self.autosave_owner.holds(p):
            return
        try:
            p.unlink(missing_ok=True)
        except OSError:
            pass
        self.autosave_owner.release(p)

    def drop_autosave(self) -> None:
        """Remove this window's autosave copy (after a save or a deliberate close).

        Only a copy this window's :class:`AutosaveOwner` holds is removed: never another running
        instance's, never a leftover nobody restored.
        """
        if self._autosaved is not None:
            self._drop_copy(self._autosaved)
        self._autosaved = None

    def pending_autosaves(self) -> list[Path]:
        """Autosave copies left by an earlier session (e.g. a killed process), not another live instance's."""
        d = autosave_dir()
        if not d.is_dir():
            return []
        return [p for p in sorted(d.glob("*.toml")) if p != self._autosaved and self.autosave_owner.is_free(p)]

    def restore_autosave(self, path: str | Path) -> None:
        """Load an autosave copy as the current job (unsaved; its file is the job it was made of)."""
        p = Path(path)
        if not self.autosave_owner.claim(p):
            self._status(f"{p.name} is the autosave of another running winder; not restored", error=True)
            return
        try:
            job = load_job(p)
        except (InputError, OSError) as exc:
            self.autosave_owner.release(p)
            self._report_dialog("Could not restore the autosaved job", exc)
            return
        if self._autosaved is not None and self._autosaved != p:
            self._drop_copy(self._autosaved)
        self._autosaved = p
        self._submit("restore", build_task, job, autosave_origin(p))

    def offer_autosaves(self) -> None:
        """Ask, for each leftover autosave copy, whether to restore it (the first accepted is loaded).

        A copy is locked while the question is open, so two instances starting together never both
        restore or delete it; the live copies of other running instances are not offered.
        """
        for p in self.pending_autosaves():
            owned = self.autosave_owner.holds(p)
            if not owned and not self.autosave_owner.claim(p):
                continue  # another instance took it meanwhile
            origin = autosave_origin(p)
            ans = QMessageBox.question(
                self, "Restore autosaved job?",
                f"winder found unsaved changes from an earlier session:\n{p.name}"
                + (f" (job {origin})" if origin else " (never saved)") + "\n\nRestore them?",
                QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Ignore,
                QMessageBox.StandardButton.Yes)
            if ans == QMessageBox.StandardButton.Yes:
                self.restore_autosave(p)
                return
            if ans == QMessageBox.StandardButton.Discard:
                try:
                    p.unlink(missing_ok=True)
                except OSError as exc:
                    self._status(f"Could not delete the autosaved copy {p}: {exc}", error=True)
            if not owned:
                self.autosave_owner.release(p)

    # -- edits -----------------------------------------------------------------------------------
    def _on_spec_edited(self, spec: Any) -> None:
        self.plot.show_message("")
        self._queue_edit(self.job.replace(mandrel=spec), "edit")

    def _on_points_edited(self, z: Any, r: Any) -> None:
        try:
            spec = PointsSpec(z_mm=[float(v) for v in z], r_mm=[float(v) for v in r])
        except ValueError as exc:  # pydantic: not finite
            self.plot.revert_points()
            self.plot.show_message(f"Not applied: {exc}")
            return
        self._queue_edit(self.job.replace(mandrel=spec), "points")

    def _convert_to_points(self) -> None:
        if self.view_data is None:
            self.mandrel_panel.set_spec(self.job.mandrel)
            return
        self._submit("points", convert_task, self.job, self.mandrel, self.job_path)

    # -- messages --------------------------------------------------------------------------------
    def _status(self, msg: str, error: bool = False) -> None:
        self.status_msg.setText(msg)
        self.status_msg.setStyleSheet("color: #c01010;" if error else "")

    def _report_dialog(self, title: str, exc: BaseException | str, tb: str = "") -> None:
        """Show an error in a (non-blocking, window-modal) dialog; never a traceback."""
        if tb and not isinstance(exc, InputError | OSError):
            print(tb, file=sys.stderr)
        text = exc if isinstance(exc, str) else describe_error(exc)
        self.last_error = f"{title}\n{text}"
        self._status(f"{title}: {text.splitlines()[-1] if text else ''}", error=True)
        box = QMessageBox(QMessageBox.Icon.Warning, title, text, QMessageBox.StandardButton.Ok, self)
        if isinstance(exc, InputError | OSError):
            box.setInformativeText("Nothing was changed: the current job is still loaded.")
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()
        self.error_box = box
        self.error_reported.emit(self.last_error)

    # -- actions ---------------------------------------------------------------------------------
    def _may_discard(self) -> bool:
        """True if the job may be replaced: saved, not asked, or the user agreed (Save/Discard)."""
        if not self.dirty or not self.confirm_discard:
            return True
        ans = QMessageBox.question(
            self,
            "Unsaved changes",
            f"The job \"{self.job.name}\" has unsaved changes. Save them first?",
            QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Cancel,
            QMessageBox.StandardButton.Save,
        )
        if ans == QMessageBox.StandardButton.Save:
            return self.save_job()
        return ans == QMessageBox.StandardButton.Discard

    def _start_dir(self) -> str:
        return str(self.job_path.parent) if self.job_path is not None else str(Path.cwd())

    def _action_new(self) -> None:
        if self._may_discard():
            self.new_job()

    def _action_open(self) -> None:
        if not self._may_discard():
            return
        path, _ = QFileDialog.getOpenFileName(self, "Open job", self._start_dir(), JOB_FILTER)
        if path:
            self.open_job(path)

    def _action_save_as(self) -> bool:
        start = str(self.job_path) if self.job_path else str(Path(self._start_dir()) / "job.toml")
        path, _ = QFileDialog.getSaveFileName(self, "Save job as", start, JOB_FILTER)
        return self.save_job(path) if path else False

    def _action_import(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Import generatrix", self._start_dir(), PROFILE_FILTER)
        if path:
            self.import_generatrix(path)
        else:
            self.mandrel_panel.set_spec(self.job.mandrel)

    def _action_export(self) -> None:
        stem = self.job_path.stem if self.job_path else "mandrel"
        path, _ = QFileDialog.getSaveFileName(
            self, "Export mandrel", str(Path(self._start_dir()) / f"{stem}.step"), EXPORT_FILTER
        )
        if path:
            self.export_mandrel(path)

    def _action_about(self) -> None:
        box = QMessageBox(QMessageBox.Icon.Information, "About winder",
                          f"<b>winder {__version__}</b><br>Open CAD/CAM for filament winding:<br>"
                          "mandrel → winding line → payout eye → machine axes → NC.<br><br>GPL-3.0-or-later",
                          QMessageBox.StandardButton.Ok, self)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()
        self.dialogs["about"] = box

    def shortcuts_text(self) -> str:
        """Every menu command with a keyboard shortcut, as an HTML table."""
        rows = []
        for act in self.actions.values():
            keys = ", ".join(k.toString(QKeySequence.SequenceFormat.NativeText) for k in act.shortcuts())
            if keys:
                rows.append(f"<tr><td><b>{keys}</b></td><td>{act.text().replace('&', '').rstrip('…')}</td></tr>")
        return "<table cellspacing=4>" + "".join(rows) + "</table>"

    def _action_shortcuts(self) -> None:
        box = QMessageBox(QMessageBox.Icon.NoIcon, "Keyboard shortcuts", self.shortcuts_text(),
                          QMessageBox.StandardButton.Ok, self)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()
        self.dialogs["shortcuts"] = box

    def open_tool(self, key: str, module: str, cls_name: str) -> QWidget | None:
        """Open a tool dialog ``module.cls_name(parent)`` (imported lazily); a message if unavailable."""
        dlg = self.dialogs.get(key)
        if dlg is not None:
            try:
                dlg.show()
                dlg.raise_()
                return dlg
            except RuntimeError:  # deleted by Qt
                self.dialogs.pop(key, None)
        try:
            cls = getattr(importlib.import_module(module), cls_name)
            dlg = cls(self)
        except Exception as exc:  # noqa: BLE001 - a tool that cannot load must not take the app down
            self._report_dialog(
                "Tool not available", f"{cls_name} could not be loaded ({type(exc).__name__}: {exc})."
            )
            return None
        self.dialogs[key] = dlg
        dlg.show()
        return dlg

    def _on_step(self, key: str) -> None:
        if key in self.step_pages:
            self.properties.setCurrentIndex(self.step_pages[key])
        tab = self.tabs.get(STEP_TABS.get(key, ""))
        if tab is not None:
            self.plot_tabs.setCurrentWidget(tab)
        if key == "timelaw" and self.timelaw_plot.selected_law() >= 0 and not self.tl_runner.is_busy():
            jt = self.job_timelaw
            if jt is None or self.result is None or not any(jt.law is x for x in self.result.timelaw_laws):
                self._show_chosen_law()

    def screenshot(self) -> QImage:
        """The window as an image, with the GL-drawn 3D view composed in (for docs and tests)."""
        img = self.grab().toImage()
        view = self.view3d.render_image()
        gl = self.view3d.gl_widget
        if view is not None and gl is not None:
            top_left = gl.mapTo(self, QPoint(0, 0))
            size = gl.size()
            painter = QPainter(img)
            painter.drawImage(QRect(top_left, size), view)
            painter.end()
        return img

    # -- closing ---------------------------------------------------------------------------------
    def closeEvent(self, event: QCloseEvent) -> None:  # noqa: N802 - Qt override
        if not self._may_discard():
            event.ignore()
            return
        self._edit_timer.stop()
        self._run_timer.stop()
        self._autosave_timer.stop()
        self.save_settings()
        self.drop_autosave()
        self.runner.cancel()
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner):
            r.cancel()
        self.io_runner.wait(30000)  # never leave a half-written export behind
        self.nc_runner.wait(30000)
        self.runner.wait(5000)
        for r in (self.pipe_runner, self.laws_runner, self.tl_runner):
            r.wait(30000)
        self.view3d.close_backend()
        for dlg in list(self.dialogs.values()):
            try:
                dlg.close()
            except RuntimeError:
                pass
        event.accept()
