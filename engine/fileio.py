"""Atomic file output: write to a temporary file beside the target, then rename.

A crash or a full disk never leaves a half-written file where the user's file was.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    return atomic_write_with(path, lambda tmp: Path(tmp).write_bytes(data))


def atomic_write_text(path: str | Path, text: str, newline: str | None = "\n") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; ``newline`` as in :func:`open`."""

    def _write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline=newline) as fh:
            fh.write(text)

    return atomic_write_with(path, _write)


def atomic_write_with(path: str | Path, writer: Callable[[str], object], suffix: str = "") -> Path:
    """Call ``writer(tmp_path)`` to produce the file, then rename it onto ``path``.

    ``suffix`` is given to the temporary name (some writers, e.g. STEP/STL exporters, pick the
    format from the extension; by default the target's suffix is used).
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix, dir=directory)
    os.close(fd)
    try:
        writer(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        if path.exists():
            try:
                os.chmod(tmp, path.stat().st_mode & 0o7777)
            except OSError:
                pass
        else:
            os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path
