"""Where the shipped data files (``resources/``) are, from the source tree or a frozen build.

From source the folder is ``<repository>/resources``.  In the PyInstaller build
(``installer/winder.spec``) it is ``<bundle>/resources``, ``<bundle>`` being ``sys._MEIPASS``
(``dist/winder/_internal``).  The existing ``Path(__file__).resolve().parents[k] / "resources"``
look-ups give the same folder in the build (PyInstaller sets ``__file__`` of a bundled module
to ``<bundle>/<package>/<module>.pyc``); new code should call :func:`resource_path`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from engine.errors import InputError


def resources_root() -> Path:
    """The ``resources`` folder of this installation (it may not exist in a stripped install)."""
    bundle = getattr(sys, "_MEIPASS", None)
    if getattr(sys, "frozen", False) and bundle:
        return Path(bundle) / "resources"
    return Path(__file__).resolve().parents[1] / "resources"


def resource_path(*parts: str) -> Path:
    """Path of a shipped data file or folder, e.g. ``resource_path("machines", "lathe4.toml")``.

    Parameters
    ----------
    *parts : str
        Path components below ``resources/``.

    Returns
    -------
    pathlib.Path
        The absolute path (not checked for existence).
    """
    return resources_root().joinpath(*parts)


def read_toml(path: str | Path, what: str = "file") -> dict[str, Any]:
    """Parse a TOML data file; :class:`~engine.errors.InputError` naming the file (and line) otherwise.

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        What the file is, for the not-found message (``"machine template file"``).
    """
    from engine.fileio import loads_toml, read_text_limited

    p = Path(path)
    return loads_toml(read_text_limited(p, what=what), file=p)


def file_stamp(path: Path) -> tuple[str, tuple[int, int]] | None:
    """``(resolved path, (modification time in ns, size))`` of a data file, to keep what was read from it
    until it changes (machine templates, the materials file); None where it cannot be stat'ed (reading it
    then says what is wrong)."""
    try:
        st = path.stat()
        return str(path.resolve()), (st.st_mtime_ns, st.st_size)
    except OSError:
        return None


def list_named(directory: Path) -> list[str]:
    """Stems of the ``*.toml`` files in ``directory``, sorted (shipped machines, controllers, ...)."""
    return sorted(p.stem for p in Path(directory).glob("*.toml"))


def find_named(directory: Path, name_or_path: str | Path, what: str, field: str) -> Path:
    """A path given as such (``*.toml``), or the shipped file ``directory/<name>.toml``.

    Raises :class:`~engine.errors.InputError` naming the known names when a name is unknown.
    """
    p = Path(name_or_path)
    if p.suffix == ".toml":
        return p
    p = Path(directory) / f"{name_or_path}.toml"
    if not p.exists():
        raise InputError(f"unknown {what} {str(name_or_path)!r}; known: {', '.join(list_named(directory))}",
                         field=field)
    return p
