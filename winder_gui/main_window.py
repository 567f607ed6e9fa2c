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
data.  Every edit makes a *candidate* job; the mandrel is built from it in a
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

from PySide6.QtCore import QEventLoop, QPoint, QRect, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QCloseEvent, QImage, QKeySequence, QPainter
from PySide6.QtWidgets import (
    QApplication,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QScrollArea,
    QSplitter,
    QStackedWidget,
    QTabWidget,
    QWidget,
)

from engine import __version__
from engine.errors import InputError
from engine.job import FileSpec, Job, PointsSpec, build_mandrel, default_job, load_job
from engine.job import save_job as _write_job
from engine.state import check_cancel
from winder_gui.panels.mandrel_panel import MandrelPanel
from winder_gui.panels.steps import StepBar
from winder_gui.views.geometry import MandrelViewData, mandrel_view_data
from winder_gui.views.profile_plot import ProfilePlot
from winder_gui.views.view3d import MandrelView3D
from winder_gui.workers import JobRunner, cad_call

if TYPE_CHECKING:  # engine.mandrel (scipy) is first imported by the build worker, off the start-up path
    from engine.mandrel import Mandrel

EDIT_DEBOUNCE_MS = 150
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

        self._build_ui()
        self._build_menus()
        self.resize(1400, 880)
        self._update_title()
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
        self.properties.setMinimumWidth(300)

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
        sb = self.statusBar()
        sb.addWidget(self.status_msg, 1)
        sb.addPermanentWidget(self.summary_label)
        sb.addPermanentWidget(self.busy_bar)

        self.steps.step_selected.connect(self._on_step)
        self.mandrel_panel.spec_edited.connect(self._on_spec_edited)
        self.mandrel_panel.points_requested.connect(self._convert_to_points)
        self.mandrel_panel.import_requested.connect(self._action_import)
        self.plot.points_edited.connect(self._on_points_edited)
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
        add(self.menu_file, "save", "&Save", lambda: self.save_job(), QKeySequence.StandardKey.Save)
        add(self.menu_file, "save_as", "Save &As…", self._action_save_as, QKeySequence.StandardKey.SaveAs)
        self.menu_file.addSeparator()
        add(self.menu_file, "import", "&Import generatrix…", self._action_import, "Ctrl+I")
        add(self.menu_file, "export", "&Export mandrel…", self._action_export, "Ctrl+E")
        self.menu_file.addSeparator()
        add(self.menu_file, "quit", "&Quit", self.close, QKeySequence.StandardKey.Quit)

        self.menu_tools = mb.addMenu("&Tools")
        add(self.menu_tools, "turning", "&Turning optimiser…",
            lambda: self.open_tool("turning", "winder_gui.dialogs.turning", "TurningDialog"))
        add(self.menu_tools, "slotting", "&Slot forming…",
            lambda: self.open_tool("slotting", "winder_gui.dialogs.slotting", "SlotDialog"))

        self.menu_help = mb.addMenu("&Help")
        add(self.menu_help, "about", "&About winder", self._action_about)

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
        self.wait_idle()
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
        self.set_dirty(False)
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

    def wait_idle(self, timeout_ms: int = 30000) -> bool:
        """Apply a debounced edit now and wait for the workers (saving, tests, shutdown)."""
        if self._edit_timer.isActive():
            self._edit_timer.stop()
            self._submit_pending()
        deadline = time.monotonic() + timeout_ms / 1000.0
        while self.runner.is_busy() or self.io_runner.is_busy():
            if time.monotonic() > deadline:
                return False
            QApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 20)
            time.sleep(0.002)
        return True

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
        self.job = res.job
        self.mandrel = res.mandrel
        self.view_data = res.data
        reset = purpose in ("open", "new", "import")
        if purpose in ("open", "new"):
            self.job_path = res.path
            self.dirty = False
        else:
            self.dirty = True
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
        if purpose in ("open", "new"):
            self.job_loaded.emit()
        self.mandrel_updated.emit(res.data)

    def _on_failed(self, exc: BaseException, tb: str) -> None:
        purpose = self._purpose
        if not isinstance(exc, InputError):
            print(tb, file=sys.stderr)
        if purpose == "edit" and isinstance(exc, InputError):
            self.mandrel_panel.show_error(exc.location.field, exc.message)
            self._status(f"Not applied: {exc.message}", error=True)
            self.error_reported.emit(exc.message)
        elif purpose == "points" and isinstance(exc, InputError):
            self.plot.revert_points()
            self.plot.show_message(f"Not applied: {exc.message}")
            self._status(f"Not applied: {exc.message}", error=True)
            self.error_reported.emit(exc.message)
        else:
            titles = {"open": "Could not open the job", "import": "Could not import the generatrix",
                      "new": "Could not create a job"}
            self._report_dialog(titles.get(purpose, "Error"), exc)
            if self.mandrel is not None:
                self.mandrel_panel.set_spec(self.job.mandrel)

    def _on_exported(self, path: Path) -> None:
        self._status(f"Exported the mandrel to {path}")

    def _on_busy(self, busy: bool) -> None:
        any_busy = self.runner.is_busy() or self.io_runner.is_busy() or busy
        self.busy_bar.setRange(0, 0 if any_busy else 1)
        self.busy_bar.setVisible(any_busy)

    def _on_progress(self, fraction: float, message: str) -> None:
        if message:
            self.busy_bar.setToolTip(message)

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
        self._on_points_edited(self.view_data.handle_z, self.view_data.handle_r)

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

    def screenshot(self) -> QImage:
        """The window as an image, with the GL-drawn 3D view composed in (for docs and tests)."""
        img = self.grab().toImage()
        view = self.view3d.render_image()
        if view is not None:
            top_left = self.view3d.mapTo(self, QPoint(0, 0))
            size = self.view3d.size()
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
        self.runner.cancel()
        self.io_runner.wait(30000)  # never leave a half-written export behind
        self.runner.wait(5000)
        self.view3d.close_backend()
        for dlg in list(self.dialogs.values()):
            try:
                dlg.close()
            except RuntimeError:
                pass
        event.accept()
