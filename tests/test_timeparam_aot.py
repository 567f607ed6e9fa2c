"""The engine's kernels compiled ahead of time (engine.aot, issue 16): the time law's give the same laws bit
for bit as numba's just-in-time kernels and the numpy passes, without numba at run time, and no kernel is
ever fed arguments its compiled signature does not take."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine import aot as aot_mod

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"

pytestmark = pytest.mark.skipif(
    os.environ.get("WINDER_AOT", "1") == "0" or os.environ.get("WINDER_NUMBA", "1") == "0",
    reason="the ahead-of-time kernels are switched off in this environment")

# the laws of a few problems that use every kernel: the paper's path (windows, DP passes, chains, symmetric
# hulls, the final sweep), the same path on 3 000 nodes (node groups and their rows, monotone-chain hulls),
# a non-uniform spacing without the penalty term (the forward pass of the "dp" method)
LAWS = """
import hashlib, json, sys
from dataclasses import replace
import numpy as np
from engine import timeparam_jit as J
MODE = sys.argv[1]
if MODE == "jit":
    assert J.warm()
from engine.timeparam import parametrize
from engine.timeparam_example import example_limits, example_path
out = []
def add(law):
    out.append([hashlib.sha256(np.ascontiguousarray(law.sdot).tobytes()).hexdigest(), law.total_time_s,
                [it.total_time_s for it in law.iterations]])
add(parametrize(*example_path(), replace(example_limits(), levels=80)))
add(parametrize(*example_path(3000), example_limits()))
s, X, dX, ddX = example_path(n=300)
keep = np.sort(np.r_[0, np.random.default_rng(3).choice(np.arange(1, 299), 180, replace=False), 299])
add(parametrize(s[keep], X[keep], dX[keep], ddX[keep], replace(example_limits(), levels=60, penalty=0.0),
                method="dp"))
k = J.kernel(0)
from engine import aot as A
print(json.dumps({"laws": out, "kernel": type(k).__name__, "misses": A.MISSES,
                  "numba": "numba" in sys.modules and sys.modules["numba"] is not None}))
"""


def _laws(mode: str, **env: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", LAWS, mode], cwd=ROOT, capture_output=True, text=True,
                          timeout=900, env={**os.environ, **env})
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def aot() -> dict:
    got = aot_mod.load()
    assert set(got) == set(aot_mod.KERNELS), ("engine._aot_kernels is not built from this source: run "
                                              "`make venv` (python -m engine.aot)")
    return got


def test_the_module_is_this_sources_and_has_every_kernel(aot: dict) -> None:
    import importlib

    mod = importlib.import_module(aot_mod.MODULE)
    for source in aot_mod.SOURCES:
        assert int(getattr(mod, f"stamp_{source}")()) == aot_mod.source_stamp(source)
    assert set(aot) == set(aot_mod.KERNELS)


def test_aot_jit_and_numpy_give_the_same_laws_bit_for_bit(aot: dict) -> None:
    """Three processes: the ahead-of-time kernels (the default where numba is not loaded), numba's kernels
    (loaded by warm(), as the GUI does), the numpy passes (WINDER_NUMBA=0)."""
    a = _laws("aot")
    pytest.importorskip("numba")
    j = _laws("jit")
    n = _laws("numpy", WINDER_NUMBA="0")
    assert a["kernel"] == "_Guarded" and not a["numba"]         # compiled, and numba never imported
    assert a["misses"] == {}                                     # every call matched the compiled signatures
    assert j["kernel"] == "CPUDispatcher"
    assert n["kernel"] == "NoneType"
    assert a["laws"] == j["laws"] == n["laws"]


def test_without_numba_the_aot_kernels_run() -> None:
    """The frozen build has no numba: the ahead-of-time kernels run there, and give the same law."""
    code = ("import sys; sys.modules['numba'] = None\n"
            "from dataclasses import replace\n"
            "from engine import timeparam_jit\n"
            "from engine.timeparam import parametrize\n"
            "from engine.timeparam_example import example_limits, example_path\n"
            "law = parametrize(*example_path(), replace(example_limits(), levels=74))\n"
            "assert type(timeparam_jit.kernel(0)).__name__ == '_Guarded'\n"
            "assert 'llvmlite' not in sys.modules\n"
            "print(repr(law.total_time_s), law.sdot.tobytes().hex()[:64])\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    from dataclasses import replace

    import engine.timeparam as tp
    from engine.timeparam_example import example_limits, example_path

    old = tp._NUMBA
    tp._NUMBA = False
    try:
        ref = tp.parametrize(*example_path(), replace(example_limits(), levels=74))
    finally:
        tp._NUMBA = old
    assert proc.stdout.split() == [repr(ref.total_time_s), ref.sdot.tobytes().hex()[:64]]


@pytest.mark.parametrize("example", ["pipe", "bottle"])
def test_the_examples_programs_are_those_of_the_numpy_passes(tmp_path: Path, example: str) -> None:
    out = {}
    for mode, env in (("aot", {}), ("numpy", {"WINDER_NUMBA": "0"})):
        nc = tmp_path / f"{mode}.ngc"
        proc = subprocess.run([sys.executable, "-m", "engine", "run", str(EXAMPLES / f"{example}.toml"), "-o",
                               str(nc), "--quiet"], cwd=ROOT, capture_output=True, text=True, timeout=600,
                              env={**os.environ, **env})
        assert proc.returncode == 0, proc.stderr
        out[mode] = nc.read_bytes()
    assert out["aot"] == out["numpy"]


def test_arguments_the_signature_does_not_take_go_to_numba(aot: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """An AOT kernel reads its arguments as raw memory of the compiled types: a float32, 2-D or strided array
    there would be garbage or a crash.  The check sends such a call to numba's kernel (counted), and without
    numba refuses it with a clear error."""
    rng = np.random.default_rng(5)
    n = 40
    d1, d2 = rng.normal(size=(n, 3, 2)), rng.normal(size=(n, 3, 2))
    h, x0, u, tau = rng.uniform(0.1, 1, n), rng.uniform(0.1, 2, n), rng.normal(size=n), rng.uniform(0.1, 1, n)
    A, V = rng.uniform(1, 2, 3), rng.uniform(1, 2, 3)
    k = aot["limits"]
    good = k(d1, d2, h, x0, u, tau, A, V)
    monkeypatch.setattr(aot_mod, "MISSES", {})
    strided = np.repeat(h, 2)[::2]
    assert not strided.flags.c_contiguous
    pytest.importorskip("numba")
    assert k(d1, d2, strided, x0, u, tau, A, V) == good                    # numba's kernel, the same answer
    assert aot_mod.MISSES == {"limits": 1}
    monkeypatch.setattr(k, "_alt", None)
    monkeypatch.setattr(k, "fallback", lambda: None)
    with pytest.raises(TypeError, match="limits"):
        k(d1, d2, h.astype(np.float32), x0, u, tau, A, V)
    with pytest.raises(TypeError, match="limits"):
        k(d1, d2, h[None, :], x0, u, tau, A, V)
    with pytest.raises(TypeError, match="limits"):
        k(d1, d2, h, x0, u, tau, A)                                            # one argument short
    assert k(d1, d2, h, x0, u, tau, A, V) == good


def test_kernels_of_a_changed_source_or_switched_off_are_not_used(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each source file is stamped on its own: the kernels of a file changed since the build are left out
    (the others still run); WINDER_AOT=0 and WINDER_NUMBA=0 leave them all out."""
    real = aot_mod.source_stamp
    monkeypatch.setattr(aot_mod, "_LOADED", [])
    assert set(aot_mod.load()) == set(aot_mod.KERNELS)                      # (this source's: used)
    for changed in aot_mod.SOURCES:
        monkeypatch.setattr(aot_mod, "_LOADED", [])
        with monkeypatch.context() as m:
            m.setattr(aot_mod, "source_stamp", lambda src, c=changed: 12345 if src == c else real(src))
            got = aot_mod.load()
        assert got and set(got) == {n for n, k in aot_mod.KERNELS.items() if k[0] != changed}
    for var in ("WINDER_AOT", "WINDER_NUMBA"):
        monkeypatch.setattr(aot_mod, "_LOADED", [])
        with monkeypatch.context() as m:
            m.setenv(var, "0")
            assert aot_mod.load() == {}


def test_a_built_module_that_does_not_load_is_refused(tmp_path: Path) -> None:
    """The build loads what it built in a fresh process: a module that does not load (a kernel numba could
    compile but not export leaves an unresolved symbol) is removed and the build fails, rather than every
    run silently going without its kernels."""
    bad = tmp_path / "_aot_kernels.cpython-311-x86_64-linux-gnu.so"
    bad.write_bytes(b"\x7fELF not really a shared object")
    with pytest.raises(RuntimeError, match="does not load"):
        aot_mod._check_loads(bad)
    assert not bad.exists()
    good = next(Path(aot_mod.__file__).parent.glob("_aot_kernels*.so"))
    aot_mod._check_loads(good)   # the real one loads
    assert good.exists()
