"""mandrel_distance_fn answers points far from the mandrel without the k-d tree: the same values, bit for bit."""

import numpy as np
import pytest

from engine.job import build_mandrel, load_job
from engine.machine_setup import mandrel_distance_fn
from engine.mandrel import Mandrel

EX = "resources/examples/"


def _mandrels() -> list[Mandrel]:
    return [build_mandrel(load_job(EX + f), EX + f) for f in ("pressure_vessel.toml", "bottle.toml", "pipe.toml")]


@pytest.mark.parametrize("k", range(3))
def test_same_as_tree_everywhere(k: int) -> None:
    m = _mandrels()[k]
    rng = np.random.default_rng(k)
    n = 20000
    z = rng.uniform(m.z_min - 80.0, m.z_max + 80.0, n)
    rho = rng.uniform(0.0, float(m.r_max) + 80.0, n)
    for upto in (0.5, 3.0, 11.0, 40.0, np.inf):
        fn = mandrel_distance_fn(m, upto_mm=upto)
        got = fn(z, rho)
        ref = fn(z[:64], rho[:64])           # small calls skip the filter: the tree's own answers
        np.testing.assert_array_equal(got[:64], ref)
        # every point one by one in chunks below the filter's size
        want = np.concatenate([fn(z[i:i + 64], rho[i:i + 64]) for i in range(0, n, 64)])
        np.testing.assert_array_equal(got, want)
        if np.isfinite(upto):
            assert np.isinf(got).any() and np.isfinite(got).any()
