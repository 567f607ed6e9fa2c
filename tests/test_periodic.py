"""Programs whose circuits repeat: the axes stage computed on three circuits and replicated equals the
point-by-point computation (engine.periodic, docs/speed.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.job import build_mandrel, load_job
from engine.payout import REPLICATE_MIN_CIRCUITS, extend_to_line, payout_for_job
from engine.periodic import repeats, replicate_axes, tile_circuits
from engine.pipeline import _axes_stage
from engine.winding import winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "resources" / "examples"


def test_tile_and_repeats_roundtrip() -> None:
    """tile_circuits builds circuit k = circuit 1 + (k-1)·step; repeats recovers the step."""
    m, nc = 5, 7
    rng = np.random.default_rng(1)
    c1 = rng.normal(size=(m, 2))
    step = np.array([2.5, 0.0])
    full = np.concatenate([rng.normal(size=(m, 2))] + [c1 + k * step for k in range(nc - 1)]
                          + [(c1[0] + (nc - 1) * step)[None]])
    head = full[:3 * m + 1]
    assert np.allclose(repeats(head, m), step)
    assert np.allclose(tile_circuits(head, nc, m, step), full, rtol=0, atol=1e-12)
    bad = head.copy()
    bad[2 * m + 2, 1] += 1e-3
    assert repeats(bad, m) is None


def _program(name: str, machine: str | None = None, points: int = 120):
    job = load_job(EX / f"{name}.toml")
    job = job.replace(winding={**job.winding.model_dump(), "circuits": REPLICATE_MIN_CIRCUITS + 3,
                               "points_per_pass": points},
                      payout=job.payout.model_copy(update={"grid_points": 200}))
    if machine is not None:
        job = job.replace(machine={**job.machine.model_dump(), "template": machine})
    path = str(EX / f"{name}.toml")
    mandrel = build_mandrel(job, path)
    line = winding_line_for_job(job, path)
    eye = extend_to_line(payout_for_job(job, line, mandrel), line)
    return job, path, mandrel, line, eye


@pytest.mark.parametrize(("name", "machine"), [("pressure_vessel", None), ("pressure_vessel", "lathe3"),
                                               ("pipe", None)])
def test_replicated_axes_equal_pointwise(name: str, machine: str | None) -> None:
    """The replicated axis path equals the point-by-point inverse kinematics to 1e-9 of each axis' scale,
    with the same machine and placement."""
    job, path, mandrel, line, eye = _program(name, machine)
    assert eye.report.get("replicated_circuits") == line.circuits

    def run(e):  # noqa: ANN001, ANN202
        return _axes_stage(job, path, mandrel, e, None)

    rep = replicate_axes(line, eye, run)
    assert rep is not None, "the program's circuits repeat: the axes stage must be replicated"
    m_ref, ref, pl_ref = run(eye)
    m_rep, axes, pl_rep = rep
    assert m_rep == m_ref
    # the same placement (its carriage range to rounding: the minimum of three circuits vs of all)
    assert (pl_rep.axis, pl_rep.mode, pl_rep.z0, pl_rep.lo, pl_rep.hi) == (pl_ref.axis, pl_ref.mode, pl_ref.z0,
                                                                          pl_ref.lo, pl_ref.hi)
    assert np.allclose([pl_rep.q_min, pl_rep.q_max, *pl_rep.z0_fit], [pl_ref.q_min, pl_ref.q_max, *pl_ref.z0_fit],
                       rtol=1e-12, atol=1e-9)
    assert not ref.violations and not axes.violations
    q, qr = np.asarray(axes.q), np.asarray(ref.q)
    assert q.shape == qr.shape == (line.z.size, len(m_ref.axes))
    scale = 1.0 + np.abs(qr).max(axis=0)
    assert np.all(np.abs(q - qr).max(axis=0) <= 1e-9 * scale), np.abs(q - qr).max(axis=0) / scale
    for f in ("eye_xyz", "fibre_dir", "contact_xyz", "eye_shift", "x"):
        a, b = np.asarray(getattr(axes, f)), np.asarray(getattr(ref, f))
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-9 * (1.0 + np.abs(b).max()), f


def test_not_replicated_when_circuits_differ() -> None:
    """A path whose circuits do not repeat (a perturbed eye) is computed point by point (None)."""
    from dataclasses import replace

    job, path, mandrel, line, eye = _program("pressure_vessel")
    m = line.points_per_circuit
    e = np.array(eye.eye_xyz)
    e[2 * m + m // 2, 2] += 0.5          # circuit 2 differs from circuit 1
    bad = replace(eye, eye_xyz=e)
    assert replicate_axes(line, bad, lambda ep: _axes_stage(job, path, mandrel, ep, None)) is None
    # fewer circuits than the payout replicates: no replication either
    assert replicate_axes(line.take_circuit(0), eye, lambda ep: _axes_stage(job, path, mandrel, ep, None)) is None


def _run_big(monkeypatch: pytest.MonkeyPatch, replicate: bool, circuits: int = 120, points: int = 400):
    import engine.payout
    import engine.periodic
    from engine.pipeline import run_pipeline

    if not replicate:    # every stage computes every point
        monkeypatch.setattr(engine.payout, "REPLICATE_MIN_CIRCUITS", 10**9)
        monkeypatch.setattr(engine.periodic, "replicated_circuits", lambda line, eye: None)
    job = load_job(EX / "pressure_vessel.toml")
    job = job.replace(winding={**job.winding.model_dump(), "circuits": circuits, "points_per_pass": points})
    res = run_pipeline(job, str(EX / "pressure_vessel.toml"))
    monkeypatch.undo()
    return res


def test_replicated_program_equals_materialised(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 120-circuit program computed by circuit replication (payout, axes) and point by point:
    the same block count, the same largest block error (1e-6 relative) and axis ranges, the program
    time to 1e-5 relative (the tube law's DP sees inputs that differ by rounding), no violations in
    either; the NC text has the same number of lines."""
    rep = _run_big(monkeypatch, True)
    ref = _run_big(monkeypatch, False)
    assert rep.eye.report.get("replicated_circuits") == rep.line.circuits == 120
    assert "replicated_circuits" not in ref.eye.report
    assert np.abs(np.asarray(rep.axes.q) - np.asarray(ref.axes.q)).max() <= 1e-9 * (
        1.0 + np.abs(np.asarray(ref.axes.q)).max())
    a, b = rep.report(), ref.report()
    assert a["blocks"] == b["blocks"]
    assert a["program_time_s"] == pytest.approx(b["program_time_s"], rel=1e-5)
    assert a["max_error_mm"] == pytest.approx(b["max_error_mm"], rel=1e-6, abs=1e-9)
    assert a["max_error_mm"] <= rep.job.post.tolerance_mm * (1 + 1e-9)
    for k, (lo, hi) in b["axis_ranges"].items():
        assert a["axis_ranges"][k] == pytest.approx([lo, hi], rel=1e-9, abs=1e-9)
    assert a["violations"] == b["violations"] == []
    assert rep.nc_text.count("\n") == ref.nc_text.count("\n")


def test_block_errors_by_circuit_equal_every_block() -> None:
    """On a replicated axis path the block errors of the middle circuits are circuit 1's, the (17) metric
    summed per block: equal to measuring every block on the whole path's metric (1e-9 mm), for every
    block and for a selection of split blocks."""
    from dataclasses import replace

    from engine.blocks import make_blocks
    from engine.pipeline import _block_errors, _block_pieces, run_pipeline

    path = EX / "pressure_vessel.toml"
    job = load_job(path)
    job = job.replace(winding={**job.winding.model_dump(), "circuits": 104, "points_per_pass": 120},
                      payout={**job.payout.model_dump(), "grid_points": 200})
    res = run_pipeline(job, path, upto="axes")
    assert res.axes.circuits == (104, res.line.points_per_circuit)
    blocks = make_blocks(res.machine, res.axes, tol_mm=0.05, pieces=_block_pieces(res))
    idx = np.asarray(blocks.index)
    # split every block in two, as the time law's jump splitting does
    mids = (idx[:-1] + idx[1:]) // 2
    split = np.unique(np.concatenate([idx, mids]))
    flat = replace(res.axes, circuits=None)
    for ix in (idx, split):
        for sel in (None, np.arange(ix.size - 1) % 3 == 0):
            e_rep = _block_errors(res.machine, res.axes, ix, sel)
            e_ref = _block_errors(res.machine, flat, ix, sel)
            assert e_rep.shape == e_ref.shape == (ix.size - 1,)
            assert np.abs(e_rep - e_ref).max() <= 1e-9
            assert e_ref.max() > 1e-3          # real errors, not all zero


def test_deferred_line_fields_equal_materialised() -> None:
    """A line of >= DEFER_MIN_CIRCUITS circuits keeps its per-point arrays as circuit 0 + rule: every
    field read gives a plain array, circuit slices (take_circuit) are made without materialising and are
    bit for bit the materialised array's rows; circuit k's points are circuit 0's turned by k·Δv (an
    independent rotation) and its length advances by circuit 0's; the summary is the same either way."""
    from dataclasses import replace

    from engine.periodic import DEFER_MIN_CIRCUITS, CircuitArray, deferred
    from engine.winding import PER_POINT_FIELDS

    job = load_job(EX / "pressure_vessel.toml")
    job = job.replace(winding={**job.winding.model_dump(), "circuits": max(DEFER_MIN_CIRCUITS, 60) + 3,
                               "points_per_pass": 100})
    line = winding_line_for_job(job, str(EX / "pressure_vessel.toml"))
    nc, m = line.circuits, line.points_per_circuit
    assert nc > 57
    n = nc * m + 1
    assert all(isinstance(deferred(line, f), CircuitArray) for f in PER_POINT_FIELDS)
    summary = line.summary()
    one = line.take_circuit(nc - 1)
    mid = line.take_circuit(nc // 2)
    assert all(deferred(line, f) is not None for f in PER_POINT_FIELDS)    # nothing materialised yet
    assert summary["points"] == n == line.n_points
    for f in PER_POINT_FIELDS:
        a = getattr(line, f)
        assert isinstance(a, np.ndarray) and a.shape[0] == n and deferred(line, f) is None, f
        assert np.array_equal(getattr(one, f), a[(nc - 1) * m:]), f
        assert np.array_equal(getattr(mid, f), a[(nc // 2) * m:(nc // 2 + 1) * m + 1]), f
        assert a.dtype == getattr(one, f).dtype, f
    assert line.summary() == summary
    # circuit k = circuit 0 turned by k·Δv (rotation by a matrix, independently of CircuitArray)
    k = 57
    ang = k * line.twist_per_circuit_rad
    rot = np.array([[np.cos(ang), -np.sin(ang), 0.0], [np.sin(ang), np.cos(ang), 0.0], [0.0, 0.0, 1.0]])
    c0, ck = line.xyz[:m + 1], line.xyz[k * m:(k + 1) * m + 1]
    assert np.abs(c0 @ rot.T - ck).max() < 1e-9
    assert np.abs(line.s[k * m:(k + 1) * m + 1] - line.s[:m + 1] - k * line.s[m]).max() < 1e-9 * line.s[-1]
    assert np.array_equal(line.z[k * m:(k + 1) * m], line.z[:m]) and np.all(line.circuit[k * m:(k + 1) * m] == k)
    # a plain (materialised) copy of the line gives the same summary
    plain = replace(line)
    assert all(deferred(plain, f) is None for f in PER_POINT_FIELDS)
    assert plain.summary() == summary


@pytest.mark.parametrize("kind", ["tile", "shift", "circuit", "turn"])
def test_circuit_array_rows_take_and_patches_equal_materialised(kind: str) -> None:
    """CircuitArray.rows / take give the materialised array's rows bit for bit, patched rows included;
    against an independent construction (a loop over circuits)."""
    from engine.periodic import CircuitArray

    rng = np.random.default_rng(3)
    nc, m = 6, 7
    ck, sk = np.cos(np.arange(nc) * 0.7), np.sin(np.arange(nc) * 0.7)
    base: object = rng.normal(size=m + 1)
    if kind == "turn":
        base = tuple(rng.normal(size=m + 1) for _ in range(3))
    patch_rows = np.array([3, 0])
    vals = rng.normal(size=(2, 3) if kind == "turn" else 2)
    if kind == "circuit":
        vals = np.array([7, 9])
    ca = CircuitArray(kind, None if kind == "circuit" else base, nc, m, 0.25 if kind == "shift" else 0,
                      cos_k=ck, sin_k=sk, patch_rows=patch_rows, patch_values=vals)
    full = ca.materialise()
    # independent: circuit by circuit
    ref = []
    for k in range(nc):
        for j in range(m):
            if kind == "tile":
                ref.append(base[j])
            elif kind == "shift":
                ref.append(base[j] + k * 0.25)
            elif kind == "circuit":
                ref.append(k)
            else:
                x, y, z = (b[j] for b in base)
                ref.append([x * ck[k] - y * sk[k], x * sk[k] + y * ck[k], z])
    last = {"tile": base[m] if kind == "tile" else None, "shift": None, "circuit": nc - 1}.get(kind)
    if kind == "shift":
        last = base[m] + (nc - 1) * 0.25
    if kind == "turn":
        x, y, z = (b[m] for b in base)
        last = [x * ck[-1] - y * sk[-1], x * sk[-1] + y * ck[-1], z]
    ref = np.array(ref + [last])
    ref[patch_rows] = vals
    assert full.shape == ca.shape and np.allclose(full, ref, rtol=0, atol=1e-14)
    idx = rng.integers(0, ca.n, size=40)
    assert np.array_equal(ca.take(idx), full[idx])
    for a, b in ((0, ca.n), (m - 1, 2 * m + 2), (ca.n - 3, ca.n)):
        assert np.array_equal(ca.rows(a, b), full[a:b])
    assert ca.array() is ca.array() and np.array_equal(ca.array(), full)


@pytest.mark.parametrize("name", ["pipe", "bottle"])
def test_examples_replicated_are_the_same_motion(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped examples (28-74 circuits) are computed as circuit 0 turned (REPLICATE_MIN_CIRCUITS and
    DEFER_MIN_CIRCUITS = 8 since 2026-11-29; 100 before).  Against the point-by-point computation their NC
    programs are the same motion: every line equal once the feed words are set aside (axis words, blocks,
    comments), the program time equal to 1e-5 relative (the time law turns the eye path's ~1e-12 round-off
    into feed words' last digits; docs/speed.md)."""
    import re

    import engine.payout
    import engine.periodic
    from engine.cli import main

    src = EX / f"{name}.toml"
    assert main(["run", str(src), "-o", str(tmp_path / "rep.ngc"), "--quiet", "-j", "1"]) == 0
    monkeypatch.setattr(engine.payout, "REPLICATE_MIN_CIRCUITS", 10**9)
    monkeypatch.setattr(engine.periodic, "DEFER_MIN_CIRCUITS", 10**9)
    assert main(["run", str(src), "-o", str(tmp_path / "pt.ngc"), "--quiet", "-j", "1"]) == 0
    rep, pt = ((tmp_path / f).read_text().splitlines() for f in ("rep.ngc", "pt.ngc"))

    def time_s(lines: list[str]) -> float:
        return float(re.search(r"program time ([0-9.]+) s", "\n".join(lines[:8])).group(1))

    def motion(line: str) -> str:
        return re.sub(r" F[-0-9.]+", "", re.sub(r"[0-9.]+ s\b", "", line))

    assert len(rep) == len(pt) and [motion(a) for a in rep] == [motion(b) for b in pt]
    assert time_s(rep) == pytest.approx(time_s(pt), rel=1e-5)
