"""Turning-mode optimiser (MATH.md §C): the paper's numbers, independent cross-checks, bad input, CLI."""

from __future__ import annotations

import itertools
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from engine.cli import main
from engine.errors import Cancelled, InfeasibleError, InputError
from engine.turning import (
    CONSTRAINT_NAMES,
    Model,
    Row,
    TurningCase,
    build_model,
    case_from_dict,
    example_case_path,
    is_feasible,
    load_case,
    load_data,
    minimal_removal_sets,
    optimise,
    plot_data,
    result_to_json,
    solve_model,
)

ROOT = Path(__file__).resolve().parents[1]
DATA = load_data()


def paper_case() -> TurningCase:
    return load_case(example_case_path("paper"))


# ------------------------------------------------------------------------------ the paper's numbers
def test_paper_expert_rows_give_the_mathcad_answer() -> None:
    res = optimise(example_case_path("paper-expert"))
    assert res.x1 == pytest.approx(6.875, abs=1e-9)
    assert res.x2 == pytest.approx(0.300, abs=1e-9)
    assert res.n_rpm == pytest.approx(967.78, rel=1e-3)
    assert res.feed_mm_rev == pytest.approx(1.35, rel=1e-3)
    assert set(res.active) == {"power", "roughness"}
    assert set(res.disabled) == {"tool_life", "insert"}  # the Mathcad "Given" block omits b1, b5
    # V = pi D n / 1000: the paper's program shows 244.8 m/min for its n = 974.4 rpm, D = 80 mm
    assert math.pi * 80 * 974.4 / 1000 == pytest.approx(244.8, abs=0.1)


def test_paper_physical_model_closed_form() -> None:
    """The handbook model's optimum, recomputed by hand from the K&M coefficients."""
    res = optimise(paper_case())
    # roughness (geometric): S = sqrt(8 r Rz) = sqrt(8 * 1.0 mm * 0.080 mm)
    s = math.sqrt(8 * 1.0 * 0.080)
    # Taylor, band S > 0.4: V = 243 K_v / (T^0.2 t^0.15 S^0.4), K_v = (190/200)^1.25 (VK6, no crust, phi 45)
    v = 243 * (190 / 200) ** 1.25 / (60**0.2 * 1.5**0.15 * s**0.4)
    n = 1000 * v / (math.pi * 80)
    assert res.feed_mm_rev == pytest.approx(s, rel=1e-9)
    assert res.n_rpm == pytest.approx(n, rel=1e-9)
    assert res.n_rpm == pytest.approx(411.38, abs=0.01)
    assert set(res.active) == {"tool_life", "roughness"}
    q = res.quantities
    assert q["tool_life_min"] == pytest.approx(60.0, rel=1e-9)
    assert q["rz_um"] == pytest.approx(80.0, rel=1e-9)
    pz = 10 * 92 * 1.5 * s**0.75 * (200 / 190) ** 0.4
    assert q["force_pz_n"] == pytest.approx(pz, rel=1e-9)
    assert q["power_kw"] == pytest.approx(pz * v / 61200, rel=1e-9)
    assert q["machine_time_min"] == pytest.approx(50 / (n * s), rel=1e-9)
    # every other row has positive slack
    for name, sl in res.slack.items():
        assert (sl == pytest.approx(0, abs=1e-9)) == (name in res.active)


def test_paper_first_band_as_the_paper_did() -> None:
    """With the S <= 0.4 Taylor row for every feed (the paper's y = 0.2), still tool life + roughness bind."""
    res = optimise(paper_case().with_(speed_bands="first"))
    s = 0.8
    v = 292 * (190 / 200) ** 1.25 / (60**0.2 * 1.5**0.15 * s**0.2)
    assert res.n_rpm == pytest.approx(1000 * v / (math.pi * 80), rel=1e-9)
    assert res.feed_mm_rev == pytest.approx(s)


def test_paper_rows_without_tool_life_reach_the_power_limit() -> None:
    """Dropping b1 as the Mathcad sheet did: the power row (4) and roughness bind, like the paper's pair."""
    res = optimise(paper_case().with_(disabled=("tool_life",)))
    assert set(res.active) == {"power", "roughness"}
    assert res.quantities["power_kw"] == pytest.approx(11 * 0.83, rel=1e-9)


# ------------------------------------------------------------------------------ independent checks
def _vertex_optimum(rows: list[Row]) -> float:
    """Max of x1 + x2 by enumerating all pairwise intersections (exact, no LP solver)."""
    best = -math.inf
    for r, q in itertools.combinations(rows, 2):
        det = r.a * q.b - r.b * q.a
        if abs(det) < 1e-12:
            continue
        x1 = (r.rhs * q.b - r.b * q.rhs) / det
        x2 = (r.a * q.rhs - r.rhs * q.a) / det
        if all(w.value(x1, x2) <= w.rhs + 1e-9 for w in rows):
            best = max(best, x1 + x2)
    return best


def _grid_optimum(rows: list[Row], box: tuple[float, float, float, float], m: int = 801) -> float:
    x1 = np.linspace(box[0], box[1], m)
    x2 = np.linspace(box[2], box[3], m)
    X1, X2 = np.meshgrid(x1, x2)
    ok = np.ones_like(X1, dtype=bool)
    for r in rows:
        ok &= r.a * X1 + r.b * X2 <= r.rhs + 1e-12
    return float(np.max(np.where(ok, X1 + X2, -np.inf)))


def _random_case(rng: np.random.Generator) -> TurningCase:
    mat = rng.choice(["sch20", "sch15", "steel45", "40kh"])
    tool = "VK8" if str(mat).startswith("sch") else rng.choice(["T15K6", "T5K10"])
    return TurningCase(
        material=str(mat), tool=str(tool), diameter_mm=float(rng.uniform(30, 200)),
        depth_mm=float(rng.uniform(0.5, 5)), length_mm=float(rng.uniform(100, 800)),
        tool_life_min=float(rng.uniform(15, 120)), rz_um=float(rng.uniform(10, 160)),
        nose_radius_mm=float(rng.choice([0.4, 0.8, 1.2, 2.0])), phi=math.radians(float(rng.choice([45, 60, 90]))),
        fixture=str(rng.choice(["centres", "chuck", "chuck_tailstock"])),
        power_kw=float(rng.uniform(3, 15)),
    )


@pytest.mark.parametrize("seed", range(12))
def test_lp_equals_grid_search_and_vertex_enumeration(seed: int) -> None:
    rng = np.random.default_rng(seed)
    case = _random_case(rng)
    model = build_model(case, DATA)
    try:
        sol = solve_model(model)
    except InfeasibleError:
        assert all(not is_feasible(model.band_rows(k)) for k in range(len(model.bands)))
        return
    f = sol.x1 + sol.x2
    verts, grids = [], []
    for k in range(len(model.bands)):
        rows = [r for r in model.band_rows(k) if math.isfinite(r.rhs)]
        verts.append(_vertex_optimum(rows))
        box = (-1.0, 9.0, -4.0, 2.0)
        grids.append(_grid_optimum(rows, box))
    assert f == pytest.approx(max(verts), abs=1e-7)
    g = max(grids)
    step = (9.0 + 1.0) / 800 + 6.0 / 800
    assert g <= f + 1e-9  # no grid point beats the LP
    assert g >= f - 2 * step  # and the grid gets as close as its spacing allows


def test_random_rows_lp_vs_vertices_and_feasibility() -> None:
    rng = np.random.default_rng(7)
    agree = 0
    for _ in range(150):
        m = int(rng.integers(3, 9))
        rows = [Row(f"r{i}", float(rng.normal()), float(rng.normal()), float(rng.normal(0, 2))) for i in range(m)]
        rows += [Row("box1", 1, 0, 5), Row("box2", -1, 0, 5), Row("box3", 0, 1, 5), Row("box4", 0, -1, 5)]
        model = Model(tuple(rows), ((0.0, math.inf),), None, None, 1.0)
        feas = is_feasible(rows)
        try:
            sol = solve_model(model)
        except InfeasibleError:
            assert not feas
            continue
        assert feas
        assert sol.x1 + sol.x2 == pytest.approx(_vertex_optimum(rows), abs=1e-7)
        agree += 1
    assert agree > 20


# ------------------------------------------------------------------------------ monotonicity
cases = st.builds(
    dict,
    material=st.sampled_from(["sch20", "steel45"]),
    diameter_mm=st.floats(40, 160),
    depth_mm=st.floats(0.5, 4),
    tool_life_min=st.floats(20, 90),
    rz_um=st.floats(20, 120),
    power_kw=st.floats(2, 15),
)
factor = st.floats(0.3, 0.95)


def _mk(d: dict) -> TurningCase:
    tool = "VK6" if d["material"] == "sch20" else "T15K6"
    return TurningCase(tool=tool, **d)


def _solve(case: TurningCase):
    try:
        return optimise(case, DATA)
    except InputError:  # infeasible, or the tightened limit left an empty range
        return None


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases, factor)
def test_tighter_power_never_helps(d: dict, k: float) -> None:
    a, b = _solve(_mk(d)), _solve(_mk(d | {"power_kw": d["power_kw"] * k}))
    assume(a is not None and b is not None)
    assert b.x1 + b.x2 <= a.x1 + a.x2 + 1e-9
    assert b.quantities["power_kw"] <= 0.83 * d["power_kw"] * k * (1 + 1e-9)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases, factor)
def test_smoother_surface_lowers_feed(d: dict, k: float) -> None:
    a, b = _solve(_mk(d)), _solve(_mk(d | {"rz_um": d["rz_um"] * k}))
    assume(a is not None and b is not None)
    assert b.x1 + b.x2 <= a.x1 + a.x2 + 1e-9
    assert b.feed_mm_rev <= a.feed_mm_rev * (1 + 1e-9)  # roughness rows constrain only S


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases, st.floats(1.1, 4.0))
def test_longer_tool_life_lowers_speed(d: dict, k: float) -> None:
    a, b = _solve(_mk(d)), _solve(_mk(d | {"tool_life_min": d["tool_life_min"] * k}))
    assume(a is not None and b is not None)
    assert b.x1 + b.x2 <= a.x1 + a.x2 + 1e-9
    assert b.quantities["speed_m_min"] <= a.quantities["speed_m_min"] * (1 + 1e-9) or b.band != a.band


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases, factor)
def test_lower_speed_limit_lowers_n(d: dict, k: float) -> None:
    base = _solve(_mk(d))
    assume(base is not None)
    b = _solve(_mk(d | {"n_max_rpm": base.n_rpm * k}))
    assume(b is not None)
    assert b.n_rpm <= base.n_rpm * k * (1 + 1e-9)
    assert b.x1 + b.x2 <= base.x1 + base.x2 + 1e-9


# ------------------------------------------------------------------------------ constraint editing
def test_user_row_and_limit_factor_and_disable() -> None:
    doc = {"mode": "physical", "constraints": {"user": [{"name": "chip", "a": 1, "b": 1, "c": 150.0}]}}
    res = optimise(case_from_dict(doc), DATA)
    assert res.n_rpm * res.feed_mm_rev == pytest.approx(150.0, rel=1e-9)
    assert "chip" in res.active
    base = optimise(paper_case())
    half = optimise(paper_case().with_(limit_factor=(("tool_life", 0.5),)))
    assert half.n_rpm == pytest.approx(base.n_rpm / 2, rel=1e-9)  # n S^y <= c: halving c halves n at fixed S
    off = optimise(paper_case().with_(disabled=("roughness",)))
    assert "roughness" in off.disabled and off.feed_mm_rev > base.feed_mm_rev


def test_unbounded_is_reported_not_a_solver_code() -> None:
    case = paper_case().with_(disabled=("tool_life", "power", "n_max"))
    with pytest.raises(InfeasibleError, match="unbounded"):
        optimise(case)


def test_infeasible_names_conflicting_constraints() -> None:
    case = paper_case().with_(rz_um=1.0)  # S <= sqrt(8 * 1 * 0.001) = 0.089 < S_min = 0.1
    with pytest.raises(InfeasibleError) as ei:
        optimise(case)
    msg = str(ei.value)
    assert "roughness" in msg and "s_min" in msg and "status" not in msg.lower()
    assert ei.value.removal_sets == (("roughness",), ("s_min",))
    assert "paper.toml" in msg


def test_minimal_removal_sets_brute_force() -> None:
    case = paper_case().with_(rz_um=1.0, n_max_rpm=150.0, n_min_rpm=100.0, tool_life_min=1e6)
    model = build_model(case, DATA)
    sets = minimal_removal_sets(model)
    assert sets and all(len(s) == len(sets[0]) for s in sets)
    names = sorted({r.name for r in model.rows if r.enabled})
    for size in range(1, len(sets[0])):
        for s in itertools.combinations(names, size):
            rows_ok = any(is_feasible([r for r in model.band_rows(k) if r.name not in s])
                          for k in range(len(model.bands)))
            assert not rows_ok
    assert {"roughness", "tool_life"} & set(itertools.chain(*sets))


# ------------------------------------------------------------------------------ snapping
def test_snap_is_the_best_feasible_discrete_pair() -> None:
    case = paper_case().with_(machine="16K20")
    res = optimise(case, DATA, snap=True)
    sn = res.snapped
    assert sn is not None and sn["feasible"]
    model = res.model
    mach = DATA.machines["16K20"]
    best = 0.0
    for n, s in itertools.product(mach["speed_series_rpm"], mach["feed_series_mm_rev"]):
        x1, x2 = math.log(n), math.log(s)
        if any(all(r.value(x1, x2) <= r.rhs + 1e-12 for r in model.band_rows(k) if math.isfinite(r.rhs))
               for k in range(len(model.bands))):
            best = max(best, n * s)
    assert sn["n_rpm"] * sn["feed_mm_rev"] == pytest.approx(best)
    assert sn["n_rpm"] in mach["speed_series_rpm"] and sn["feed_mm_rev"] in mach["feed_series_mm_rev"]
    assert sn["ratio_to_continuous"] <= 1.0


def test_no_series_means_no_snap() -> None:
    assert optimise(paper_case(), snap=True).snapped is None


# ------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("doc", "field", "text"),
    [
        ({"workpiece": {"depth_mm": -1.5}}, "workpiece.depth_mm", "positive"),
        ({"machine": {"s_min_mm_rev": 2.0, "s_max_mm_rev": 0.5}}, "machine.s_max_mm_rev", "inverted"),
        ({"workpiece": {"material": "unobtainium"}}, "workpiece.material", "unknown workpiece material"),
        ({"tool": {"material": "diamond"}}, "tool.material", "unknown tool material"),
        ({"machine": {"id": "lathe9000"}}, "machine.id", "unknown machine"),
        ({"tool": {"phi_deg": 200}}, "tool.phi_deg", "angle"),
        ({"workpiece": {"fixture": "glue"}}, "workpiece.fixture", "fixture"),
        ({"workpiece": {"depth_mm": "deep"}}, "workpiece.depth_mm", "number"),
        ({"workpiece": {"depth_mm": 50.0}}, "workpiece.depth_mm", "radius"),
        ({"workpiece": {"colour": "red"}}, "workpiece.colour", "unknown entry"),
        ({"constraints": {"disable": ["nonsense"]}}, "constraints.disable", "unknown constraint"),
        ({"mode": "expert"}, "rows", "expert mode needs"),
    ],
)
def test_bad_input_names_the_field(doc: dict, field: str, text: str) -> None:
    with pytest.raises(InputError) as ei:
        optimise(case_from_dict(doc, file="case.toml"), DATA)
    assert ei.value.location.field == field
    assert text in ei.value.message
    assert "case.toml" in str(ei.value)


def test_unknown_group_tool_factor_names_the_file() -> None:
    with pytest.raises(InputError) as ei:
        optimise(TurningCase(material="sch20", tool="T15K6"), DATA)
    assert ei.value.location.file.endswith("speed.toml")
    assert ei.value.location.field == "grey_cast_iron.k_uv.T15K6"


def test_missing_coefficient_names_file_and_key(tmp_path: Path) -> None:
    for f in (ROOT / "resources" / "cutting").glob("*.toml"):
        shutil.copy(f, tmp_path / f.name)
    force = (tmp_path / "force.toml").read_text(encoding="utf-8")
    (tmp_path / "force.toml").write_text(force.replace("pz = { cp = 92.0, x = 1.0,", "pz = { x = 1.0,"),
                                         encoding="utf-8")
    with pytest.raises(InputError) as ei:
        optimise(paper_case(), load_data(tmp_path))
    assert ei.value.location.file.endswith("force.toml")
    assert ei.value.location.field == "grey_cast_iron.pz.cp"
    speed = (tmp_path / "speed.toml").read_text(encoding="utf-8")
    (tmp_path / "force.toml").write_text(force, encoding="utf-8")
    (tmp_path / "speed.toml").write_text(speed.replace("cv = 243.0", "cw = 243.0"), encoding="utf-8")
    with pytest.raises(InputError, match=r"bands\[1\]\.cv"):
        optimise(paper_case(), load_data(tmp_path))


def test_missing_force_component_for_stainless() -> None:
    case = TurningCase(material="12kh18n10t", tool="VK8")
    with pytest.raises(InputError) as ei:
        optimise(case, DATA)
    assert "force.toml" in str(ei.value) and "accuracy" in str(ei.value)
    res = optimise(case.with_(disabled=("accuracy", "feed_mechanism")), DATA)
    assert res.n_rpm > 0 and res.quantities["force_py_n"] is None


def test_every_material_and_tool_in_the_database_is_usable() -> None:
    for mat, tool, off in [("sch20", "VK6", ()), ("sch15", "VK8", ()), ("steel45", "T15K6", ()),
                           ("40kh", "T5K10", ()), ("12kh18n10t", "VK8", ("accuracy", "feed_mechanism")),
                           ("d16t", "VK6", ("accuracy", "feed_mechanism"))]:
        res = optimise(TurningCase(material=mat, tool=tool, disabled=off), DATA)
        assert 0 < res.n_rpm and 0 < res.feed_mm_rev


# ------------------------------------------------------------------------------ state, plot data
def test_progress_and_cancel(state) -> None:
    optimise(paper_case(), DATA, state=state)
    assert state.fractions[0] == 0.0 and state.fractions[-1] == 1.0
    from engine.state import RecordingState

    with pytest.raises(Cancelled):
        optimise(paper_case(), DATA, state=RecordingState(cancel_after=0))


def test_plot_data_is_consistent() -> None:
    res = optimise(paper_case(), DATA)
    pd = plot_data(res)
    names = {ln["name"] for ln in pd["lines"]}
    assert {"power", "roughness", "tool_life", "s_min", "s_max", "n_min", "n_max"} <= names
    # every vertex of a shaded region is feasible in its band
    for reg in pd["regions"]:
        rows = res.model.band_rows(reg["band"])
        for n, s in zip(reg["n"], reg["S"]):
            assert all(r.value(math.log(n), math.log(s)) <= r.rhs + 1e-7 for r in rows if math.isfinite(r.rhs))
    # the objective line passes through the optimum: n S = const
    o = pd["objective"]
    assert o["n"][0] * o["S"][0] == pytest.approx(res.n_rpm * res.feed_mm_rev)
    assert pd["optimum"] == (res.n_rpm, res.feed_mm_rev)
    assert sum(ln["active"] for ln in pd["lines"]) == 2


# ------------------------------------------------------------------------------ CLI
def test_cli_json_expert(capsys) -> None:
    assert main(["turning", "--example", "paper-expert", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("n_rpm", "feed_mm_rev", "x1", "x2", "speed_m_min", "power_kw", "machine_time_min", "active", "slack"):
        assert key in out
    assert out["x1"] == pytest.approx(6.875) and out["x2"] == pytest.approx(0.3)
    assert out["n_rpm"] == pytest.approx(967.78, rel=1e-3)
    assert set(out["active"]) == {"power", "roughness"}
    assert out["slack"]["s_max"] == pytest.approx(math.log(2) - 0.3)


def test_cli_text_and_overrides(capsys, tmp_path: Path) -> None:
    case = tmp_path / "c.toml"
    case.write_text(example_case_path("paper").read_text(encoding="utf-8"), encoding="utf-8")
    assert main(["turning", str(case), "--set", 'machine.id="16K20"', "--snap"]) == 0
    out = capsys.readouterr().out
    assert "ACTIVE" in out and "On the machine's series" in out
    assert main(["turning", str(case), "--json", "--disable", "roughness"]) == 0
    assert "roughness" in json.loads(capsys.readouterr().out)["disabled"]
    assert main(["turning", "--list"]) == 0
    assert "sch20" in capsys.readouterr().out


def test_cli_bad_input_exit_2(capsys) -> None:
    assert main(["turning", "--example", "paper", "--set", "workpiece.depth_mm=-1"]) == 2
    err = capsys.readouterr().err
    assert "workpiece.depth_mm" in err and "Traceback" not in err
    assert main(["turning", "--example", "nope"]) == 2
    assert main(["turning", "--example", "paper", "--set", "requirements.rz_um=1"]) == 2
    assert "conflicts with" in capsys.readouterr().err


def test_cli_subprocess() -> None:
    exe = Path(sys.executable).with_name("winder")
    out = subprocess.run([str(exe), "turning", "--example", "paper", "--json"], capture_output=True, text=True,
                         check=True)
    data = json.loads(out.stdout)
    assert data["n_rpm"] == pytest.approx(411.38, abs=0.01)


def test_json_of_result_roundtrips() -> None:
    res = optimise(paper_case(), DATA, snap=True)
    js = json.dumps(result_to_json(res), allow_nan=False)
    back = json.loads(js)
    assert [r["name"] for r in back["rows"]] == list(CONSTRAINT_NAMES)  # the rows of the band used
    assert back["feed_band"] == 2 and back["rows"][0]["b"] == pytest.approx(0.4)
