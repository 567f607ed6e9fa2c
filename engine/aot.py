"""The engine's compiled kernels built ahead of time (issue 16): no numba at run time.

:mod:`engine.timeparam_jit` compiles the time law's hot loops with numba, :mod:`engine.mandrel_jit` the
isotensoid dome's Chebyshev sums, :mod:`engine.payout_jit` the payout's interval propagation and interior
point, :mod:`engine.winding_jit` the Clairaut pass's integration, :mod:`engine.nearest_jit` the clearance
distances' nearest-vertex search, :mod:`engine.numtext_jit` the NC move lines' text; each kernel gives bit
for bit the answer of the code it replaces.
numba's just-in-time kernels cost ~0.5 s of CPU to load in every process (numba's import and its
registries, then the cached machine code), more than they save in a one-shot ``winder run``, which used to
run the numpy code (3-5x slower there).  This module compiles the same kernels ahead of time into an
extension module, ``engine._aot_kernels``, with numba's own AOT compiler (``numba.pycc``) at install time
(``make venv``, or ``python -m engine.aot``).  Importing it takes about a millisecond and needs neither numba
nor llvmlite, so every run, the frozen build included, gets the compiled kernels from its first call.

The same numba code, compiled by the same LLVM without fast-math, gives the same bits as the
just-in-time kernels (``tests/test_timeparam_aot.py`` compares the three ways on the tests' problems and
the examples' programs; ``tests/test_mandrel_chebval.py`` the dome's sums).  What an AOT module does not
do is check its arguments (a wrong dtype, rank or memory layout is read as raw memory), so :func:`load`
wraps every kernel in a check of each argument against the kernel's signature (:data:`KERNELS`); a call
that does not match goes to numba's just-in-time kernel instead (a bug to fix, counted in :data:`MISSES`).

The module records a stamp of each kernel source file (:data:`SOURCES`, :func:`source_stamp`); the kernels
of a file that changed since the build are not used (numba's kernels or the numpy code run until it is
rebuilt: the same answers, slower).  ``WINDER_AOT=0`` switches the module off, ``WINDER_NUMBA=0`` every
compiled kernel.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

MODULE = "engine._aot_kernels"
"""The extension module the build writes into the ``engine`` package."""

SOURCES = ("timeparam_jit", "mandrel_jit", "payout_jit", "winding_jit", "nearest_jit", "numtext_jit")
"""The modules of ``engine`` that hold the kernels' numba code (each stamped on its own)."""

# every kernel: (module of SOURCES, its builder there, index in what the builder returns or None, argument
# types).  "f8:2" is a C-contiguous float64 array of 2 dimensions ("u1:1": uint8); "f8", "i8", "b1" scalars.
KERNELS: dict[str, tuple[str, str, int | None, tuple[str, ...]]] = {
    "forward": ("timeparam_jit", "_build_kernel", None,
                ("f8:1", "i8:2", "i8:2", "b1:2", "f8:1", "f8:1", "b1", "i8", "i8", "i8", "i8:1")),
    "windows": ("timeparam_jit", "_build_windows", None,
                ("f8:2", "f8:2", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "i8", "f8:1", "f8:1", "b1:1", "f8:1",
                 "f8:1", "i8:1", "i8:1", "i8", "i8:2", "i8:2", "b1:2")),
    "dp_pass": ("timeparam_jit", "_build_fused", None,
                ("f8:1", "f8:1", "f8:1", "f8:1", "f8:2", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1",
                 "i8", "f8:1", "f8:1", "b1:1", "f8:1", "f8:1", "i8:1", "i8:1", "i8", "f8:1", "f8:1", "b1", "i8",
                 "b1", "i8", "i8", "i8:1", "i8:1", "f8:1")),
    "chains": ("timeparam_jit", "_build_chains", None,
               ("f8:3", "i8:2", "i8:1", "i8", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1",
                "f8:1", "f8:1", "f8:1", "f8:1", "f8:1")),
    "limits": ("timeparam_jit", "_build_limits", None,
               ("f8:3", "f8:3", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1", "f8:1")),
    "rows": ("timeparam_jit", "_build_rows", None, ("f8:3", "f8:3", "f8:1", "f8", "f8:3", "f8:3")),
    "groups": ("timeparam_jit", "_build_groups", None,
               ("f8:3", "i8:2", "b1:2", "b1:2", "i8:2", "f8:2", "b1:2", "f8:3", "f8:3")),
    "sweep_back": ("timeparam_jit", "_build_sweep", 0,
                   ("f8:1", "f8:1", "f8:1", "f8:1", "i8", "f8:1", "f8:1", "f8:1", "f8:1", "f8", "f8:1", "f8:1")),
    "sweep_fwd": ("timeparam_jit", "_build_sweep", 1, ("f8:3", "f8:1", "f8:1", "f8:1", "f8", "f8", "f8", "f8:1")),
    "hull_graham": ("timeparam_jit", "_build_hull_sym", 0,
                    ("f8:2", "f8:2", "f8:2", "f8:2", "i8:2", "f8:1", "f8:1", "i8:2", "i8:1")),
    "hull_prep": ("timeparam_jit", "_build_hull_sym", 1, ("f8:3", "i8:1", "i8:1", "f8:2", "f8:2", "i8:2", "f8:2")),
    "hull_assemble": ("timeparam_jit", "_build_hull_sym", 2, ("i8:2", "i8:1", "i8:1", "i8:2", "i8:1")),
    "hulls": ("timeparam_jit", "_build_hull", None, ("f8:3", "i8:2", "i8:1", "i8:1", "i8:1")),
    "chebval": ("mandrel_jit", "_build_chebval", None, ("f8:1", "f8:1", "f8:1", "f8:1", "f8:1")),
    "tube_pre": ("payout_jit", "_build_tube", 0, ("f8:2", "f8:1", "i8:1", "b1", "b1", "f8:1", "f8:1", "f8:1")),
    "tube_post": ("payout_jit", "_build_tube", 1, ("f8:2", "f8:1", "f8:1", "i8:1", "b1", "b1", "f8:1")),
    "tube_step": ("payout_jit", "_build_tube", 2, ("f8:1",) * 7 + ("f8", "f8") + ("f8:1",) * 5),
    "tube_newton": ("payout_jit", "_build_tube", 3, ("f8:1",) * 9 + ("f8", "f8", "f8:1", "f8:1")),
    "tube_edge_mid": ("payout_jit", "_build_edge", 0, ("f8:1",) * 4 + ("i8", "f8", "f8:1")),
    "tube_edge_upd": ("payout_jit", "_build_edge", 1, ("f8:1",) * 8),
    "clairaut_rk4": ("winding_jit", "_build_rk4", None, ("f8:1",) * 7 + ("i8", "i8", "f8", "f8", "b1", "f8:1", "f8:1",
                                                                    "b1", "b1", "f8:1", "f8:1")),
    "ipm_res": ("payout_jit", "_build_ipm", 0, ("i8:1", "i8:1", "f8:1", "b1") + ("i8:1", "i8:1", "f8:1") * 2
                + ("f8:1",) * 11),
    "ipm_fac": ("payout_jit", "_build_ipm", 1, ("f8:1", "f8:1", "i8:1", "i8:1", "i8:1", "b1:1") + ("f8:1",) * 6),
    "ipm_rhs": ("payout_jit", "_build_ipm", 2, ("i8:1", "i8:1") + ("f8:1",) * 7 + ("b1", "f8") + ("f8:1",) * 3),
    "ipm_aff": ("payout_jit", "_build_ipm", 3, ("f8:1", "f8:1", "f8", "f8", "f8", "i8:1", "i8:1") + ("f8:1",) * 10),
    "ipm_fin": ("payout_jit", "_build_ipm", 4, ("f8:1", "f8:1", "f8", "f8", "f8", "i8:1", "i8:1") + ("f8:1",) * 9),
    "nearest_vertex": ("nearest_jit", "_build_nearest", None,
                       ("f8:1", "f8:1", "i8:1") + ("f8:1",) * 4 + ("i8", "f8:1", "f8:1", "f8", "f8:1", "i8:1", "b1:1")),
    "nc_rows": ("numtext_jit", "_build_rows", None,
                ("i8", "i8:1", "i8:1", "i8:1", "i8:2", "i8:1", "i8:1", "b1:1", "b1:2", "u1:1")),
}

MISSES: dict[str, int] = {}
"""Calls, by kernel, whose arguments did not match the compiled signature (they ran numba's kernel)."""

_DTYPES = {"f8": np.dtype(np.float64), "i8": np.dtype(np.int64), "b1": np.dtype(np.bool_), "u1": np.dtype(np.uint8)}
_NUMBA_TYPES = {"f8": "float64", "i8": "int64", "b1": "boolean", "u1": "uint8"}


def source_stamp(source: str) -> int | None:
    """A 62-bit hash of the kernel source file ``engine/<source>.py``, or None where it cannot be read (a
    frozen build: there the module was built from the very source that was frozen)."""
    try:
        data = Path(__file__).with_name(f"{source}.py").read_bytes()
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
                raise TypeError(f"compiled kernel {self.name}: arguments {[type(a).__name__ for a in args]} do not "
                                f"match its signature and numba is not available")
        return self._alt(*args)


_LOADED: list[dict[str, _Guarded]] = []


def jit_kernel(name: str) -> Any:
    """numba's just-in-time kernel ``name`` (for a call its ahead-of-time kernel's signature does not take),
    or None without numba."""
    import importlib

    source, builder, index, _spec = KERNELS[name]
    try:
        import numba  # noqa: F401

        from engine.timeparam_jit import _light_blas

        _light_blas()
        got = getattr(importlib.import_module(f"engine.{source}"), builder)()
    except Exception:  # noqa: BLE001 - no numba
        return None
    return got if index is None else got[index]


def load() -> dict[str, _Guarded]:
    """The ahead-of-time kernels by name, each behind its argument check (a call that does not match runs
    :func:`jit_kernel`'s): those of the source files unchanged since the build; none where the module is not
    built or switched off (``WINDER_AOT=0``, ``WINDER_NUMBA=0``).  Loaded once per process."""
    if _LOADED:
        return _LOADED[0]
    out: dict[str, _Guarded] = {}
    if os.environ.get("WINDER_AOT", "1") != "0" and os.environ.get("WINDER_NUMBA", "1") != "0":
        try:
            import importlib

            mod = importlib.import_module(MODULE)
        except Exception:  # noqa: BLE001 - absent, or built for another numpy: the other kernels run
            mod = None
        if mod is not None:
            fresh = set()
            for source in SOURCES:
                stamp = source_stamp(source)
                fn = getattr(mod, f"stamp_{source}", None)
                if fn is not None and (stamp is None or int(fn()) == stamp):
                    fresh.add(source)
            out = {name: _Guarded(name, getattr(mod, name), spec, lambda n=name: jit_kernel(n))
                   for name, (source, _b, _i, spec) in KERNELS.items() if source in fresh and hasattr(mod, name)}
    _LOADED.append(out)
    return out


def raw_kernels(names: tuple[str, ...], cache: list[Any]) -> tuple[Any, ...] | None:
    """The ahead-of-time kernels ``names`` without their argument checks (for callers that pass arrays they
    made), or None where one of them does not run (not built, stale, switched off); remembered in
    ``cache``, the calling module's list (a test sets it to ``[None]`` to switch the kernels off)."""
    if not cache:
        got = load()
        cache.append(tuple(got[n].fn for n in names) if all(n in got for n in names) else None)
    return cache[0]


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
    import importlib
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc's pending-deprecation notice
        from numba import types
        from numba.pycc import CC

        cc = CC(MODULE.rpartition(".")[2], source_module=sys.modules[__name__])
        cc.output_dir = str(out_dir if out_dir is not None else Path(__file__).parent)
        cc.verbose = not quiet
        built: dict[tuple[str, str], Any] = {}
        for name, (source, builder, index, spec) in KERNELS.items():
            if (source, builder) not in built:
                built[source, builder] = getattr(importlib.import_module(f"engine.{source}"), builder)()
            got = built[source, builder]
            disp = got if index is None else got[index]
            args = _signature(spec)
            disp.compile(tuple(args))
            ret = types.unliteral(disp.overloads[tuple(args)].signature.return_type)
            # the export calls numba's kernel, so that the kernel keeps its own options (error_model="numpy":
            # x/0 = inf, as in numpy); numba compiles it into the module
            names = ", ".join(f"a{i}" for i in range(len(spec)))
            ns: dict[str, Any] = {"_kernel": disp}
            exec(f"def export({names}):\n    return _kernel({names})\n", ns)  # noqa: S102 - generated wrapper
            cc.export(name, ret(*args))(ns["export"])
        for source in SOURCES:
            stamp = source_stamp(source)
            if stamp is None:
                raise RuntimeError(f"engine/{source}.py cannot be read: nothing to stamp the module with")
            ns = {}
            exec(f"def stamp():\n    return {stamp}\n", ns)  # noqa: S102 - the source's stamp as a constant
            cc.export(f"stamp_{source}", types.int64())(ns["stamp"])
        cc.compile()
    path = Path(cc.output_dir) / cc._output_file
    _check_loads(path)
    return path


def _check_loads(path: Path) -> None:
    """Load the built module in a fresh process; remove it and raise RuntimeError if it does not load (a kernel
    numba could compile but not export: e.g. a recursive one leaves an unresolved symbol, and the whole module
    would silently be unused)."""
    import subprocess

    name = MODULE.rpartition(".")[2]
    code = ("import importlib.machinery as m, importlib.util as u, sys\n"
            f"loader = m.ExtensionFileLoader({name!r}, sys.argv[1])\n"
            f"mod = u.module_from_spec(u.spec_from_loader({name!r}, loader))\n"
            "loader.exec_module(mod)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        path.unlink(missing_ok=True)
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"the built module does not load ({last}); removed")


def main(argv: list[str] | None = None) -> int:
    """``python -m engine.aot [--quiet]``: build the extension module (exit 1 where it cannot)."""
    args = sys.argv[1:] if argv is None else argv
    quiet = "--quiet" in args
    try:
        path = build(quiet=quiet)
    except Exception as exc:  # noqa: BLE001 - no numba.pycc, no compiler: the run falls back, it says why
        print(f"engine.aot: not built ({type(exc).__name__}: {exc}); numba's just-in-time kernels or the numpy "
              f"code run instead (the same answers)", file=sys.stderr)
        return 1
    print(f"engine.aot: built {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
