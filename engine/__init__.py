"""Numerical core of the winder filament-winding CAD/CAM application.

Pure numpy/scipy; no Qt may be imported anywhere below this package (an import-linter
contract in ``pyproject.toml`` and ``tests/test_layering.py`` enforce it).

Units inside the engine: lengths in mm, angles in rad, time in s.
"""

__version__ = "0.1.0"

from engine import _lightimport

_lightimport.install()  # SciPy's array-API layer without NumPy's unused lazy submodules (issue 16)
