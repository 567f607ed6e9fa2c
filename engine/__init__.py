"""Numerical core of the winder filament-winding CAD/CAM application.

Pure numpy/scipy; no Qt may be imported anywhere below this package (an import-linter
contract in ``pyproject.toml`` and ``tests/test_layering.py`` enforce it).

Units inside the engine: lengths in mm, angles in rad, time in s.
"""

__version__ = "0.1.0"

import os as _os

from engine import _lightimport

_lightimport.install()  # SciPy's array-API layer without NumPy's unused lazy submodules (issue 16)

# No third-party pydantic plugins for the job's models: their discovery reads the entry points of every
# installed distribution when the first model is built (~20 ms of every start; issue 16).  A user who sets
# PYDANTIC_DISABLE_PLUGINS keeps their setting.
_os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")
del _os
