"""The job document: the state of one open job that every panel and view observes.

:class:`JobDocument` holds the :class:`engine.job.Job`, its file, the built mandrel, whether it has
unsaved changes, the undo stack of job snapshots, the latest pipeline result with the job it was
computed for (so any later edit makes the result *stale*), and the job's autosave copy.  It has no
widgets: panels show it and send edits to it, the window wires the two (as napari's ``ViewerModel``
is kept apart from its ``QtViewer``).  A new panel observes the document by connecting to its
signals (:attr:`JobDocument.job_changed`, :attr:`JobDocument.results_changed`,
:attr:`JobDocument.stale_changed`) and edits it with :meth:`JobDocument.edit`.

Computations that need a worker (building a mandrel, running the pipeline) belong to
:class:`winder_gui.run_controller.RunController`; the document only records their outcome.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QUndoCommand, QUndoStack

from engine.fileio import atomic_write_text
from engine.job import FileSpec, Job, default_job, load_job
from engine.job import save_job as write_job
from winder_gui import texts
from winder_gui.autosave import AUTOSAVE_HEADER, AutosaveOwner, autosave_dir, process_autosave_owner, slug
from winder_gui.i18n import tr
from winder_gui.settings import add_recent
from winder_gui.tasks import BuildResult, profile_ref

if TYPE_CHECKING:
    from engine.mandrel import Mandrel
    from winder_gui.views.geometry import MandrelViewData

FRESH_PURPOSES = ("open", "new", "restore")
"""Builds that replace the document (a new undo history, results cleared)."""


class JobSnapshot(QUndoCommand):
    """One edit of the job: the job before and after (immutable pydantic models)."""

    def __init__(self, doc: JobDocument, before: Job, after: Job, text: str) -> None:
        super().__init__(text)
        self._doc = doc
        self.before = before
        self.after = after
        self._first = True

    def redo(self) -> None:  # noqa: D102 - Qt override
        if self._first:  # the edit is already applied when the command is pushed
            self._first = False
            return
        self._doc.restore(self.after)

    def undo(self) -> None:  # noqa: D102 - Qt override
        self._doc.restore(self.before)


class JobDocument(QObject):
    """The open job and everything derived from it (see the module docstring).

    Signals
    -------
    job_changed(source):
        ``job`` was replaced; ``source`` is the key of the panel that made the edit (it keeps what
        the user typed) or ``None``.
    edited():
        The user changed the job (an edit, undo or redo), not an open or save.
    mandrel_changed(BuildResult):
        A newly built mandrel is the document's.
    dirty_changed(bool), path_changed(object):
        Unsaved changes / the job's file changed.
    results_changed(object):
        The pipeline result (or ``None``) was replaced.
    stale_changed(bool):
        The results no longer describe the job shown (an edit after the run), or do again.
    rebuild_requested(Job):
        Undo/redo reached a job with another mandrel: it must be built (by the run controller).
    status(str, bool):
        A message for the status bar (``True``: an error).
    """

    job_changed = Signal(object)
    edited = Signal()
    mandrel_changed = Signal(object)
    dirty_changed = Signal(bool)
    path_changed = Signal(object)
    results_changed = Signal(object)
    stale_changed = Signal(bool)
    rebuild_requested = Signal(object)
    status = Signal(str, bool)

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.job: Job = default_job()
        self.path: Path | None = None
        self.mandrel: Mandrel | None = None
        self.view_data: MandrelViewData | None = None
        self.dirty = False
        self.undo_stack = QUndoStack(self)
        self.result: Any = None
        """Latest :class:`engine.pipeline.PipelineResult` (possibly partial, after a cancel or error)."""
        self.result_job: Job | None = None
        """The job ``result`` was computed for."""
        self.run_warnings: list[str] = []
        self.run_violations: list[Any] = []
        self.checked: Any = None
        """The result whose warnings and violations are ``run_warnings`` / ``run_violations``."""
        self.edits_pending = False
        """An edit is typed but not applied yet (debounce, mandrel build in flight)."""
        self.running = False
        """The pipeline computes the current job."""
        self.autosave_owner: AutosaveOwner = process_autosave_owner()
        """Holds the locks of this document's autosave copies (see :class:`AutosaveOwner`)."""
        self.autosaved: Path | None = None
        self._stale = False

    # -- the job -----------------------------------------------------------------------------------
    def edit(self, job: Job, source: str | None, text: str = "") -> bool:
        """Make ``job`` current as an undoable edit from panel ``source``; False when nothing changed."""
        if job == self.job:
            return False
        before = self.job
        self.job = job
        self.undo_stack.push(JobSnapshot(self, before, job, text or f"Edit {source}"))
        self.job_changed.emit(source)
        self.set_dirty(True)
        self.edited.emit()
        self.refresh_stale()
        return True

    def restore(self, job: Job) -> None:
        """Make ``job`` current again (undo/redo); asks for a rebuild if its mandrel differs."""
        if job.mandrel != self.job.mandrel:
            self.rebuild_requested.emit(job)
            return
        self.job = job
        self.job_changed.emit(None)
        self.set_dirty(True)
        self.edited.emit()
        self.refresh_stale()

    def commit_build(self, res: BuildResult, purpose: str) -> bool:
        """Make the built job ``res`` current (``purpose``: open, new, restore, import, edit, points,
        undo); returns True when it replaced the document (open, new, restore)."""
        before = self.job
        self.job = res.job
        self.mandrel = res.mandrel
        self.view_data = res.data
        fresh = purpose in FRESH_PURPOSES
        if fresh:
            self.set_path(res.path)
            self.undo_stack.clear()
            self.set_result(None)
            if purpose == "open" and res.path is not None:
                add_recent(res.path)
            self.set_dirty(purpose == "restore")
        else:
            if purpose != "undo" and before != res.job:
                self.undo_stack.push(JobSnapshot(self, before, res.job, f"Edit mandrel ({purpose})"))
            self.set_dirty(True)
        self.job_changed.emit(None)
        self.mandrel_changed.emit(res)
        self.refresh_stale()
        return fresh

    def set_dirty(self, dirty: bool) -> None:
        """Mark the job as changed since it was opened or saved."""
        self.dirty = bool(dirty)
        self.dirty_changed.emit(self.dirty)

    def set_path(self, path: Path | None) -> None:
        """The job's file (``None``: not saved yet)."""
        self.path = Path(path) if path is not None else None
        self.path_changed.emit(self.path)

    def start_dir(self) -> Path:
        """The folder file dialogs start in: the job's, else the working directory."""
        return self.path.parent if self.path is not None else Path.cwd()

    def file_stem(self) -> str:
        """A file name stem for exports: the job file's, else the job's name."""
        return self.path.stem if self.path is not None else slug(self.job.name)

    def save(self, target: Path) -> Path:
        """Write the job atomically to ``target`` (.toml added); profile paths are made relative to it.

        Raises :class:`engine.errors.InputError` / :class:`OSError`; the document is unchanged then.
        """
        if target.suffix == "":
            target = target.with_suffix(".toml")
        job = self.job
        if isinstance(job.mandrel, FileSpec):
            ref = profile_ref(self.start_dir() / job.mandrel.path, target)
            if ref != job.mandrel.path:
                job = job.replace(mandrel=FileSpec(path=ref))
        write_job(job, target)
        if job != self.job and self.result_job == self.job:
            self.result_job = job  # the same job, its profile referred to from its new folder
        self.job = job
        self.set_path(target)
        self.job_changed.emit(None)
        self.set_dirty(False)
        self.drop_autosave()
        add_recent(target)
        self.refresh_stale()
        return target

    # -- results -------------------------------------------------------------------------------------
    def set_result(self, result: Any, job: Job | None = None, warnings: list[str] | None = None,
                   violations: list[Any] | None = None) -> None:
        """The pipeline result computed for ``job`` (``None`` clears the results); ``warnings`` and
        ``violations`` as checked in the worker (``None``: keep those of an earlier check)."""
        self.result = result
        self.result_job = job if result is not None else None
        if warnings is not None or result is None:
            self.run_warnings = list(warnings or [])
            self.run_violations = list(violations or [])
            self.checked = result
        self.results_changed.emit(result)
        self.refresh_stale()

    def violations(self) -> list[Any]:
        """The limit violations of ``result`` (checked in the worker when available)."""
        if self.result is None:
            return []
        return self.run_violations if self.checked is self.result else list(self.result.violations)

    def results_current(self) -> bool:
        """True when ``result`` was computed for exactly the job shown, with no edit pending."""
        return self.result is not None and self.result_job == self.job and not self.edits_pending

    def is_stale(self) -> bool:
        """True when there are results but they do not describe the job shown (see :meth:`results_current`)."""
        return self.result is not None and not self.results_current()

    def refresh_stale(self) -> None:
        """Emit :attr:`stale_changed` when the staleness changed."""
        stale = self.is_stale()
        if stale != self._stale:
            self._stale = stale
            self.stale_changed.emit(stale)

    def set_edits_pending(self, pending: bool) -> None:
        self.edits_pending = bool(pending)
        self.refresh_stale()

    def set_running(self, running: bool) -> None:
        self.running = bool(running)
        self.refresh_stale()

    def export_block_reason(self) -> str:
        """Why the NC program may not be exported now ('' when it may): no program, or a stale one."""
        if self.result is None or self.result.nc_text is None:
            return tr(texts.EXPORT_NO_PROGRAM)
        if self.running and self.result_job != self.job:
            return tr(texts.EXPORT_RUNNING)
        if not self.results_current():
            return tr(texts.EXPORT_STALE)
        return ""

    # -- autosave ------------------------------------------------------------------------------------
    def autosave_path(self) -> Path:
        """Where this job's autosave copy goes: ``<name>.toml``, or ``<name>-2.toml``, … when that name
        is taken (another running instance's live copy, or a leftover copy not yet offered)."""
        name = self.path.stem if self.path is not None else self.job.name
        stem = slug(name)
        d = autosave_dir()
        names = [f"{stem}.toml", *(f"{stem}-{k}.toml" for k in range(2, 1000))]
        mine = self.autosaved
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
            origin = str(self.path.resolve()) if self.path is not None else "(not saved)"
            atomic_write_text(p, f"{AUTOSAVE_HEADER}{origin}\n{self.job.to_toml()}")
        except OSError as exc:
            if p is not None and p != self.autosaved and not p.exists():
                self.autosave_owner.release(p)      # a name locked for a copy that was never written
            self.status.emit(f"Autosave failed: {exc}", True)
            return None
        if self.autosaved is not None and self.autosaved != p:
            self.drop_copy(self.autosaved)
        self.autosaved = p
        return p

    def drop_copy(self, p: Path) -> None:
        """Delete autosave copy ``p`` and release its lock, if this document's owner holds it."""
        if not self.autosave_owner.holds(p):
            return
        try:
            p.unlink(missing_ok=True)
        except OSError:
            pass
        self.autosave_owner.release(p)

    def drop_autosave(self) -> None:
        """Remove this document's autosave copy (after a save or a deliberate close); never another
        running instance's, never a leftover nobody restored."""
        if self.autosaved is not None:
            self.drop_copy(self.autosaved)
        self.autosaved = None

    def pending_autosaves(self) -> list[Path]:
        """Autosave copies left by an earlier session (e.g. a killed process), not another live instance's."""
        d = autosave_dir()
        if not d.is_dir():
            return []
        return [p for p in sorted(d.glob("*.toml")) if p != self.autosaved and self.autosave_owner.is_free(p)]

    def claim_autosave(self, p: Path) -> Job:
        """Take autosave copy ``p`` as this document's and read its job (built by the caller).

        Raises :class:`PermissionError` when another running winder holds it, and
        :class:`engine.errors.InputError` / :class:`OSError` when it cannot be read (lock released).
        """
        if not self.autosave_owner.claim(p):
            raise PermissionError(f"{p.name} is the autosave of another running winder; not restored")
        try:
            job = load_job(p)
        except Exception:
            self.autosave_owner.release(p)
            raise
        if self.autosaved is not None and self.autosaved != p:
            self.drop_copy(self.autosaved)
        self.autosaved = p
        return job
