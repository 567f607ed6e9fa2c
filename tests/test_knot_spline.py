"""engine.knot_spline against scipy.interpolate.CubicSpline: the same values and derivatives, bit for bit."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline as SciPySpline

from engine.knot_spline import CubicSpline, knot_derivatives

BCS = ["not-a-knot", ((1, 0.3), "not-a-knot"), ("not-a-knot", (1, -2.0)), ((1, 0.0), (1, 0.0)),
       ((1, 0.5), (2, 0.0)), ((2, 0.0), (1, -0.5)), ((2, 1.0), (2, -1.0))]


@pytest.mark.parametrize("seed", range(12))
def test_knot_derivatives_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(40):
        n = int(rng.integers(2, 400))
        x = np.cumsum(rng.uniform(0.01, 3.0, n)) * 10 ** rng.uniform(-3, 3)
        y = rng.normal(size=(n, 7)) * 10 ** rng.uniform(-3, 3, size=7)
        y[:, 0] = 0.0                                   # an axis at rest
        y[:, 1] = 2.5 * x - 1.0                         # a linear axis
        cs = SciPySpline(x, y, axis=0)
        D1, D2 = knot_derivatives(x, y)
        np.testing.assert_array_equal(D1, cs(x, 1))
        np.testing.assert_array_equal(D2, cs(x, 2))


@pytest.mark.parametrize("bc", BCS)
@pytest.mark.parametrize("seed", range(4))
def test_values_everywhere_bit_for_bit(bc: object, seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    for _ in range(25):
        n = int(rng.integers(2, 200))
        x = np.sort(rng.uniform(-500.0, 500.0, n))
        x = x[np.concatenate([[True], np.diff(x) > 1e-6])]
        if x.size < 2:
            continue
        y = 60.0 + 10.0 * np.sin(x / 50.0) + rng.normal(scale=0.1, size=x.size)
        ref = SciPySpline(x, y, bc_type=bc)
        ours = CubicSpline(x, y, bc_type=bc)
        q = np.concatenate([x, rng.uniform(x[0] - 50.0, x[-1] + 50.0, 300), [np.nan]])
        for nu in (0, 1, 2):
            np.testing.assert_array_equal(ours(q, nu), ref(q, nu))
            np.testing.assert_array_equal(ours(float(q[3]), nu), ref(float(q[3]), nu))


def test_exact_cubic_and_shapes() -> None:
    x = np.array([0.0, 0.7, 1.1, 2.0, 3.5, 4.0])
    y = 2 * x**3 - x**2 + 3 * x - 5                  # not-a-knot reproduces a cubic exactly
    D1, D2 = knot_derivatives(x, y)
    np.testing.assert_allclose(D1, 6 * x**2 - 2 * x + 3, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(D2, 12 * x - 2, rtol=1e-12, atol=1e-12)
    assert D1.shape == y.shape
    cs = CubicSpline(x, y)
    assert np.shape(cs(1.5)) == ()
    np.testing.assert_allclose(cs(1.5), 2 * 1.5**3 - 1.5**2 + 4.5 - 5, rtol=1e-12)


def test_tridiagonal_solve_is_solve_banded_bit_for_bit() -> None:
    """knot_spline._solve_tridiagonal (LAPACK's dgtsv without importing scipy.linalg) against
    scipy.linalg.solve_banded((1, 1), ...) on random diagonally dominant and general systems."""
    from scipy.linalg import solve_banded

    from engine.knot_spline import _solve_tridiagonal

    rng = np.random.default_rng(11)
    for k in range(60):
        n, m = int(rng.integers(2, 40)), int(rng.integers(1, 4))
        A = rng.normal(size=(3, n))
        if k % 2:
            A[1] += 4.0 * np.sign(A[1])
        b = rng.normal(size=(n, m))
        want = solve_banded((1, 1), A.copy(), b.copy(), overwrite_ab=True, overwrite_b=True, check_finite=False)
        got = _solve_tridiagonal(A.copy(), b.copy())
        assert np.array_equal(got, want), k
