"""The main window: it lays out the widgets and wires them to the job document and the run controller.

Layout::

    ┌──────────┬─────────────────────────────────┬──────────────────┐
    │ Steps    │ 3D view of the revolved mandrel  │ Properties of    │
    │ Mandrel  │                                  │ the current step │
    │ Winding  ├─────────────────────────────────┤                  │
    │ Payout   │ Plot tabs: r(z) + r''(z), …      │                  │
    │ …        │                                  │                  │
    ├──────────┴─────────────────────────────────┴──────────────────┤
    │ status: message                        mandrel summary  [busy] │
    └────────────────────────────────────────────────────────────────┘

The state lives elsewhere, so that each part can change on its own (as napari keeps ``ViewerModel``
apart from ``QtViewer``):

- :class:`winder_gui.document.JobDocument` (``doc``): the job, its file, dirty state, undo stack,
  results and their staleness, autosave;
- :class:`winder_gui.run_controller.RunController` (``ctl``): the workers, debounce, run state;
- :class:`winder_gui.results_view.ResultsPresenter` (``results``): draws the results in the views;
- :mod:`winder_gui.window_menus`: menus, toolbar and file dialogs; :mod:`winder_gui.settings`.

A panel observes the document through its signals and edits it with ``doc.edit(job, key)``.
A failed open, import or edit leaves the current job loaded and unchanged; the error is shown at its
place (a dialog naming file/line/field for files, a red message at the field or on the plot for edits).
The NC program, its preview and export always describe the job shown: any edit marks them out of
date until the next run finishes, and export is refused (with the reason) while the job is invalid
or the results are out of date.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from PySide6.QtCore import QPoint, QRect, Qt, QTimer, Signal
from PySide6.QtGui import QCloseEvent, QImage, QPainter
from PySide6.QtWidgets import (
    QMainWindow,
    QMessageBox,
    QWidget,
)

from engine import __version__
from engine.errors import InputError
from engine.job import FileSpec, PointsSpec, SegmentsSpec, default_job
from winder_gui import texts, window_builds, window_exports, window_layout, window_menus
from winder_gui.autosave import (  # noqa: F401 - re-exported for callers of the old module
    AUTOSAVE_HEADER,
    AUTOSAVE_MS,
    AutosaveOwner,
    autosave_origin,
    process_autosave_owner,
)
from winder_gui.document import JobDocument
from winder_gui.i18n import tr
from winder_gui.laminate_view import LaminatePresenter
from winder_gui.panels.segments_table import apply_handles
from winder_gui.results_view import ResultsPresenter
from winder_gui.run_controller import RunController
from winder_gui.settings import prompts_enabled, recent_files
from winder_gui.tasks import (  # noqa: F401 - JobTimeLawResult re-exported
    JobTimeLawResult,
    build_task,
    convert_task,
    mandrel_io_available,
    open_task,
    profile_ref,
    sketch_task,
)

STEP_TABS = {"mandrel": "generatrix", "winding": "winding", "payout": "pull_speed", "machine": "axes",
             "timelaw": "time_law", "nc": "axes"}
"""The plot tab shown with each step."""

def _delegate(owner: str, name: str, doc: str = "") -> property:
    """A read/write attribute of the window kept in ``self.<owner>.<name>``."""
    return property(lambda self: getattr(getattr(self, owner), name),
                    lambda self, v: setattr(getattr(self, owner), name, v), doc=doc)


class MainWindow(QMainWindow):
    """The winder main window (``job_path``: a job file to open at start; ``None``: a new job).

    Signals: ``job_loaded()`` (a job was opened or created), ``mandrel_updated(MandrelViewData)``,
    ``error_reported(str)``, ``pipeline_done(result)``, ``laws_done``, ``timelaw_done``, ``nc_written``.
    """

    job_loaded = Signal()
    mandrel_updated = Signal(object)
    error_reported = Signal(str)
    pipeline_done = Signal(object)
    laws_done = Signal(object)
    timelaw_done = Signal(object)
    nc_written = Signal(object)
    nc_read = Signal(object)
    """An NC program was read back (File > Open NC program): :class:`winder_gui.tasks.NcReadback`."""

    job = _delegate("doc", "job", "The current :class:`engine.job.Job`.")
    job_path = _delegate("doc", "path", "The job's file (``None``: not saved).")
    mandrel = _delegate("doc", "mandrel")
    view_data = _delegate("doc", "view_data")
    dirty = _delegate("doc", "dirty")
    result = _delegate("doc", "result", "Latest :class:`engine.pipeline.PipelineResult`.")
    undo_stack = _delegate("doc", "undo_stack")
    run_warnings = _delegate("doc", "run_warnings")
    run_violations = _delegate("doc", "run_violations")
    autosave_owner = _delegate("doc", "autosave_owner")
    auto_run = _delegate("ctl", "auto_run", "Re-run the pipeline after every edit once it has run.")
    runner = _delegate("ctl", "runner")
    pipe_runner = _delegate("ctl", "pipe_runner")
    laws = _delegate("results", "laws")
    timelaw = _delegate("results", "timelaw")
    job_timelaw = _delegate("results", "job_timelaw")

    def __init__(self, job_path: str | Path | None = None) -> None:
        super().__init__()
        self.confirm_discard = prompts_enabled()
        """Ask before closing or replacing a job with unsaved changes (tests set it False)."""
        self.last_error = ""
        self.error_box: QMessageBox | None = None
        self.dialogs: dict[str, QWidget] = {}
        self.doc = JobDocument(self)
        self.ctl = RunController(self.doc, self.run_block_reason, self)
        self._build_ui()
        self.results = ResultsPresenter(self.doc, self.ctl, self)
        self.laminate = LaminatePresenter(self.doc, self.ctl, self)
        self.laminate.layer_shown.connect(self.results.offer_shown_layer_laws)
        window_menus.build_menus(self)
        window_menus.build_toolbar(self)
        self._wire()
        self._autosave_timer = QTimer(self)
        self._autosave_timer.setInterval(AUTOSAVE_MS)
        self._autosave_timer.timeout.connect(self.autosave_now)
        self._autosave_timer.start()
        self.resize(1400, 880)
        self._restore_settings()
        self._update_title()
        self._update_run_state()
        if job_path is not None:
            self.open_job(job_path)
        else:
            self.ctl.build("new", build_task, self.job, None)

    # -- layout ----------------------------------------------------------------------------------
    def _build_ui(self) -> None:
        window_layout.build_layout(self)

    def add_step_page(self, key: str, panel: QWidget, horizontal_scroll: bool = False) -> None:
        """Add ``panel`` as the properties page of step ``key`` (in a scroll area)."""
        window_layout.add_step_page(self, key, panel, horizontal_scroll)

    def _wire(self) -> None:
        doc, ctl, res = self.doc, self.ctl, self.results
        doc.job_changed.connect(self._sync_panels)
        doc.dirty_changed.connect(lambda _d: self._update_title())
        doc.path_changed.connect(lambda _p: self._update_title())
        doc.stale_changed.connect(lambda _s: self._update_run_state())
        doc.status.connect(self._status)
        doc.undo_stack.indexChanged.connect(lambda _i: self._update_run_state())
        ctl.built.connect(self._on_built)
        ctl.build_failed.connect(self._on_build_failed)
        ctl.build_progress.connect(lambda _f, m: m and self.busy_bar.setToolTip(m))
        ctl.busy_changed.connect(self._on_busy)
        ctl.progress.connect(self._on_pipe_progress)
        ctl.run_started.connect(lambda: (self.progress_bar.setValue(0), self._status(tr("Running the pipeline…"))))
        ctl.run_done.connect(lambda out: self.pipeline_done.emit(out.result))
        ctl.run_failed.connect(self._on_pipe_failed)
        ctl.run_cancelled.connect(lambda: self._status(tr("Cancelled; the results of the finished stages are kept.")))
        ctl.laws_failed.connect(lambda exc, tb: self.report_dialog(tr("Payout law comparison failed"), exc, tb))
        ctl.timelaw_failed.connect(self._on_timelaw_failed)
        ctl.nc_written.connect(self._on_nc_written)
        ctl.nc_read.connect(self._on_nc_read)
        ctl.exported.connect(lambda p: self._status(tr("Exported the mandrel to {p}").format(p=p)))
        ctl.io_failed.connect(self.report_dialog)
        res.status.connect(self._status)
        res.laws_shown.connect(self.laws_done)
        res.timelaw_shown.connect(self.timelaw_done)

        for key, panel in self.section_panels.items():
            panel.job_edited.connect(lambda job, k=key: self.doc.edit(job, k))
            panel.validity_changed.connect(lambda _m: self._update_run_state())
        self.layers_panel.job_edited.connect(lambda job, text: self.doc.edit(job, "layers", text))
        self.layers_panel.validity_changed.connect(lambda _m: self._update_run_state())
        self.timelaw_panel.compute_requested.connect(self.compute_timelaw)
        self.timelaw_plot.law_selected.connect(lambda _i: self.results.show_chosen_law())
        self.nc_panel.run_requested.connect(self.run_pipeline_now)
        self.nc_panel.cancel_requested.connect(self.cancel_run)
        self.nc_panel.export_requested.connect(self.action_export_nc)
        self.cancel_button.clicked.connect(self.cancel_run)
        self.steps.step_selected.connect(self._on_step)
        self.mandrel_panel.spec_edited.connect(self._on_spec_edited)
        self.mandrel_panel.checked.connect(self._update_run_state)
        self.mandrel_panel.points_requested.connect(self._convert_to_points)
        self.mandrel_panel.sketch_requested.connect(self._convert_to_sketch)
        self.mandrel_panel.import_requested.connect(lambda: window_menus.action_import(self))
        self.plot.points_edited.connect(self._on_points_edited)
        self.mandrel_panel.attach_plot(self.plot)  # live table while dragging, shared selection
        self.plot.message.connect(lambda m: self._status(m, error=True) if m else None)

    # -- document commands -----------------------------------------------------------------------
    def open_job(self, path: str | Path) -> None:
        """Open a job file; the mandrel is built in a worker and the job replaced only on success."""
        p = Path(path)
        self._status(tr("Opening {name}…").format(name=p.name))
        self.ctl.build("open", open_task, p)

    def new_job(self) -> None:
        """Replace the job by a new default one (no prompt; see the File menu action)."""
        self.ctl.build("new", build_task, default_job(), None)

    def action_new(self) -> None:
        if self._may_discard():
            self.new_job()

    def save_job(self, path: str | Path | None = None) -> bool:
        """Write the job (atomically) to ``path``, or to its own file; asks for a name if it has none.

        Pending edits are applied first.  Returns True when the file was written.
        """
        self.wait_idle(pipeline=False)
        if path is None and self.job_path is None:
            return self._action_save_as()
        try:
            target = self.doc.save(Path(path) if path is not None else self.job_path)
        except (InputError, OSError) as exc:
            self.report_dialog(tr("Could not save the job"), exc)
            return False
        window_menus.rebuild_recent_menu(self)
        self._status(tr("Saved {target}").format(target=target))
        return True

    def _action_save_as(self) -> bool:
        path = window_menus.ask_save_path(self)
        return self.save_job(path) if path else False

    def set_dirty(self, dirty: bool) -> None:
        """Mark the job as changed since it was opened or saved (shown as '*' in the title)."""
        self.doc.set_dirty(dirty)

    def _update_title(self) -> None:
        where = self.job_path.name if self.job_path is not None else "not saved"
        self.setWindowTitle(tr("{name}{v1} — {where} — winder {__version__}")
                            .format(name=self.job.name, v1='*' if self.dirty else '', where=where,
                                    __version__=__version__))

    def import_generatrix(self, path: str | Path) -> None:
        """Make the job's mandrel the profile in ``path`` (.csv/.txt/.dxf/.step/.stp), read in a worker."""
        p = Path(path)
        if not mandrel_io_available():
            self.report_dialog(tr("Import generatrix"), InputError(
                "importing profiles needs engine.mandrel_io, which this build does not have yet", file=p))
            return
        try:
            spec = FileSpec(path=profile_ref(p, self.job_path))
        except ValueError as exc:
            msg = exc.errors()[0]["msg"] if hasattr(exc, "errors") else str(exc)  # pydantic ValidationError
            self.report_dialog(tr("Import generatrix"), InputError(msg.removeprefix("Value error, "), file=p))
            return
        self._status(tr("Importing {name}…").format(name=p.name))
        self.ctl.build("import", build_task, self.job.replace(mandrel=spec), self.job_path)

    def export_mandrel(self, path: str | Path) -> None:
        """Write the current mandrel as STEP (solid) or STL (mesh) by suffix, in the CAD worker."""
        p = Path(path)
        if self.mandrel is None:
            self.report_dialog(tr("Export mandrel"), InputError("there is no valid mandrel to export yet"))
            return
        if not mandrel_io_available():
            self.report_dialog(tr("Export mandrel"), InputError(
                "exporting needs engine.mandrel_io, which this build does not have yet", file=p))
            return
        if p.suffix.lower() not in (".step", ".stp", ".stl"):
            p = p.with_suffix(".step")
        self._status(tr("Exporting {name}…").format(name=p.name))
        self.ctl.export_mandrel(self.mandrel, p)

    def wait_idle(self, timeout_ms: int = 30000, pipeline: bool = True) -> bool:
        """Apply a debounced edit now and wait for the workers (``pipeline=False``: builds and writes only)."""
        return self.ctl.wait_idle(timeout_ms, pipeline, self.results.pending)

    def busy(self) -> bool:
        """True while any worker of the window computes or writes."""
        return self.ctl.busy()

    def views_pending(self) -> bool:
        """True while queued view updates are still to be drawn."""
        return self.results.pending()

    # -- builds ----------------------------------------------------------------------------------
    def _on_built(self, purpose: str, res: Any) -> None:
        window_builds.on_built(self, purpose, res)

    def _on_build_failed(self, purpose: str, exc: BaseException, tb: str) -> None:
        window_builds.on_build_failed(self, purpose, exc, tb)

    def _on_busy(self) -> None:
        ctl = self.ctl
        io_busy = ctl.runner.is_busy() or ctl.io_runner.is_busy() or ctl.nc_runner.is_busy()
        self.busy_bar.setRange(0, 0 if io_busy else 1)
        self.busy_bar.setVisible(io_busy)
        computing = ctl.pipe_runner.is_busy() or ctl.tl_runner.is_busy() or ctl.laws_runner.is_busy()
        self.progress_bar.setVisible(computing)
        self.cancel_button.setVisible(computing)
        self.actions["cancel"].setEnabled(computing)
        self.view3d.set_busy(self.busy())
        self._update_run_state()

    # -- edits -----------------------------------------------------------------------------------
    def _sync_panels(self, source: str | None) -> None:
        """Show the job in every section panel (the ``source`` panel keeps what the user typed)."""
        for key, panel in self.section_panels.items():
            if key == source:
                panel.job = self.job
            else:
                panel.set_job(self.job)
        if source == "layers":
            self.layers_panel.job = self.job
        else:
            self.layers_panel.set_job(self.job)
        self._update_title()

    def _on_spec_edited(self, spec: Any) -> None:
        self.plot.show_message("")
        self.ctl.queue_edit(self.job.replace(mandrel=spec), "edit")
        self._update_run_state()

    def _on_points_edited(self, z: Any, r: Any) -> None:
        if isinstance(self.job.mandrel, SegmentsSpec):  # a joint of the sketch dragged on the plot
            try:
                seg = apply_handles(self.job.mandrel, z, r)
            except ValueError as exc:
                self.plot.revert_points()
                self.plot.show_message(tr("Not applied: {exc}").format(exc=exc))
                return
            self.ctl.queue_edit(self.job.replace(mandrel=seg), "points")
            return
        try:
            spec = PointsSpec(z_mm=[float(v) for v in z], r_mm=[float(v) for v in r])
        except ValueError as exc:  # pydantic: not finite
            self.plot.revert_points()
            self.plot.show_message(tr("Not applied: {exc}").format(exc=exc))
            return
        self.ctl.queue_edit(self.job.replace(mandrel=spec), "points")

    def _convert_to_points(self) -> None:
        if self.view_data is None:
            self.mandrel_panel.set_spec(self.job.mandrel)
            return
        self.ctl.build("points", convert_task, self.job, self.mandrel, self.job_path)

    def _convert_to_sketch(self) -> None:
        if self.view_data is None:
            self.mandrel_panel.set_spec(self.job.mandrel)
            return
        self.ctl.build("points", sketch_task, self.job, self.mandrel, self.job_path)

    def _toggle_auto_run(self, on: bool) -> None:
        self.auto_run = bool(on)

    # -- run state -------------------------------------------------------------------------------
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
        return self.layers_panel.errors()

    def export_block_reason(self) -> str:
        """Why Export NC is disabled ('' when allowed): invalid job, no program or out-of-date results."""
        return self.ctl.export_block_reason()

    def _update_run_state(self) -> None:
        if not hasattr(self, "actions"):
            return
        reason = self.run_block_reason()
        running = self.ctl.pipe_runner.is_busy()
        self.actions["run"].setEnabled(not reason)
        self.actions["run"].setToolTip(tr("Run disabled: {reason}")
                                       .format(reason=reason) if reason else tr("Run the pipeline (F5)"))
        self.nc_panel.set_run_state(not reason, reason, running)
        self.timelaw_panel.compute_button.setEnabled(not self.timelaw_panel.errors())
        why = self.export_block_reason()
        self.actions["export_nc"].setEnabled(not why)
        self.actions["export_nc"].setToolTip(texts.export_refused(why) if why else tr("Export the NC program"))
        self.actions["export_report"].setEnabled(not why)
        self.nc_panel.set_export_state(texts.export_refused(why) if why else "")

    # -- pipeline ----------------------------------------------------------------------------------
    def run_pipeline_now(self, upto: str = "nc", explicit: bool = True) -> bool:
        """Run the pipeline on the current job (in the worker); False, with the reason shown, when a
        field is bad."""
        reason = self.run_block_reason()
        if reason:
            self._status(tr("Run disabled: {reason}").format(reason=reason), error=True)
            return False
        return self.ctl.run_now(upto, explicit)

    def cancel_run(self) -> None:
        """Stop every computation in flight (pipeline, law comparison, time law)."""
        self.ctl.cancel()

    def _on_pipe_progress(self, fraction: float, message: str) -> None:
        self.progress_bar.setValue(int(round(1000 * min(max(fraction, 0.0), 1.0))))
        if message:
            self.progress_bar.setToolTip(message)
            self.progress_bar.setFormat(f"{message} %p%")

    def _on_pipe_failed(self, exc: BaseException, tb: str) -> None:
        shown = False
        if isinstance(exc, InputError) and exc.location.field:
            fld = exc.location.field
            for panel in self.section_panels.values():
                shown = panel.show_error(fld, exc.message) or shown
            if fld.startswith("mandrel"):
                self.mandrel_panel.show_error(fld, exc.message)
                shown = True
            if fld.startswith("layer"):
                shown = self.layers_panel.show_error(fld, exc.message) or shown
        msg = exc.message if isinstance(exc, InputError) else str(exc)
        self.nc_panel.summary.setText(tr("<span style='color:#c01010'>Not computed: {msg}</span>").format(msg=msg))
        if self.ctl.explicit or not shown:
            self.report_dialog(tr("The pipeline stopped"), exc, tb)
        else:
            self._status(tr("Pipeline stopped: {msg}").format(msg=msg), error=True)
            self.error_reported.emit(msg)
        self._update_run_state()

    def compute_timelaw(self) -> None:
        """The time law (tube, DP, TOPP-RA) of the law chosen above the plot, in the worker."""
        self.results.compute_timelaw()

    def _on_timelaw_failed(self, exc: BaseException, tb: str) -> None:
        self.timelaw_panel.summary.setText("")
        if not self.timelaw_plot.has_data():
            self.timelaw_plot.set_message(tr(texts.NO_DATA))
        self.report_dialog(tr("Time law failed"), exc, tb)

    # -- NC export -----------------------------------------------------------------------------------
    def export_nc(self, path: str | Path, force: bool | None = None) -> bool:
        """Write the NC program of the run on screen to ``path`` (see :func:`window_exports.export_nc`)."""
        return window_exports.export_nc(self, path, force)

    def open_nc(self, path: str | Path) -> None:
        """Read an NC program back on the job's machine (worker) and draw its eye path and laid fibre."""
        self._status(tr("Reading {v0} back on {template}…")
                     .format(v0=Path(path).name, template=self.job.machine.template))
        self.ctl.read_nc(Path(path))

    def _on_nc_read(self, out: Any) -> None:
        self.nc_readback = out
        self.view3d.set_paths(out.paths)
        r = out.report
        viol = r.get("violations", [])
        fibre = f", laid fibre {r['fibre_length_mm'] / 1000:.2f} m" if "fibre_length_mm" in r else ""
        msg = (f"{out.path.name} on {r['machine']} ({r['controller']}): {r['moves']} moves, program time "
               f"{r['program_time_s']:.2f} s (with the limits {r['time_with_limits_s']:.2f} s){fibre}; "
               + (f"{len(viol)} kind(s) of limit violation: {viol[0]['message']}" if viol else "within every limit"))
        self._status(msg, error=bool(viol))
        self.nc_read.emit(out)

    def _on_nc_written(self, path: Path) -> None:
        what = "the job report" if path.suffix.lower() in (".pdf", ".html", ".htm") else "the NC program"
        self._status(tr("Wrote {what} to {path}").format(what=what, path=path))
        self.nc_written.emit(path)

    def export_report(self, path: str | Path) -> bool:
        """Write the job report of the run on screen (see :func:`window_exports.export_report`)."""
        return window_exports.export_report(self, path)

    def action_export_report(self) -> None:
        window_exports.action_export_report(self)

    def action_export_nc(self) -> None:
        window_exports.action_export_nc(self)

    # -- steps, view -------------------------------------------------------------------------------
    def go_to_step(self, key: str) -> None:
        """Select step ``key`` in the step bar (its page and plot tab are shown)."""
        for i in range(self.steps.count()):
            if self.steps.item(i).data(Qt.ItemDataRole.UserRole) == key:
                self.steps.setCurrentRow(i)
        self._on_step(key)

    def _on_step(self, key: str) -> None:
        if key in self.step_pages:
            self.properties.setCurrentIndex(self.step_pages[key])
        tab = self.tabs.get(STEP_TABS.get(key, ""))
        if tab is not None:
            self.plot_tabs.setCurrentWidget(tab)
        if key == "timelaw" and self.timelaw_plot.selected_law() >= 0 and not self.ctl.tl_runner.is_busy() \
                and not self.results.law_shown():
            self.results.show_chosen_law()

    def _toggle_play(self) -> None:
        if self.view3d.is_playing():
            self.view3d.pause()
        else:
            self.view3d.play()

    def open_tool(self, key: str, module: str, cls_name: str) -> QWidget | None:
        """Open a tool dialog ``module.cls_name(parent)`` (imported lazily); a message if unavailable."""
        return window_menus.open_tool(self, key, module, cls_name)

    def screenshot(self) -> QImage:
        """The window as an image, with the GL-drawn 3D view composed in (for docs and tests)."""
        img = self.grab().toImage()
        view = self.view3d.render_image()
        gl = self.view3d.gl_widget
        if view is not None and gl is not None:
            painter = QPainter(img)
            painter.drawImage(QRect(gl.mapTo(self, QPoint(0, 0)), gl.size()), view)
            painter.end()
        return img

    # -- settings ----------------------------------------------------------------------------------
    def recent_files(self) -> list[str]:
        return recent_files()

    def _restore_settings(self) -> None:
        window_layout.restore_layout(self)

    def save_settings(self) -> None:
        """Write the window layout and options to the settings."""
        window_layout.save_layout(self)

    # -- autosave ----------------------------------------------------------------------------------
    def autosave_path(self) -> Path:
        """Where this job's autosave copy goes (see :meth:`JobDocument.autosave_path`)."""
        return self.doc.autosave_path()

    def autosave_now(self) -> Path | None:
        """Write the job to the autosave folder (atomically) if it has unsaved changes."""
        return self.doc.autosave_now()

    def drop_autosave(self) -> None:
        """Remove this window's autosave copy (after a save or a deliberate close)."""
        self.doc.drop_autosave()

    def pending_autosaves(self) -> list[Path]:
        """Autosave copies left by an earlier session, not another live instance's."""
        return self.doc.pending_autosaves()

    def restore_autosave(self, path: str | Path) -> None:
        """Load an autosave copy as the current job (unsaved; its file is the job it was made of)."""
        p = Path(path)
        try:
            job = self.doc.claim_autosave(p)
        except PermissionError as exc:
            self._status(str(exc), error=True)
            return
        except (InputError, OSError) as exc:
            self.report_dialog(tr("Could not restore the autosaved job"), exc)
            return
        self.ctl.build("restore", build_task, job, autosave_origin(p))

    def offer_autosaves(self) -> None:
        """Ask, for each leftover autosave copy, whether to restore it (the first accepted is loaded)."""
        window_menus.offer_autosaves(self)

    # -- messages, closing ---------------------------------------------------------------------------
    def _status(self, msg: str, error: bool = False) -> None:
        self.status_msg.setText(msg)
        self.status_msg.setStyleSheet("color: #c01010;" if error else "")

    def report_dialog(self, title: str, exc: BaseException | str, tb: str = "") -> None:
        """Show an error in a (non-blocking, window-modal) dialog; never a traceback."""
        if tb and not isinstance(exc, InputError | OSError):
            print(tb, file=sys.stderr)
        text = exc if isinstance(exc, str) else texts.describe_error(exc)
        self.last_error = f"{title}\n{text}"
        self._status(f"{title}: {text.splitlines()[-1] if text else ''}", error=True)
        box = QMessageBox(QMessageBox.Icon.Warning, title, text, QMessageBox.StandardButton.Ok, self)
        if isinstance(exc, InputError | OSError):
            box.setInformativeText(tr(texts.NOTHING_CHANGED))
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()
        self.error_box = box
        self.error_reported.emit(self.last_error)

    _report_dialog = report_dialog

    def _may_discard(self) -> bool:
        """True if the job may be replaced: saved, not asked, or the user agreed (Save/Discard)."""
        if not self.dirty or not self.confirm_discard:
            return True
        ans = QMessageBox.question(
            self, tr("Unsaved changes"), tr("The job \"{name}\" has unsaved changes. Save them first?")
                                         .format(name=self.job.name),
            QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Cancel,
            QMessageBox.StandardButton.Save)
        if ans == QMessageBox.StandardButton.Save:
            return self.save_job()
        return ans == QMessageBox.StandardButton.Discard

    def closeEvent(self, event: QCloseEvent) -> None:  # noqa: N802 - Qt override
        if not self._may_discard():
            event.ignore()
            return
        self._autosave_timer.stop()
        self.save_settings()
        self.drop_autosave()
        self.ctl.shutdown()
        self.view3d.close_backend()
        for dlg in list(self.dialogs.values()):
            try:
                dlg.close()
            except RuntimeError:
                pass
        event.accept()
