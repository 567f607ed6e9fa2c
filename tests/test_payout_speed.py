"""Issue 16: the payout's refinement rounds reuse work without changing a number."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine import payout
from engine.job import build_mandrel, load_job
from engine.payout import ContactLine
from engine.winding import winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["pressure_vessel", "pipe"])
def test_envelope_cache_equals_the_whole_envelope(name: str) -> None:
    """A refined grid's envelope, taken from the earlier grid plus the new points, is bit for bit the
    envelope computed on the whole refined grid (each point's envelope depends on that point alone)."""
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": 600}))
    spec = job.payout
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    contour = payout._Contour(build_mandrel(job, path))
    cache = payout._EnvCache()
    geo1 = payout._grid(line, spec.parameter, 200)
    env1 = cache.envelope(geo1, contour, spec.clearance_mm, spec.free_length_max_mm, None, None)
    full1 = payout.envelope(geo1, contour, spec.clearance_mm, spec.free_length_max_mm)
    assert np.array_equal(env1.l_min, full1.l_min) and np.array_equal(env1.l_max, full1.l_max)
    # two refinement rounds: line points not on the first grid join it (as _refined adds them)
    rng = np.random.default_rng(7)
    extra = np.unique(rng.choice(line.z.size, 60, replace=False))
    for more in (extra[:30], extra):
        geo = payout._grid(line, spec.parameter, 200, more)
        assert geo.n > geo1.n
        env = cache.envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm, None, None)
        full = payout.envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm)
        assert np.array_equal(env.l_min, full.l_min)
        assert np.array_equal(env.l_max, full.l_max)
        assert env.workspace == full.workspace


def test_refined_min_range_law_unchanged_by_the_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole refined min-range law with and without the envelope cache: the same law bit for bit."""
    path = ROOT / "resources" / "examples" / "pipe.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": 600}),
                      payout=job.payout.model_copy(update={"grid_points": 300}))
    mandrel = build_mandrel(job, path)
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    a = payout.min_range_law(line, mandrel, job.payout)
    assert a.report["line"]["refinements"] >= 1  # the cache was used

    def uncached(self, geo, contour, clearance, l_cap, workspace, state):  # noqa: ANN001, ANN202
        return payout.envelope(geo, contour, clearance, l_cap, workspace, state)

    monkeypatch.setattr(payout._EnvCache, "envelope", uncached)
    b = payout.min_range_law(line, mandrel, job.payout)
    assert np.array_equal(a.l, b.l) and np.array_equal(a.x, b.x)
    assert a.report["line"]["u_range"] == b.report["line"]["u_range"]
