"""The compiled nearest-vertex search (engine.nearest_jit) gives scipy's cKDTree answers bit for bit: the
distances and the indices, with and without an upper bound, on the examples' clearance boundaries and on
random curves, for points near, far, on vertices, exactly midway between two (ties), on the bound; NaN
and infinite coordinates are refused as by the tree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine import nearest_jit
from engine.job import build_mandrel, load_job
from engine.machine_setup import mandrel_distance_fn
from engine.payout import _Contour

ROOT = Path(__file__).resolve().parents[1]


def _require() -> None:
    if nearest_jit.kernel() is None:
        pytest.fail("engine._aot_kernels is not built from this source: run `make venv` (python -m engine.aot)")


def _queries(z: np.ndarray, r: np.ndarray, rng: np.random.Generator, m: int) -> np.ndarray:
    """Query points around the vertices (z, r): uniform in a box grown by the curve's size, close to
    vertices, on vertices, exactly midway between neighbours and between far vertices."""
    span = max(float(np.ptp(z)), float(np.ptp(r)), 1.0)
    lo = np.array([z.min(), r.min()]) - 0.3 * span
    hi = np.array([z.max(), r.max()]) + 0.3 * span
    P = [rng.uniform(lo, hi, size=(m, 2))]
    V = np.column_stack([z, r])
    k = rng.integers(0, z.size, m // 4)
    P.append(V[k] + rng.normal(scale=0.01 * span, size=(k.size, 2)))
    P.append(V[rng.integers(0, z.size, 200)])
    i = rng.integers(0, z.size - 1, 400)
    P.append(0.5 * (V[i] + V[i + 1]))                       # midway between neighbours: ties
    a, b = rng.integers(0, z.size, 200), rng.integers(0, z.size, 200)
    P.append(0.5 * (V[a] + V[b]))
    return np.vstack(P)


def _same(nv: nearest_jit.NearestVertex, tree: cKDTree, P: np.ndarray, ub: float) -> int:
    d, j = nv.query(P, distance_upper_bound=ub)
    d0, j0 = tree.query(P, distance_upper_bound=ub)
    assert np.array_equal(d, d0), (ub, np.flatnonzero(d != d0)[:5])
    assert np.array_equal(j, j0), (ub, np.flatnonzero(j != j0)[:5])
    return int(np.isfinite(d).sum())


@pytest.mark.parametrize("name", ["pressure_vessel", "bottle", "pipe"])
def test_the_examples_boundaries_as_the_kd_tree(name: str) -> None:
    _require()
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    mandrel = build_mandrel(load_job(path), path)
    c = _Contour(mandrel)
    assert isinstance(c.tree, nearest_jit.NearestVertex) and c.tree._kernel is not None
    tree = cKDTree(np.column_stack([c.bz, c.br]))
    rng = np.random.default_rng(11)
    P = _queries(c.bz, c.br, rng, 60_000)
    for ub in (np.inf, 0.5, 3.0, 25.0, 400.0):
        _same(c.tree, tree, P, ub)


def test_random_curves_ties_and_the_bound_as_the_kd_tree() -> None:
    _require()
    rng = np.random.default_rng(3)
    for case in range(40):
        n = int(rng.integers(1, 900))
        kind = case % 4
        if kind == 0:        # a generatrix with end faces (the clearance boundary's shape)
            z = np.sort(rng.uniform(0, 500, n))
            r = 50 + 10 * np.sin(z / rng.uniform(5, 80))
            z = np.concatenate([np.zeros(7), z, np.full(7, z[-1])])
            r = np.concatenate([np.linspace(0, r[0], 7), r, np.linspace(r[-1], 0, 7)])
        elif kind == 1:      # integer grid points: many exact ties
            z = rng.integers(-20, 20, n).astype(float)
            r = rng.integers(0, 10, n).astype(float)
        elif kind == 2:      # repeated vertices and equal z
            z = np.repeat(rng.uniform(-5, 5, max(1, n // 3)), 3)[:n]
            r = rng.uniform(0, 3, z.size)
        else:                # scattered, any order
            z = rng.normal(scale=100, size=n)
            r = rng.normal(scale=1e-3, size=n) * 10 ** rng.uniform(-3, 5)
        nv = nearest_jit.NearestVertex(z, r)
        assert nv._kernel is not None
        tree = cKDTree(np.column_stack([z, r]))
        P = _queries(z, r, rng, 3000)
        if kind == 1:
            P = np.vstack([P, rng.integers(-25, 25, size=(3000, 2)) + 0.5 * rng.integers(0, 2, size=(3000, 2))])
        for ub in (np.inf, 1.0, 5.0, float(rng.uniform(0.01, 50))):
            _same(nv, tree, P, ub)
    # a vertex exactly on the bound is not found (the tree's strict bound): 3-4-5
    nv = nearest_jit.NearestVertex(np.array([0.0, 10.0]), np.array([0.0, 10.0]))
    for bad in ([np.nan, 1.0], [1.0, np.inf], [-np.inf, np.nan]):   # refused as by the tree
        with pytest.raises(ValueError, match="finite"):
            nv.query(np.array([[0.0, 0.0], bad]))
    d, j = nv.query(np.array([[3.0, 4.0]]), distance_upper_bound=5.0)
    assert np.isinf(d[0]) and j[0] == 2
    d, j = nv.query(np.array([[3.0, 4.0]]), distance_upper_bound=np.nextafter(5.0, 6.0))
    assert d[0] == 5.0 and j[0] == 0


def test_ties_go_to_the_tree_and_the_tree_serves_without_the_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """A point midway between two vertices is flagged and answered by the k-d tree (built then, not before);
    without the compiled kernel every query is the tree's."""
    _require()
    z = np.arange(10.0)
    r = np.zeros(10)
    nv = nearest_jit.NearestVertex(z, r)
    d, _ = nv.query(np.array([[2.0, 1.0]]))
    assert d[0] == 1.0 and nv._tree is None           # no tie: the tree is not built
    P = np.array([[2.5, 1.0], [7.5, 0.0]])
    d, j = nv.query(P)
    assert nv._tree is not None
    d0, j0 = cKDTree(np.column_stack([z, r])).query(P)
    assert np.array_equal(d, d0) and np.array_equal(j, j0)
    monkeypatch.setattr(nearest_jit, "_KERNEL", [None])
    plain = nearest_jit.NearestVertex(z, r)
    assert plain._kernel is None
    d, j = plain.query(P)
    assert np.array_equal(d, d0) and np.array_equal(j, j0)


@pytest.mark.parametrize("name", ["pressure_vessel", "bottle"])
def test_mandrel_distance_as_with_the_kd_tree(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """engine.machine_setup's distance from the body (the laminate's transitions): the same values with the
    compiled search as with the k-d tree, bounded and not."""
    _require()
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    mandrel = build_mandrel(load_job(path), path)
    rng = np.random.default_rng(2)
    m = 40_000
    z = rng.uniform(float(mandrel.z_min) - 80, float(mandrel.z_max) + 80, m)
    rho = rng.uniform(0.0, 2.0 * float(np.max(mandrel.r(np.linspace(mandrel.z_min, mandrel.z_max, 50)))), m)
    fast = mandrel_distance_fn(mandrel, 0.05, 30.0)
    got = [fast(z, rho), fast(z, rho, upto=2.0), fast(z, rho, upto=np.inf)]
    monkeypatch.setattr(nearest_jit, "_KERNEL", [None])
    ref = mandrel_distance_fn(mandrel, 0.05, 30.0)
    want = [ref(z, rho), ref(z, rho, upto=2.0), ref(z, rho, upto=np.inf)]
    for a, b in zip(got, want):
        assert np.array_equal(a, b)
    assert np.isfinite(got[0]).sum() > 1000 and np.isinf(got[1]).sum() > 1000
