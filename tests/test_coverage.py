"""Coverage map (engine.coverage) against the closed form of the pattern (band b / cos β along a
parallel against the pitch 2πr/p, engine.winding's ``coverage``) on the pipe."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.coverage import coverage_map, meridian_length
from engine.job import load_job
from engine.pipeline import run_pipeline

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def pipe():
    path = ROOT / "resources/examples/pipe.toml"
    return run_pipeline(load_job(path), path, upto="winding")


def test_overlap_on_the_cylinder_matches_the_closed_form(pipe) -> None:
    line = pipe.line
    cov = coverage_map(line, pipe.mandrel, nz=100, nv=2000)
    closed = line.coverage
    mid = slice(30, 70)  # away from the turnarounds
    expect = closed["overlap_mm"] / closed["pitch_mm"]  # share of a parallel two bands of one direction share
    assert np.mean(cov.forward[mid] > 1) == pytest.approx(expect, abs=0.006)
    assert np.mean(cov.backward[mid] > 1) == pytest.approx(expect, abs=0.006)
    assert np.all(cov.forward[mid] >= 1) and np.all(cov.backward[mid] >= 1)  # no gaps: fraction > 1
    assert cov.covered_fraction == 1.0


def test_a_narrower_band_leaves_gaps_of_the_closed_form_share(pipe) -> None:
    line = pipe.line
    closed = line.coverage
    b = 0.5 * line.band_width_mm
    cov = coverage_map(line, pipe.mandrel, nz=100, nv=2000, band_width_mm=b)
    mid = slice(30, 70)
    per_dir = 0.5 * closed["band_along_parallel_mm"] / closed["pitch_mm"]  # (b/2)/cos β over the pitch
    assert np.mean(cov.forward[mid] > 0) == pytest.approx(per_dir, abs=0.006)
    assert np.mean(cov.backward[mid] > 0) == pytest.approx(per_dir, abs=0.006)
    assert np.mean(cov.count[mid] == 0) > 0.05 and cov.gap_fraction > 0.0


def test_meridian_length_of_a_cone_and_a_cylinder() -> None:
    class Cone:
        z_min, z_max = 0.0, 100.0

        @staticmethod
        def r(z):
            return 50.0 + 0.75 * np.asarray(z)

    z = np.array([0.0, 40.0, 100.0])
    np.testing.assert_allclose(meridian_length(Cone, z), z * np.hypot(1.0, 0.75), rtol=1e-9)
