"""Autosave copies of unsaved jobs and the locks that tell running instances' copies apart.

A dirty job is written atomically every :data:`AUTOSAVE_MS` to ``AppDataLocation/autosave/<name>.toml``
(by :class:`winder_gui.document.JobDocument`); a leftover copy is offered on the next start.  Each
copy is locked (:class:`AutosaveOwner`, a QLockFile) by the running instance writing it: a second
instance neither offers, restores, deletes nor overwrites it (it writes ``<name>-2.toml``), while the
copy of a killed instance (stale lock: its PID is gone) is offered as before.
"""

from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QLockFile, QStandardPaths

AUTOSAVE_MS = int(os.environ.get("WINDER_AUTOSAVE_MS", "30000") or 30000)
"""How often a job with unsaved changes is written to the autosave folder."""
AUTOSAVE_ENV = "WINDER_AUTOSAVE_DIR"
"""A folder for autosave copies instead of AppDataLocation/autosave."""
AUTOSAVE_HEADER = "# winder autosave of: "
"""First line of an autosave copy, followed by the job file it was made of (or "(not saved)")."""


def autosave_dir() -> Path:
    """The folder of autosave copies (``WINDER_AUTOSAVE_DIR`` or AppDataLocation/autosave)."""
    env = os.environ.get(AUTOSAVE_ENV, "")
    if env:
        return Path(env)
    base = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.AppDataLocation)
    return Path(base or Path.home() / ".winder") / "autosave"


def slug(name: str) -> str:
    """``name`` as a safe file stem (letters, digits, - _ . kept; others as _)."""
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
