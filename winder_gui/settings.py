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
