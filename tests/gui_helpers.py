"""Helpers shared by the GUI tests (pytest puts this folder on sys.path): open and close a window."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def shown_window(qtbot: Any, path: Path | str | None = None) -> Any:
    """A :class:`~winder_gui.main_window.MainWindow` on ``path`` (the default job if None), shown,
    its first build finished; it never asks to save on close."""
    from winder_gui.main_window import MainWindow

    w = MainWindow(path)
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    return w


def close_window(w: Any, timeout_ms: int = 60000) -> None:
    """Let the window's workers finish, close an error dialog left open, close the window."""
    w.wait_idle(timeout_ms)
    if w.error_box is not None:
        try:
            w.error_box.close()
        except RuntimeError:  # already deleted on close
            pass
    w.close()
