"""The time law's compiled kernels built ahead of time (issue 16): no numba at run time.

:mod:`engine.timeparam_jit` compiles the time law's hot loops with numba, bit for bit the numpy passes'
answers.  numba's just-in-time kernels cost ~0.5 s of CPU to load in every process (numba's import and its
registries, then the cached machine code), more than they save on the examples' laws, so a one-shot
``winder run`` used to run the numpy passes (3-5x slower).  This module compiles the same kernels ahead
of time into an extension module, ``engine._timeparam_kernels``, with numba's own AOT compiler
(``numba.pycc``) at install time (``make venv``, or ``python -m engine.timeparam_aot``).  Importing it
takes well under a millisecond and needs neither numba nor llvmlite, so every run, the frozen build
included, gets the compiled kernels from its first law.

The same numba code, compiled by the same LLVM without fast-math, gives the same bits as the
just-in-time kernels (``tests/test_timeparam_aot.py`` compares all three on the tests' problems and the
examples' programs).  What an AOT module does not do is check its arguments (a wrong dtype, rank or
memory layout is read as raw memory), so :func:`load` wraps every kernel in a check of each argument
against the kernel's signature (:data:`KERNELS`); an argument that does not match goes to numba's
just-in-time kernel instead (a bug to fix, counted in :data:`MISSES`).

The module records a stamp of the kernels' source (:func:`source_stamp`: ``engine/timeparam_jit.py``); a
module built from other source is not used (numba's just-in-time kernels or the numpy passes run until it
is rebuilt: the same answers, slower).  ``WINDER_AOT=0`` switches it off,
``WINDER_NUMBA=0`` switches off every compiled kernel.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

MODULE = "engine._timeparam_kernels"
"""The extension module the build writes into the ``engine`` package."""

# every kernel of engine.timeparam_jit: (builder in engine.timeparam_jit, index in what it returns or None,
# argument types).  "f8:2" is a C-contiguous float64 array of 2 dimensions; "f8", "i8", "b1" scalars.
KERNELS: dict[str, tuple[str, int | None, tuple[str, ...]]] = {
    "forward": ("_build_kernel", None,
                ("f8:1", "i8:2", "i8:2", "b1:2", "f8:1", "f8:1", "b1", "i8", "i8", "i8", "i8:1")),
    "windows": ("_build_windows", None,
                ("f8:2", "f8:2", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "i8", "f8:1", "f8:1", "b1:1", "f8:1",
                 "f8:1", "i8:1", "i8:1", "i8", "i8:2", "i8:2", "b1:2")),
    "dp_pass": ("_build_fused", None,
                ("f8:1", "f8:1", "f8:1", "f8:1", "f8:2", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1",
                 "i8", "f8:1", "f8:1", "b1:1", "f8:1", "f8:1", "i8:1", "i8:1", "i8", "f8:1", "f8:1", "b1", "i8",
                 "b1", "i8", "i8", "i8:1", "i8:1", "f8:1")),
    "chains": ("_build_chains", None,
               ("f8:3", "i8:2", "i8:1", "i8", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1",
                "f8:1", "f8:1", "f8:1", "f8:1", "f8:1")),
    "limits": ("_build_limits", None, ("f8:3", "f8:3", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1")),
    "rows": ("_build_rows", None, ("f8:3", "f8:3", "f8:1", "f8", "f8:3", "f8:3")),
    "groups": ("_build_groups", None, ("f8:3", "i8:2", "b1:2", "b1:2", "i8:2", "f8:2", "b1:2", "f8:3", "f8:3")),
    "sweep_back": ("_build_sweep", 0,
                   ("f8:1", "f8:1", "f8:1", "f8:1", "i8", "f8:1", "f8:1", "f8:1", "f8:1", "f8", "f8:1", "f8:1")),
    "sweep_fwd": ("_build_sweep", 1, ("f8:3", "f8:1", "f8:1", "f8:1", "f8", "f8", "f8", "f8:1")),
    "hull_graham": ("_build_hull_sym", 0, ("f8:2", "f8:2", "f8:2", "f8:2", "i8:2", "f8:1", "f8:1", "i8:2", "i8:1")),
    "hull_prep": ("_build_hull_sym", 1, ("f8:3", "i8:1", "i8:1", "f8:2", "f8:2", "i8:2", "f8:2")),
    "hull_assemble": ("_build_hull_sym", 2, ("i8:2", "i8:1", "i8:1", "i8:2", "i8:1")),
    "hulls": ("_build_hull", None, ("f8:3", "i8:2", "i8:1", "i8:1", "i8:1")),
}

MISSES: dict[str, int] = {}
"""Calls, by kernel, whose arguments did not match the compiled signature (they ran numba's kernel)."""

_DTYPES = {"f8": np.dtype(np.float64), "i8": np.dtype(np.int64), "b1": np.dtype(np.bool_)}
_NUMBA_TYPES = {"f8": "float64", "i8": "int64", "b1": "boolean"}


def source_stamp() -> int | None:
    """A 62-bit hash of the kernels' source, ``engine/timeparam_jit.py``, or None where it cannot be read (a
    frozen build: there the module was built from the very source that was frozen)."""
    try:
        data = Path(__file__).with_name("timeparam_jit.py").read_bytes()
    except OSError:
        return None
    return int.from_bytes(hashlib.sha256(data).digest()[:8], "little") >> 2


def _accepts(spec: tuple[str, ...]) -> Callable[[tuple[Any, ...]], bool]:
    """A check that a call's arguments have exactly the types of ``spec`` (see :data:`KERNELS`)."""
    arrays = [(i, _DTYPES[s[:2]], int(s[3:])) for i, s in enumerate(spec) if ":" in s]
    ints = [i for i, s in enumerate(spec) if s == "i8"]
    floats = [i for i, s in enumerate(spec) if s == "f8"]
    bools = [i for i, s in enumerate(spec) if s == "b1"]
    n = len(spec)
    nd = np.ndarray

    def ok(args: tuple[Any, ...]) -> bool:
        if len(args) != n:
            return False
        for i, dt, dim in arrays:
            a = args[i]
            if type(a) is not nd or a.dtype != dt or a.ndim != dim or not a.flags.c_contiguous:
                return False
        for i in ints:
            a = args[i]
            if isinstance(a, (bool, np.bool_)) or not isinstance(a, (int, np.integer)):
                return False
        for i in floats:
            if not isinstance(args[i], (float, int, np.floating, np.integer)) or isinstance(args[i], (bool, np.bool_)):
                return False
        return all(isinstance(args[i], (bool, np.bool_)) for i in bools)

    return ok


class _Guarded:
    """A compiled kernel behind a check of its arguments; a call that does not match runs ``fallback()``'s
    kernel (numba's, built on first need) instead."""

    __slots__ = ("name", "fn", "ok", "fallback", "_alt")

    def __init__(self, name: str, fn: Callable[..., Any], spec: tuple[str, ...],
                 fallback: Callable[[], Any]) -> None:
        self.name, self.fn, self.ok, self.fallback = name, fn, _accepts(spec), fallback
        self._alt: Any = None

    def __call__(self, *args: Any) -> Any:
        if self.ok(args):
            return self.fn(*args)
        MISSES[self.name] = MISSES.get(self.name, 0) + 1
        if self._alt is None:
            self._alt = self.fallback()
            if self._alt is None:
                raise TypeError(f"time-law kernel {self.name}: arguments {[type(a).__name__ for a in args]} do not "
                                f"match its compiled signature and numba is not available")
        return self._alt(*args)


_LOADED: list[dict[str, _Guarded] | None] = []


def load(fallback: Callable[[str], Any]) -> dict[str, _Guarded] | None:
    """The ahead-of-time kernels by name, each behind its argument check (``fallback(name)``: numba's kernel
    for a call that does not match, or None), or None: not built, built from other source, or switched off
    (``WINDER_AOT=0``, ``WINDER_NUMBA=0``).  Loaded once per process."""
    if _LOADED:
        return _LOADED[0]
    out: dict[str, _Guarded] | None = None
    if os.environ.get("WINDER_AOT", "1") != "0" and os.environ.get("WINDER_NUMBA", "1") != "0":
        try:
            import importlib

            mod = importlib.import_module(MODULE)
        except ImportError:
            mod = None
        if mod is not None:
            stamp = source_stamp()
            if stamp is None or int(mod.stamp()) == stamp:
                out = {name: _Guarded(name, getattr(mod, name), spec, lambda n=name: fallback(n))
                       for name, (_b, _i, spec) in KERNELS.items() if hasattr(mod, name)}
                if len(out) != len(KERNELS):
                    out = None
    _LOADED.append(out)
    return out


def _signature(spec: tuple[str, ...]) -> list[Any]:
    """numba argument types of ``spec``."""
    from numba import types

    out = []
    for s in spec:
        base = getattr(types, _NUMBA_TYPES[s[:2]])
        out.append(types.Array(base, int(s[3:]), "C") if ":" in s else base)
    return out


def build(out_dir: str | Path | None = None, quiet: bool = False) -> Path:
    """Compile every kernel of :data:`KERNELS` into the extension module (in the ``engine`` package, or
    ``out_dir``); returns its path.  Needs numba (with its AOT compiler), setuptools and a C compiler."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc's pending-deprecation notice
        from numba import types
        from numba.pycc import CC

        from engine import timeparam_jit

        cc = CC(MODULE.rpartition(".")[2], source_module=sys.modules[__name__])
        cc.output_dir = str(out_dir if out_dir is not None else Path(__file__).parent)
        cc.verbose = not quiet
        built: dict[str, Any] = {}
        for name, (builder, index, spec) in KERNELS.items():
            if builder not in built:
                built[builder] = getattr(timeparam_jit, builder)()
            disp = built[builder] if index is None else built[builder][index]
            args = _signature(spec)
            disp.compile(tuple(args))
            cres = disp.overloads[tuple(args)]
            ret = types.unliteral(cres.signature.return_type)
            # the export calls numba's kernel, so that the kernel keeps its own options (error_model="numpy":
            # x/0 = inf, as in numpy); numba compiles it into the module
            names = ", ".join(f"a{i}" for i in range(len(spec)))
            ns: dict[str, Any] = {"_kernel": disp}
            exec(f"def export({names}):\n    return _kernel({names})\n", ns)  # noqa: S102 - generated wrapper
            cc.export(name, ret(*args))(ns["export"])
        stamp = source_stamp()
        if stamp is None:
            raise RuntimeError("the kernels' source cannot be read: nothing to stamp the module with")
        ns = {}
        exec(f"def stamp():\n    return {stamp}\n", ns)  # noqa: S102 - the source stamp as a constant
        cc.export("stamp", types.int64())(ns["stamp"])
        cc.compile()
    return Path(cc.output_dir) / cc._output_file


def main(argv: list[str] | None = None) -> int:
    """``python -m engine.timeparam_aot [--quiet]``: build the extension module (exit 1 where it cannot)."""
    args = sys.argv[1:] if argv is None else argv
    quiet = "--quiet" in args
    try:
        path = build(quiet=quiet)
    except Exception as exc:  # noqa: BLE001 - no numba.pycc, no compiler: the run falls back, it says why
        print(f"engine.timeparam_aot: not built ({type(exc).__name__}: {exc}); the time law uses numba's "
              f"just-in-time kernels or the numpy passes (the same answers)", file=sys.stderr)
        return 1
    print(f"engine.timeparam_aot: built {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
