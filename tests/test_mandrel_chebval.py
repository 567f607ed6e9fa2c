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
