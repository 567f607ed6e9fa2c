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
