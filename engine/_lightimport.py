"""Lighter imports of the SciPy parts the engine uses (issue 16: a one-shot ``winder run`` is a fresh process).

Two measured costs of a ``winder run`` that are not computation:

* SciPy's vendored array-API layer (``scipy._lib.array_api_compat.numpy``, imported by every SciPy
  subpackage) clones NumPy's namespace with ``from numpy import *`` and ``hasattr`` over ``dir(numpy)``.
  NumPy 2 lists its lazily imported submodules in ``__all__`` and ``__dir__``, so that clone imports
  ``numpy.f2py``, ``numpy.testing`` and what they pull in (``unittest``, ``email``, ``charset_normalizer``,
  ...): ~0.08 s of CPU, for names (``f2py``, ``testing``, ``ma``, ``random``, ...) that are not part of
  the array API and that SciPy's array-API code uses only for CuPy and PyTorch.  :func:`install` hides
  those not-yet-imported submodules from NumPy's ``__all__``/``__dir__`` while that one module is
  executed, and restores both right after; ``numpy.testing`` and the rest stay importable as before.
* The narrowest-band LP needs only SciPy's HiGHS extension (``scipy.optimize._highspy._core``) and the
  clearance distances only SciPy's k-d tree (``scipy.spatial._ckdtree``), but importing either runs its
  package's ``__init__`` first: ``scipy.optimize``'s imports all its solvers and ``scipy.spatial``,
  ``scipy.spatial``'s imports ``distance``, ``transform`` and ``scipy.special`` (~0.06 s and ~0.1 s).
  :func:`extension_module` loads such an extension from its file under its own name, holding that
  module's own import lock (the lock the ordinary import machinery takes for it, never the
  interpreter-wide lock, which could deadlock with a thread importing SciPy), and registers it in
  ``sys.modules``: a later ``import scipy.optimize`` or ``import scipy.spatial`` then uses this module
  and does not load the extension a second time (:func:`ckdtree` is ``scipy.spatial.cKDTree``).

Both change nothing numerical: the same modules run the same code.
"""

from __future__ import annotations

import sys
from typing import Any

_CLONE_MODULE = "scipy._lib.array_api_compat.numpy"
# NumPy's lazily imported public submodules that the array-API clone does not need (not array-API names)
_HIDDEN = ("f2py", "testing", "ctypeslib", "rec", "char", "strings", "ma", "polynomial", "random", "test",
           "core")


class _HiddenLazySubmodules:
    """Context: NumPy's not-yet-imported submodules of :data:`_HIDDEN` left out of ``numpy.__all__`` and
    ``dir(numpy)``; both restored on exit."""

    def __enter__(self) -> None:
        self._np: Any = sys.modules.get("numpy")
        self._saved: tuple[Any, Any] | None = None
        np = self._np
        if np is None:
            return
        hide = {n for n in _HIDDEN if f"numpy.{n}" not in sys.modules}
        names = getattr(np, "__all__", None)
        dir_fn = np.__dict__.get("__dir__")
        if not hide or not isinstance(names, list) or dir_fn is None:
            return
        self._saved = (names, dir_fn)
        np.__all__ = [n for n in names if n not in hide]
        np.__dir__ = lambda: [n for n in dir_fn() if n not in hide]

    def __exit__(self, *exc: object) -> None:
        if self._saved is not None:
            self._np.__all__, self._np.__dir__ = self._saved


class _Loader:
    """A module loader running ``inner``'s ``exec_module`` inside :class:`_HiddenLazySubmodules`."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    def create_module(self, spec: Any) -> Any:
        return self._inner.create_module(spec)

    def exec_module(self, module: Any) -> None:
        with _HiddenLazySubmodules():
            self._inner.exec_module(module)

    def __getattr__(self, name: str) -> Any:  # get_code, get_resource_reader, ... of the real loader
        return getattr(self._inner, name)


class _CloneFinder:
    """A ``sys.meta_path`` finder that answers once, for :data:`_CLONE_MODULE`, with the ordinary spec and
    its loader wrapped in :class:`_Loader`; it removes itself when it answers."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != _CLONE_MODULE:
            return None
        uninstall()
        from importlib.machinery import PathFinder

        spec = PathFinder.find_spec(name, path)
        if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _Loader(spec.loader)
        return spec


_FINDER = _CloneFinder()


def install() -> None:
    """Make SciPy's array-API layer skip importing NumPy's unused lazy submodules (see the module's
    docstring); a no-op once that layer is imported."""
    if _CLONE_MODULE not in sys.modules and _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


def uninstall() -> None:
    """Remove the finder :func:`install` added (nothing else changes)."""
    try:
        sys.meta_path.remove(_FINDER)
    except ValueError:
        pass


def extension_module(name: str) -> Any | None:
    """The compiled extension module ``name`` (e.g. ``"scipy.optimize._highspy._core"``), loaded from its
    file without importing its parent packages' ``__init__`` when they are not imported yet (see the
    module's docstring); the ordinary import when they are.  None when it cannot be found or loaded."""
    mod = sys.modules.get(name)
    if mod is not None:
        return mod
    parent = name.rpartition(".")[0]
    if parent in sys.modules:
        return _ordinary(name)
    try:
        import importlib.machinery
        import importlib.util
        import os
        from importlib._bootstrap import _ModuleLockManager  # type: ignore[attr-defined]

        top = __import__(name.partition(".")[0])
        folder = os.path.join(os.path.dirname(top.__file__), *name.split(".")[1:-1])
        leaf = name.rpartition(".")[2]
        path = next((os.path.join(folder, leaf + suf) for suf in importlib.machinery.EXTENSION_SUFFIXES
                     if os.path.isfile(os.path.join(folder, leaf + suf))), None)
    except Exception:  # noqa: BLE001 - any other layout (frozen build, other Python): the ordinary import
        return _ordinary(name)
    if path is None:
        return _ordinary(name)
    try:
        with _ModuleLockManager(name):  # the lock an ordinary import of `name` takes: it waits, then finds it
            mod = sys.modules.get(name)
            if mod is None:
                try:
                    loader = importlib.machinery.ExtensionFileLoader(name, path)
                    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
                    if spec is None:
                        raise ImportError(name)
                    new = importlib.util.module_from_spec(spec)
                    loader.exec_module(new)
                except Exception:  # noqa: BLE001
                    new = None
                if new is not None:
                    sys.modules[name] = new
                mod = new
    except RuntimeError:  # the import machinery's deadlock detection (another thread holds what we wait for)
        mod = sys.modules.get(name)
    return mod if mod is not None else _ordinary(name)


def ckdtree() -> Any:
    """SciPy's ``cKDTree`` class, from its extension (``scipy.spatial._ckdtree``) without importing the
    rest of ``scipy.spatial`` (its ``__init__`` imports ``distance``, ``transform`` and ``scipy.special``:
    ~0.1 s of a one-shot run that needs the k-d tree alone); ``scipy.spatial.cKDTree`` is the same class."""
    mod = extension_module("scipy.spatial._ckdtree")
    if mod is not None and hasattr(mod, "cKDTree"):
        return mod.cKDTree
    from scipy.spatial import cKDTree

    return cKDTree


def _ordinary(name: str) -> Any | None:
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError:
        return None


def flapack() -> Any:
    """SciPy's LAPACK wrappers (``scipy.linalg._flapack``: ``dgtsv``, ``dpbtrf``, ``dpbtrs``, ... -- the
    functions ``scipy.linalg.lapack`` re-exports) without importing ``scipy.linalg`` (~0.03 s of a one-shot
    run whose only use of it is two banded solves); ``scipy.linalg.lapack`` where that file is absent."""
    mod = extension_module("scipy.linalg._flapack")
    if mod is not None and all(hasattr(mod, f) for f in ("dgtsv", "dpbtrf", "dpbtrs")):
        return mod
    import scipy.linalg.lapack as lapack

    return lapack
