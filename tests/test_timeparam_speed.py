"""The compiled DP pass (engine.timeparam_jit, numba) against the numpy reference pass (issue 16).

Both passes must give the same J bits and argmins, hence the same laws bit for bit: on the paper's
example (uniform node spacing, every tube iteration) and on a non-uniform path without the penalty
term.  Without numba (the frozen build leaves it out) the numpy pass runs and gives the same answer.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import engine.timeparam as tp
from engine.timeparam_example import example_limits, example_path

ROOT = Path(__file__).resolve().parents[1]
numba = pytest.importorskip("numba")


def _law(flag: bool, *args, **kw):
    old = tp._NUMBA
    tp._NUMBA = flag
    try:
        return tp.parametrize(*args, **kw)
    finally:
        tp._NUMBA = old


def test_compiled_pass_is_used_and_bit_identical_on_the_example() -> None:
    from engine import timeparam_jit

    s, X, dX, ddX = example_path()
    lim = replace(example_limits(), levels=80)
    ref = _law(False, s, X, dX, ddX, lim)
    new = _law(True, s, X, dX, ddX, lim)
    assert timeparam_jit.kernel(0) is not None          # numba is loaded: the kernel ran
    assert np.array_equal(ref.sdot, new.sdot) and ref.total_time_s == new.total_time_s
    assert [it.total_time_s for it in ref.iterations] == [it.total_time_s for it in new.iterations]
    assert [(it.w_touches, it.o_touches) for it in ref.iterations] == \
        [(it.w_touches, it.o_touches) for it in new.iterations]


def test_compiled_pass_bit_identical_non_uniform_spacing_no_penalty() -> None:
    s, X, dX, ddX = example_path(n=300)
    rng = np.random.default_rng(3)
    keep = np.sort(np.r_[0, rng.choice(np.arange(1, 299), 180, replace=False), 299])
    s, X, dX, ddX = s[keep], X[keep], dX[keep], ddX[keep]
    lim = replace(example_limits(), levels=60, penalty=0.0)
    for method in ("tube", "dp"):
        ref = _law(False, s, X, dX, ddX, lim, method=method)
        new = _law(True, s, X, dX, ddX, lim, method=method)
        assert np.array_equal(ref.sdot, new.sdot), method


def test_without_numba_the_numpy_pass_gives_the_same_law() -> None:
    code = (
        "import sys; sys.modules['numba'] = None\n"         # import numba fails, as in the frozen build
        "from dataclasses import replace\n"
        "from engine import timeparam_jit\n"
        "from engine.timeparam import parametrize\n"
        "from engine.timeparam_example import example_limits, example_path\n"
        "law = parametrize(*example_path(), replace(example_limits(), levels=74))\n"
        "assert timeparam_jit.kernel(10**12) is None\n"
        "print(repr(law.total_time_s))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    s, X, dX, ddX = example_path()
    law = _law(True, s, X, dX, ddX, replace(example_limits(), levels=74))
    assert float(out.stdout.strip()) == law.total_time_s
