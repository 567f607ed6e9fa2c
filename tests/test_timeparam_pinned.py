"""The DP + tube answers on the paper-sized example, pinned before the speed work of issue 6.

Recorded with engine/timeparam.py at commit 95be922 (before the optimisation): every later change to
the DP, the hull/chains or the tube must reproduce them -- total time to 1e-9 relative, the same
iteration count and the same W/O touch counts in every iteration.  The final sweep (issue 16,
``TimeLimits.sweep``) comes after the tube: pinned with it off, and checked to be at least as good with it on.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from engine.timeparam import parametrize
from engine.timeparam_example import example_limits, example_path

# M -> (total time of every iteration (s), (W, O) touches of every iteration)
PINNED = {
    74: ([7.141349496222921, 6.732151695733205, 6.534406822304678, 6.4412433026275036, 6.402321834990476,
          6.380812807627346],
         [(0, 0), (22, 2), (6, 2), (1, 2), (0, 2), (0, 2)]),
    80: ([7.041519311447896, 6.6631475194188745, 6.5025312625334415, 6.425098343971128, 6.389602268060745,
          6.374761622992732, 6.365964086797974],
         [(0, 0), (20, 2), (5, 2), (0, 2), (2, 2), (0, 2), (0, 2)]),
    90: ([6.920876524629107, 6.58307702704502, 6.456748749217984, 6.40312363061391, 6.378170104169611],
         [(0, 0), (17, 2), (2, 2), (0, 2), (0, 2)]),
    100: ([6.834929337060371, 6.525820663640517, 6.425058503277312, 6.388804606870523, 6.3716923116465205],
          [(0, 0), (11, 2), (1, 2), (0, 2), (0, 2)]),
}


@pytest.fixture(scope="module")
def example():
    return (*example_path(), example_limits())


@pytest.mark.parametrize("M", sorted(PINNED))
def test_tube_answer_is_pinned(example, M: int) -> None:
    s, X, dX, ddX, lim = example
    law = parametrize(s, X, dX, ddX, replace(lim, levels=M, coarse=False, sweep=False), method="tube")
    times, touches = PINNED[M]
    assert len(law.iterations) == len(times)
    assert law.total_time_s == pytest.approx(times[-1], rel=1e-9, abs=0)
    for it, t, (w, o) in zip(law.iterations, times, touches):
        assert it.total_time_s == pytest.approx(t, rel=1e-9, abs=0)
        assert (it.w_touches, it.o_touches) == (w, o)
    assert law.iterations[-1].stop and law.max_accel_ratio <= 1.0 + 1e-9
    assert law.sweep_gain_s == 0.0


@pytest.mark.parametrize("M", sorted(PINNED))
def test_final_sweep_keeps_the_pinned_tube_and_is_at_least_as_good(example, M: int) -> None:
    """With the final sweep (the default) the tube's iterations are the pinned ones, bit for bit; the law is
    at least as fast as the pinned tube's and keeps every limit inside the intervals."""
    s, X, dX, ddX, lim = example
    law = parametrize(s, X, dX, ddX, replace(lim, levels=M, coarse=False), method="tube")
    times, touches = PINNED[M]
    assert [it.total_time_s for it in law.iterations] == pytest.approx(times, rel=1e-9, abs=0)
    assert [(it.w_touches, it.o_touches) for it in law.iterations] == touches
    assert law.total_time_s <= times[-1]
    assert law.total_time_s == pytest.approx(times[-1] - law.sweep_gain_s, rel=1e-12)
    assert law.sweep_gain_s > 0.001 * times[-1]          # the tube's law is 0.2-0.8 % above the optimum here
    assert max(law.max_accel_ratio, law.max_speed_ratio, law.max_sddot_ratio) <= 1.0
