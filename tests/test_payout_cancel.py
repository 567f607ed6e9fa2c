"""Cancellation of the payout stage: every phase (envelope, (13), (14), (15); fast and HiGHS paths) polls
``state.cancelled()``, and a cancel at any poll stops the run at that very poll with :class:`Cancelled`."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from engine.errors import Cancelled
from engine.job import PayoutSpec
from engine.mandrel import Mandrel
from engine.payout import ContactLine, min_range_law, reference_vessel_circuit
from engine.state import RecordingState


@dataclass
class PhaseState(RecordingState):
    """A RecordingState that also notes the last progress fraction seen at every poll."""

    poll_fractions: list[float] = field(default_factory=list)

    def cancelled(self) -> bool:
        self.poll_fractions.append(self.progress_calls[-1][0] if self.progress_calls else 0.0)
        return super().cancelled()


@pytest.fixture(scope="module")
def vessel() -> Mandrel:
    return Mandrel.vessel(100.0, 300.0, "hemisphere", pole_radii=30.0)


@pytest.fixture(scope="module")
def circuit() -> ContactLine:
    return reference_vessel_circuit(100.0, 300.0, 40.0, 2400)


CASES = [("fast", 600), ("highs", 60)]  # 600 points: the envelope scan runs in several chunks


@pytest.mark.parametrize(("solver", "points"), CASES)
def test_every_phase_polls(circuit: ContactLine, vessel: Mandrel, solver: str, points: int) -> None:
    st = PhaseState()
    eye = min_range_law(circuit, vessel, PayoutSpec(grid_points=points, impregnation_k=1), state=st, solver=solver)
    assert eye.report["feasible"] and not eye.report["solver"].get("fallback")
    f = st.poll_fractions
    # phases are delimited by the progress reports: envelope < 0.2 <= (13) < 0.45 <= (14) < 0.7 <= (15) < 0.95
    for lo, hi, name in ((0.0, 0.2, "envelope"), (0.2, 0.45, "(13)"), (0.45, 0.7, "(14)"), (0.7, 0.95, "(15)")):
        n = sum(lo <= x < hi for x in f)
        assert n >= 2, f"{solver}: phase {name} polls {n} times"


@pytest.mark.parametrize(("solver", "points"), CASES)
def test_cancel_after_k_polls(circuit: ContactLine, vessel: Mandrel, solver: str, points: int) -> None:
    spec = PayoutSpec(grid_points=points, impregnation_k=1)
    full = PhaseState()
    min_range_law(circuit, vessel, spec, state=full, solver=solver)
    total = full.polls
    assert total > 10
    # one k in every phase (its first polls, its middle), plus the very first and the very last poll
    picks = {0, total - 1}
    for lo, hi in ((0.0, 0.2), (0.2, 0.45), (0.45, 0.7), (0.7, 0.95)):
        idx = [i for i, x in enumerate(full.poll_fractions) if lo <= x < hi]
        picks |= {idx[0], idx[len(idx) // 2]}
    for k in sorted(picks):
        st = RecordingState(cancel_after=k)
        with pytest.raises(Cancelled):
            min_range_law(circuit, vessel, spec, state=st, solver=solver)
        assert st.polls == k + 1, (k, st.polls)  # stopped at the first poll that said "cancel"
        assert not st.fractions or st.fractions[-1] < 1.0
