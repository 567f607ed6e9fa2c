"""The compiled steps of the time law's reference hull (engine.timeparam_jit.hull_sym_rows) give
timeparam._hull_sym's vertices bit for bit: small problems take that hull with and without numba."""

import numpy as np
import pytest

import engine.timeparam as tp

numba = pytest.importorskip("numba")


def _same(pts: np.ndarray, ipos: np.ndarray, ineg: np.ndarray) -> bool:
    a = tp._hull_sym(pts, ipos, ineg, compiled=False)
    b = tp._hull_sym(pts, ipos, ineg, compiled=True)
    return bool(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]))


@pytest.mark.parametrize("kind", ["random", "near_twins", "rays", "flat"])
def test_compiled_reference_hull_is_bit_for_bit(kind: str) -> None:
    from engine import timeparam_jit

    assert timeparam_jit.warm()
    rng = np.random.default_rng(["random", "near_twins", "rays", "flat"].index(kind))
    for _ in range(120):
        B, H = int(rng.integers(1, 30)), int(rng.integers(1, 30))
        half = rng.normal(size=(B, H, 2)) * 10 ** rng.uniform(-3, 3, size=(B, 1, 2))
        if kind == "near_twins" and H > 3:          # near and exact duplicates, a midpoint, a zero row
            half[:, 0] = half[:, 1] * (1 + 1e-13)
            half[:, 2] = half[:, 1]
            half[:, 3] = 0.5 * (half[:, 1] + half[:, 2]) + 1e-15
            half[:, -1] = 0.0
        elif kind == "rays":                        # many points on a few rays
            ang = rng.integers(0, 5, size=(B, H)) * 0.3
            rad = rng.uniform(0.5, 2.0, size=(B, H))
            half = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
        elif kind == "flat":                        # nearly collinear clouds
            t = rng.uniform(-1, 1, size=(B, H))
            half = np.stack([t, 2 * t + rng.normal(scale=1e-14, size=(B, H))], -1)
        pts = np.concatenate([half, -half], 1)
        assert _same(pts, np.arange(H), np.arange(H, 2 * H))


def test_compiled_reference_hull_takes_the_compiled_steps() -> None:
    from engine import timeparam_jit

    assert timeparam_jit.warm()
    pts = np.array([[[1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [-1.0, 0.0], [0.0, -1.0], [-0.5, -0.5]]])
    px, py = pts[:, :3, 0].copy(), pts[:, :3, 1].copy()
    ang, r2 = np.arctan2(py, px), px * px + py * py
    out = timeparam_jit.hull_sym_rows(px, py, ang, r2, np.array([[0, 1, 2]]), np.array([1.0, 0.7, 0.0, -0.7]),
                                      np.array([0.0, 0.7, 1.0, 0.7]))
    assert out is not None
    up, k = out
    assert k.tolist() == [2] and up[0, :2].tolist() == [0, 1]     # the midpoint (0.5, 0.5) is not a vertex
