"""Cycloidal slot forming (engine/slotting.py, `winder slot`) — MATH.md §D, seed 002.

Independent references used here: the closed-form circle intersection for a fixed part (i = 0),
a forward kinematic model (law of cosines + rotation into the part frame, not system (1)), a
numerically sampled trajectory, and the bracketing solver against the paper's fixed-point iteration.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.cli import main
from engine.errors import Cancelled, InputError
from engine.slotting import (
    SlotSetup,
    centre_distance_paper,
    cutting_mode,
    error_histories,
    fixed_point_iteration,
    forward_slot_length,
    max_reachable_length,
    parse_range,
    ratio_curves,
    reduced_parameters,
    slot_study,
    slot_table,
    slot_trajectory,
    solve_slot,
    table_csv,
    theta_roots,
    write_table_csv,
)

RHO, RU, TOL = 22.0, -95.0, 0.005  # the paper's case: ρ = R_d1 = 22 mm, R_u = −95 mm, [Δ] = 0.005
LENGTHS = np.arange(2.0, 20.0 + 1e-9, 2.0)  # l = 2 … 20 mm


def paper(i: float, **kw) -> SlotSetup:
    return SlotSetup(RHO, RU, i, TOL, **kw)


# ---------------------------------------------------------------------------------------------
# the paper's Tables 2 and 3
# ---------------------------------------------------------------------------------------------
# The seed text (002_*.txt) keeps only the captions of Tables 2 and 3: their printed numbers were
# lost in PDF extraction, so no numerical comparison with the paper is possible.  These are our
# values (iteration answer, exact closure; the paper's printed closure alongside) — a regression
# anchor, each of them checked independently by the tests below.
TABLE2_I_MINUS_2 = {  # l: (A exact, A paper-printed closure, j)
    2: (116.903, 116.922, 7), 4: (116.617, 116.689, 7), 6: (116.151, 116.311, 6), 8: (115.519, 115.795, 6),
    10: (114.738, 115.154, 6), 12: (113.829, 114.403, 6), 14: (112.813, 113.558, 6), 16: (111.712, 112.634, 6),
    18: (110.555, 111.665, 5), 20: (109.338, 110.626, 5),
}
TABLE3_I_MINUS_1 = {
    2: (116.953, 116.962, 4), 4: (116.811, 116.847, 4), 6: (116.577, 116.656, 4), 8: (116.251, 116.391, 4),
    10: (115.838, 116.054, 4), 12: (115.341, 115.646, 4), 14: (114.763, 115.171, 4), 16: (114.111, 114.633, 4),
    18: (113.389, 114.033, 4), 20: (112.603, 113.378, 4),
}


@pytest.mark.parametrize("ratio, expected", [(-2, TABLE2_I_MINUS_2), (-1, TABLE3_I_MINUS_1)])
def test_paper_tables_regression(ratio: float, expected: dict) -> None:
    table = slot_table(LENGTHS, paper(ratio))
    for row in table.rows:
        a, a_paper, j = expected[round(row.l)]
        assert row.A == pytest.approx(a, abs=6e-4)
        assert row.A_paper == pytest.approx(a_paper, abs=6e-4)
        assert row.iterations == j
        assert row.converged and row.method == "iteration" and row.message == ""
        assert row.mode == "down-cut"


@pytest.mark.parametrize("ratio", [-4, -3, -2, -1, -0.5, 0, 0.5, 1, 2, 3])
def test_iteration_agrees_with_bracketing_solver(ratio: float) -> None:
    """Every row: |θ_iter − θ_brentq| within the [Δ]-consistent bound max(1, q/(1−q))·[Δ]·|θ|."""
    for row in slot_table(LENGTHS, paper(ratio)).rows:
        assert row.converged and row.agrees, row
        assert abs(row.theta - row.theta_check) <= row.theta_bound
        q = row.contraction
        assert row.theta_bound <= max(1.0, q / (1 - q)) * TOL * abs(row.theta_check) * 1.0001
        # the bracketing root is exact by the forward model (independent of system (1))
        s = paper(ratio)
        assert forward_slot_length(row.A_check, s) == pytest.approx(row.l, abs=1e-9)
        # the slot the iteration's A really gives: off by at most |dl/dθ|·(θ bound) (to first order)
        assert abs(forward_slot_length(row.A, s) - row.l) <= 1.5 * dl_dtheta(row, s) * row.theta_bound + 1e-12
        # ... which is within [Δ]·l in the paper's range (|i| <= 2); near |ρ·i/R_u| = 1 (i = -4,
        # q = 0.84) a θ within [Δ] can still mean a few per cent in l
        if abs(ratio) <= 2:
            assert abs(forward_slot_length(row.A, s) - row.l) <= TOL * row.l


def dl_dtheta(row, s: SlotSetup) -> float:
    """|dl/dθ| at the root: l = 2ρ(β(θ) − iθ) with sin β = (R_u/ρ) sin θ."""
    th = row.theta_check
    beta = row.phi + s.ratio * th
    return abs(2 * s.rho * (s.tool_radius * math.cos(th) / (s.rho * math.cos(beta)) - s.ratio))


def test_fixed_part_closed_form() -> None:
    """i = 0: the tool circle meets circle ρ at ±φ: A = ρ cos φ + sqrt(R_u² − ρ² sin² φ)."""
    for row in slot_table(LENGTHS, paper(0)).rows:
        phi = row.l / (2 * RHO)
        assert row.A == pytest.approx(RHO * math.cos(phi) + math.sqrt(RU**2 - (RHO * math.sin(phi)) ** 2), abs=1e-12)
        assert row.theta == pytest.approx(math.asin(RHO / RU * math.sin(phi)), abs=1e-15)
        assert row.iterations == 1  # "at i = 0 the computation ends at the first iteration"
        assert list(row.error_history) == [1.0, 0.0]


def test_printed_closure_differs_from_exact_by_cos_theta() -> None:
    """The paper's printed A lacks cos θ: A_paper − A_exact = −R_u (1 − cos θ); its slot is short."""
    for ratio in (-2, -1, 0, 1):
        for row in slot_table(LENGTHS, paper(ratio)).rows:
            th = row.theta_check  # the identity holds at the exact root
            a_paper = centre_distance_paper(th, RHO, RU)
            assert a_paper - row.A_check == pytest.approx(-RU * (1 - math.cos(th)), abs=1e-9)
            assert forward_slot_length(row.A_paper, paper(ratio)) < row.l * 0.92
    row = solve_slot(20.0, paper(0))
    assert forward_slot_length(row.A_paper, paper(0)) == pytest.approx(18.06, abs=0.01)
    assert centre_distance_paper(row.theta, RHO, RU) == row.A_paper
    # the setting a_formula="paper" reports the printed closure as A
    assert solve_slot(20.0, paper(0, a_formula="paper")).A == row.A_paper


# ---------------------------------------------------------------------------------------------
# the paper's qualitative findings (Figs. 4 and 5)
# ---------------------------------------------------------------------------------------------
def test_A_falls_with_l_and_rises_with_i() -> None:
    ratios = np.round(np.arange(-4.0, 4.0 + 1e-9, 0.25), 6)
    curves = ratio_curves([2, 5, 10, 15, 20], ratios, paper(0))
    assert np.all(np.isfinite(curves.A))
    assert np.all(np.diff(curves.A, axis=1) > 0)  # rises with i
    assert np.all(np.diff(curves.A, axis=0) < 0)  # falls with l
    for ratio in (-2, -1):
        assert np.all(np.diff(slot_table(LENGTHS, paper(ratio)).A) < 0)


def test_sensitivity_highest_in_down_cut() -> None:
    """|dA/di| is larger on the down-cut side (i < 0 for the external scheme) than on the up-cut side."""
    for l in (10.0, 20.0):
        def a(i: float, l: float = l) -> float:
            return solve_slot(l, paper(i)).A_check

        for mag in (1.0, 2.0, 3.0):
            down = abs(a(-mag + 0.01) - a(-mag - 0.01))
            up = abs(a(mag + 0.01) - a(mag - 0.01))
            assert down > 1.5 * up
    assert cutting_mode(-2, RU) == "down-cut" and cutting_mode(2, RU) == "up-cut"
    assert cutting_mode(0, RU) == "fixed part"
    assert cutting_mode(2, 30.0) == "down-cut"  # internal scheme: i·R_u > 0 is down-cut too


def test_more_iterations_as_abs_i_grows() -> None:
    for l in (2.0, 10.0, 20.0):
        for side in (-1, 1):
            # the paper's range; at l = 20 mm, i = -4 (|ρ·i/R_u| = 0.93) needs 5 steps against 6 at
            # i = -3: the root's contraction factor falls as cos(φ + iθ) does
            its = [solve_slot(l, paper(side * m)).iterations for m in (0, 0.5, 1, 2, 3)]
            assert its[0] == 1
            assert all(b >= a for a, b in zip(its, its[1:])), (l, side, its)
            assert its[-1] > its[1]


def test_error_monotone_in_down_cut_alternating_in_up_cut() -> None:
    hist = error_histories(10.0, [-3, -2, -1, 1, 2, 3], paper(0))
    for ratio, it in hist.items():
        d = it.error_history
        assert it.converged and d[0] == 1.0 and abs(d[-1]) <= TOL
        if ratio < 0:  # down-cut: monotone decay, one sign
            assert np.all(d > 0)
            assert np.all(np.diff(d) < 0)
        else:  # up-cut: alternating sign, decaying envelope (|Δ_j+2| < |Δ_j|)
            assert np.all(np.sign(d[1:]) == -np.sign(d[:-1]))
            assert np.all(np.abs(d[2:]) < np.abs(d[:-2]))


# ---------------------------------------------------------------------------------------------
# where the iteration cannot converge
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ratio", [4.5, 6.0, 10.0])
def test_up_cut_beyond_contraction_falls_back(ratio: float) -> None:
    s = paper(ratio)
    row = solve_slot(20.0, s)
    assert not row.converged and row.method == "fallback"
    assert "|ρ·i/R_u|" in row.message and "bracketing" in row.message
    assert forward_slot_length(row.A, s) == pytest.approx(20.0, abs=1e-9)


def test_down_cut_beyond_contraction_is_flagged_and_checked() -> None:
    s = paper(-6.0)
    row = solve_slot(20.0, s)
    assert ">= 1" in row.message  # the user is told the guarantee does not hold
    assert row.agrees and abs(row.theta - row.theta_check) <= row.theta_bound
    assert forward_slot_length(row.A_check, s) == pytest.approx(20.0, abs=1e-9)


def test_internal_scheme_domain_error_and_unreachable() -> None:
    s = SlotSetup(rho=60.0, tool_radius=25.0, ratio=0.5, tol=TOL)  # tool inside, |ρ/R_u| > 1
    row = solve_slot(20.0, s)
    assert row.status == "domain" and row.method == "fallback" and "outside [-1, 1]" in row.message
    assert forward_slot_length(row.A, s) == pytest.approx(20.0, abs=1e-9)
    bad = solve_slot(60.0, s)
    assert bad.method == "none" and not bad.ok and math.isnan(bad.A)
    assert "cannot be reached" in bad.message and "longest reachable" in bad.message
    assert bad.as_dict()["A_mm"] is None


def test_max_reachable_length_fixed_part_closed_form() -> None:
    """i = 0, tool inside: the longest chord angle is arcsin(R_u/ρ)."""
    s = SlotSetup(rho=60.0, tool_radius=25.0, ratio=0.0)
    assert max_reachable_length(s) == pytest.approx(2 * 60 * math.asin(25 / 60), rel=1e-6)
    assert solve_slot(51.0, s).ok and not solve_slot(52.0, s).ok


def test_internal_ring_tool() -> None:
    """R_u > ρ (ring tool around the part): A is negative (centre on the other side) and exact."""
    s = SlotSetup(rho=22.0, tool_radius=100.0, ratio=0.3)
    for l in (5.0, 20.0, 40.0):
        row = solve_slot(l, s)
        assert row.A < 0 and row.agrees
        assert forward_slot_length(row.A_check, s) == pytest.approx(l, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    rho=st.floats(5.0, 80.0),
    scale=st.floats(1.3, 8.0),
    ki=st.floats(-0.85, 0.85),
    frac=st.floats(0.02, 0.9),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_property_iteration_vs_brentq(rho: float, scale: float, ki: float, frac: float, sign: float) -> None:
    ru = sign * rho * scale  # |ρ/R_u| < 1
    ratio = ki * ru / rho
    s = SlotSetup(rho, ru, ratio, TOL)
    l = frac * 2 * rho * 1.2  # φ up to ~1.1 rad
    row = solve_slot(l, s)
    if row.method == "iteration":
        assert row.agrees
        assert abs(row.theta - row.theta_check) <= row.theta_bound
    if row.ok:
        assert forward_slot_length(row.A_check, s) == pytest.approx(l, rel=1e-8)


# ---------------------------------------------------------------------------------------------
# kinematics: the trajectory S in the part frame
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ratio", [-2, 0, 1.5])
def test_trajectory_crosses_bore_at_slot_ends(ratio: float) -> None:
    s = paper(ratio, part_radius=30.0)
    row = solve_slot(16.0, s)
    tr = slot_trajectory(row.A_check, s, n=20001)
    assert tr.slot_length == pytest.approx(16.0, abs=1e-9)
    # numerically: where the sampled path crosses r = ρ, by linear interpolation
    d = tr.r - RHO
    idx = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    assert len(idx) == 2
    angles = []
    for k in idx:
        t = d[k] / (d[k] - d[k + 1])
        x = tr.x[k] + t * (tr.x[k + 1] - tr.x[k])
        y = tr.y[k] + t * (tr.y[k + 1] - tr.y[k])
        angles.append(math.atan2(y, x))
    assert sorted(angles) == pytest.approx([-row.phi, row.phi], abs=1e-5)
    assert tr.r.min() < RHO < tr.r.max()
    assert tr.r.max() >= 30.0  # the path reaches the outer surface R_d


def test_reduced_parameters_table1() -> None:
    red = reduced_parameters(paper(-2, part_radius=25.0))
    assert red.i1 == pytest.approx(-95 / 25)
    assert red.A_tilde_nominal == pytest.approx(1 + 95 / 25)
    assert red.I == pytest.approx((-95 / 25) / -2)
    assert red.rho_tilde == pytest.approx(22 / 25)
    assert reduced_parameters(paper(0)).I is None


def test_theta_roots_unique_in_contraction_region() -> None:
    roots = theta_roots(10 / 44, -2.0, RHO / RU)
    assert len(roots) == 1
    it = fixed_point_iteration(10 / 44, -2.0, RHO / RU, 1e-14, 500)
    assert it.theta == pytest.approx(roots[0], abs=1e-13)


# ---------------------------------------------------------------------------------------------
# input errors, state, study, CSV
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"rho": 0.0, "tool_radius": -95.0}, "rho"),
        ({"rho": float("nan"), "tool_radius": -95.0}, "rho"),
        ({"rho": 22.0, "tool_radius": 0.0}, "tool_radius"),
        ({"rho": 22.0, "tool_radius": 22.0}, "tool_radius"),
        ({"rho": 22.0, "tool_radius": -95.0, "tol": 0.0}, "tol"),
        ({"rho": 22.0, "tool_radius": -95.0, "tol": 1.5}, "tol"),
        ({"rho": 22.0, "tool_radius": -95.0, "ratio": float("inf")}, "ratio"),
        ({"rho": 22.0, "tool_radius": -95.0, "max_iter": 0}, "max_iter"),
        ({"rho": 22.0, "tool_radius": -95.0, "part_radius": -1.0}, "part_radius"),
    ],
)
def test_bad_setup(kwargs: dict, field: str) -> None:
    with pytest.raises(InputError) as err:
        solve_slot(10.0, SlotSetup(**kwargs))
    assert err.value.location.field == field


@pytest.mark.parametrize("l", [0.0, -2.0, float("nan"), 2 * math.pi * RHO])
def test_bad_length(l: float) -> None:
    with pytest.raises(InputError) as err:
        slot_table([5.0, l], paper(-1))
    assert err.value.location.field == "length"


def test_parse_range() -> None:
    assert parse_range("2:20:2") == pytest.approx(LENGTHS)
    assert parse_range("0.1:0.3:0.1") == pytest.approx([0.1, 0.2, 0.3])
    assert parse_range("5") == pytest.approx([5.0])
    assert parse_range("1, 2,3") == pytest.approx([1, 2, 3])
    for bad in ("", "a", "1:2", "1:2:0", "3:1:1", "0:1e9:1", "1:nan:1"):
        with pytest.raises(InputError):
            parse_range(bad)


def test_state_progress_and_cancel(state) -> None:
    slot_table(LENGTHS, paper(-2), state)
    assert state.fractions[-1] == pytest.approx(1.0)
    assert all(b >= a for a, b in zip(state.fractions, state.fractions[1:]))
    from engine.state import RecordingState

    with pytest.raises(Cancelled):
        slot_study(paper(-2), LENGTHS, [10], [-1, 0, 1], [0], 10.0, RecordingState(cancel_after=0))


def test_study_bundles_everything(state) -> None:
    study = slot_study(paper(-2), LENGTHS, [2, 10, 20], np.linspace(-4, 4, 9), [-2, 0, 2], 20.0, state)
    assert len(study.table.rows) == 10
    assert study.curves.A.shape == (3, 9)
    assert set(study.histories) == {-2.0, 0.0, 2.0}
    assert study.trajectory is not None and study.trajectory.slot_length == pytest.approx(20.0, rel=TOL)
    assert state.fractions[-1] == 1.0


def test_csv_roundtrip(tmp_path: Path) -> None:
    table = slot_table(LENGTHS, paper(-2))
    out = write_table_csv(tmp_path / "t.csv", table)
    rows = list(csv.reader(out.read_text(encoding="utf-8").splitlines()))
    assert rows[0][0].startswith("# rho_mm=22")
    assert rows[1][:2] == ["l_mm", "A_mm"]
    assert [float(r[1]) for r in rows[2:]] == pytest.approx(list(table.A), abs=1e-12)
    assert table_csv(table) == out.read_text(encoding="utf-8")
    with pytest.raises(InputError):
        write_table_csv(tmp_path / "missing-dir" / "t.csv", table)


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------
def test_cli_json(capsys) -> None:
    rc = main(["slot", "--rho", "22", "--tool-radius", "-95", "--ratio", "-2", "--length", "2:20:2",
               "--tol", "0.005", "--json"])
    assert rc == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 10
    for r in rows:
        for key in ("l_mm", "A_mm", "theta_rad", "iterations", "converged", "error_history"):
            assert key in r
        assert r["converged"] and abs(r["error_history"][-1]) <= 0.005
        assert r["A_mm"] == pytest.approx(TABLE2_I_MINUS_2[round(r["l_mm"])][0], abs=6e-4)


def test_cli_text_and_csv(capsys, tmp_path: Path) -> None:
    out = tmp_path / "table.csv"
    rc = main(["slot", "--rho", "22", "--tool-radius", "-95", "--ratio", "-1", "--length", "2:20:2",
               "--csv", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "down-cut" in text and "Reduced (Table 1)" in text and "112.603" in text
    assert out.exists() and out.read_text(encoding="utf-8").count("\n") == 12


def test_cli_unreachable_and_bad_input(capsys) -> None:
    rc = main(["slot", "--rho", "60", "--tool-radius", "25", "--ratio", "0", "--length", "20,60", "--json"])
    captured = capsys.readouterr()
    assert rc == 1 and "cannot be reached" in captured.err
    rows = json.loads(captured.out)
    assert rows[0]["A_mm"] is not None and rows[1]["A_mm"] is None and "cannot be reached" in rows[1]["message"]
    assert main(["slot", "--rho", "-1", "--tool-radius", "-95", "--length", "2"]) == 2
    assert "rho" in capsys.readouterr().err
    assert main(["slot", "--rho", "22", "--tool-radius", "-95", "--length", "2:x"]) == 2


def test_cli_subprocess() -> None:
    exe = Path(sys.executable).with_name("winder")
    res = subprocess.run(
        [str(exe), "slot", "--rho", "22", "--tool-radius", "-95", "--ratio", "-2", "--length", "10", "--json"],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert res.returncode == 0, res.stderr
    (row,) = json.loads(res.stdout)
    assert row["A_mm"] == pytest.approx(114.738, abs=6e-4) and row["iterations"] == 6
