"""engine.mandrel._chebval (the isotensoid's small-array Clenshaw sum) is numpy's chebval bit for bit."""

import numpy as np
from numpy.polynomial import chebyshev as C

from engine.mandrel import IsotensoidSegment, _chebval, _isotensoid_series


def test_chebval_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    for _ in range(2000):
        c = rng.normal(size=int(rng.integers(1, 90))) * 10 ** rng.uniform(-5, 5)
        x = rng.uniform(-1, 1, size=int(rng.integers(0, 30)))
        np.testing.assert_array_equal(_chebval(x, c), C.chebval(x, c))
    zc = _isotensoid_series(0.2)[0]
    for x in (np.array(0.3), np.array([-1.0, 1.0]), np.linspace(-1, 1, 20).reshape(4, 5)):
        a, b = _chebval(x, zc), C.chebval(x, zc)
        assert a.shape == b.shape
        np.testing.assert_array_equal(a, b)


def test_isotensoid_small_and_large_evaluations_agree() -> None:
    """A point evaluated alone (Python-float path) equals the same point inside a long array (numpy)."""
    seg = IsotensoidSegment(0.0, 100.0, R=100.0, zc=0.0, rho_p=0.3)
    z = np.linspace(seg.z0, seg.z1, 301)
    r, dr, d2r = seg.eval(z)
    for k in (0, 17, 150, 300):
        one = seg.eval(z[k:k + 1])
        assert (one[0][0], one[1][0], one[2][0]) == (r[k], dr[k], d2r[k])


def test_compiled_chebval_bit_for_bit_and_used() -> None:
    """The compiled sum (engine.mandrel_jit, ahead of time) is numpy's chebval bit for bit on every size and
    shape, extreme coefficients and points outside [-1, 1] included; _chebval takes it where it runs."""
    from engine import aot
    from engine.mandrel_jit import chebval

    if "chebval" not in aot.load():
        import pytest

        pytest.fail("engine._aot_kernels is not built from this source: run `make venv` (python -m engine.aot)")
    rng = np.random.default_rng(1)
    for _ in range(400):
        c = rng.normal(size=int(rng.integers(3, 120))) * 10 ** rng.uniform(-8, 8)
        n = int(rng.integers(1, 3000))
        x = rng.uniform(-1.5, 1.5, size=n)
        got = chebval(x, c)
        assert got is not None
        np.testing.assert_array_equal(got, C.chebval(x, c))
    x = np.linspace(-1, 1, 60).reshape(3, 4, 5)
    zc = _isotensoid_series(0.25)[0]
    got = chebval(x, zc)
    assert got.shape == x.shape
    np.testing.assert_array_equal(got, C.chebval(x, zc))
    np.testing.assert_array_equal(_chebval(x, zc), C.chebval(x, zc))
    assert chebval(x, zc[:2]) is None and chebval(np.zeros(0), zc) is None   # numpy's own: 2 terms, no points
