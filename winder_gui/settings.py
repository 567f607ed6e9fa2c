"""The persistent settings of the application (QSettings) and the recent-files list.

A module of its own so that views and panels can read settings without importing the window.
"""

from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QSettings

SETTINGS_ENV = "WINDER_SETTINGS"
"""An .ini file to keep the settings in instead of the user's (tests, portable use)."""
NO_PROMPT_ENV = "WINDER_NO_PROMPT"
"""Set to 1 to close/replace a job with unsaved changes without asking (tests, scripts)."""
MAX_RECENT = 8
"""How many recently opened jobs File -> Open Recent keeps."""


def app_settings() -> QSettings:
    """The persistent settings (``WINDER_SETTINGS``: an .ini file instead of the user's)."""
    path = os.environ.get(SETTINGS_ENV, "")
    if path:
        return QSettings(path, QSettings.Format.IniFormat)
    return QSettings("winder", "winder")


def prompts_enabled() -> bool:
    """False when ``WINDER_NO_PROMPT`` asks never to ask before discarding unsaved changes."""
    return os.environ.get(NO_PROMPT_ENV, "") in ("", "0")


def recent_files() -> list[str]:
    """The recently opened job files, newest first (absolute paths)."""
    val = app_settings().value("recent", [])
    if isinstance(val, str):
        val = [val]
    return [str(v) for v in (val or [])]


def add_recent(path: str | Path) -> list[str]:
    """Put ``path`` first in the recent-files list (at most :data:`MAX_RECENT`); the new list."""
    p = str(Path(path).resolve())
    rec = [p, *[r for r in recent_files() if r != p]][:MAX_RECENT]
    app_settings().setValue("recent", rec)
    return rec


MEMORY_KEY = "memory_budget"
"""Settings key of the memory budget (text such as ``8G``; absent: the engine's default)."""


def apply_memory_budget() -> int:
    """Give the engine the memory budget kept in the settings (:mod:`engine.budget`); the bytes in force."""
    from engine import budget
    from engine.errors import InputError

    budget.set_results_materialised(True)  # the views read whole arrays: a big program is materialised here
    text = str(app_settings().value(MEMORY_KEY, "") or "")
    try:
        budget.set_max_memory(budget.parse_size(text) if text else None)
    except InputError:
        budget.set_max_memory(None)  # a damaged setting must not stop the application
    return budget.max_memory_bytes()


def set_memory_budget(text: str) -> int:
    """Keep ``text`` (e.g. ``"8G"``; empty = the default) as the memory budget and apply it; the bytes.

    Raises :class:`engine.errors.InputError` for text that is not a size (nothing changes)."""
    from engine import budget

    if text.strip():
        budget.parse_size(text.strip(), field="Memory budget")
    app_settings().setValue(MEMORY_KEY, text.strip())
    return apply_memory_budget()
