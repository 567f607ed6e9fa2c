"""Issue 16, target 2 on other jobs: 400 circuits x 8 000 points per pass, not only the vessel's line.

Run: ``.venv/bin/python benchmarks/bench_big_variety.py [--case NAME ...] [--list]``

The target ("400 circuits x 8 000 points per pass in <= 12 s wall and <= 1.2 GB peak RSS") was measured
on one job (``bench_program_scale.py --big``: the pressure vessel's line through ``run_pipeline``).  An
independent check will run other jobs, most likely through ``winder run``; this benchmark runs a set of
them, each in a fresh process, one after the other (never side by side: the machine is shared):

a. ``vessel-pipeline``: the vessel's ``[winding]`` line through ``engine.pipeline.run_pipeline`` (the
   measured case; no NC file written).
b. ``vessel-helical``: ``winder run`` of a v2 job with one helical layer (40 deg, closed by angle) whose
   ``circuits`` / ``points_per_pass`` are the layer's own (the laminate path, its pipeline forked).
c. ``pipe-helical``: the pipe example's helical layer (55 deg, turns on pins beyond the ends, 180 deg
   dwells, min-range payout).
d. ``bottle-helical``: the bottle example's helical layer (minimax line on the waisted neck).
d2. ``bottle-csv``: the same on the bottle's generatrix imported from ``bottle_profile.csv``.
e. ``vessel-polar``: a polar layer on the vessel.
f. ``vessel-nongeodesic``: a non-geodesic helical layer on the vessel (``mode = "constant-lambda"``).
g. ``vessel-laminate``: a 2-layer laminate, hoop + helical 400 x 8 000, through ``winder run``.
h. ``vessel-example``: the shipped vessel (polar, 2 hoops, helical, hoop) with ``[winding] circuits = 400``,
   ``points_per_pass = 8000``: two heavy layers of 6.4 M points each, wound side by side (``--force``: its
   helical layer, closed by dwell as p = 400 cannot be closed by angle, slips on the dwell parallels).

Every case runs with the *default* memory budget (``WINDER_MAX_MEMORY`` unset): a job the target names
must not be refused; if a ``winder run`` is, that is printed and the case runs again with
``WINDER_MAX_MEMORY=64G``.  Printed per case: wall (the whole command, interpreter start and NC file
included), CPU (user + system of the process and of its children: ``winder run`` forks one worker per
heavy layer), peak RSS of the process and of its largest child (``ru_maxrss``), and the ratios to the
targets 12 s and 1.2 GB (1228.8 MB); ``!`` marks a figure over its target, ``~`` one within 10 % of it;
and the memory budget's estimate of the job (``engine.budget``), which must bound the peak.

``--cold-numba`` runs each case with an empty numba cache: a first run after installing without
``make venv`` (which compiles the time law's kernels) pays ~7 s more CPU compiling them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import tomli_w

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "resources" / "examples"
CIRCUITS, POINTS = 400, 8000
WALL_TARGET_S, RSS_TARGET_MB = 12.0, 1228.8

# The measuring wrapper: runs `winder ARGS...` (or run_pipeline) in this fresh process and writes its own
# and its children's resource use to the JSON file argv[1].
_WRAP = r"""
import json, resource, sys, time
t0 = time.perf_counter()
out, mode, args = sys.argv[1], sys.argv[2], sys.argv[3:]
extra = {}
if mode == "cli":
    from engine.cli import main
    rc = main(args)
else:
    from engine.job import load_job
    from engine.pipeline import run_pipeline
    job = load_job(args[0])
    job = job.replace(winding={**job.winding.model_dump(), "circuits": int(args[1]), "points_per_pass": int(args[2])})
    res = run_pipeline(job, args[0])
    extra = {"stages": {k: float(v) for k, v in res.stage_times.items()}, "points": int(res.line.n_points)}
    rc = 0
t1 = time.perf_counter()
s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
with open(out, "w") as f:
    json.dump({"rc": rc, "wall_inside": t1 - t0, "cpu_self": s.ru_utime + s.ru_stime,
               "cpu_children": c.ru_utime + c.ru_stime, "rss_self_mb": s.ru_maxrss / 1024,
               "rss_children_mb": c.ru_maxrss / 1024, **extra}, f)
sys.exit(rc)
"""


def _example(name: str) -> dict[str, Any]:
    return tomllib.loads((EX / f"{name}.toml").read_text(encoding="utf-8"))


def _big(layer: dict[str, Any]) -> dict[str, Any]:
    return {**layer, "circuits": CIRCUITS, "points_per_pass": POINTS}


def _layers(doc: dict[str, Any], *names: str) -> list[dict[str, Any]]:
    by_name = {lay.get("name"): lay for lay in doc["layer"]}
    return [dict(by_name[n]) for n in names]


def job_vessel_helical() -> dict[str, Any]:
    doc = _example("pressure_vessel")
    doc["layer"] = [_big(lay) for lay in _layers(doc, "helical 40")]
    return doc


def job_pipe_helical() -> dict[str, Any]:
    doc = _example("pipe")
    doc["layer"] = [_big(lay) for lay in _layers(doc, "helical 55")]
    return doc


def job_bottle_helical() -> dict[str, Any]:
    doc = _example("bottle")
    doc["layer"] = [_big(lay) for lay in _layers(doc, "helical")]
    return doc


def job_bottle_csv() -> dict[str, Any]:
    doc = job_bottle_helical()
    doc["mandrel"] = {"kind": "file", "path": str(EX / "bottle_profile.csv")}
    return doc


def job_vessel_polar() -> dict[str, Any]:
    doc = _example("pressure_vessel")
    doc["layer"] = [_big(lay) for lay in _layers(doc, "polar")]
    return doc


def job_vessel_nongeodesic() -> dict[str, Any]:
    doc = _example("pressure_vessel")
    doc["layer"] = [_big({"kind": "helical", "name": "non-geodesic", "mode": "constant-lambda"})]
    return doc


def job_vessel_laminate() -> dict[str, Any]:
    doc = _example("pressure_vessel")
    hoop, hel = _layers(doc, "hoop 1", "helical 40")
    doc["layer"] = [hoop, _big(hel)]
    return doc


def job_vessel_example() -> dict[str, Any]:
    doc = _example("pressure_vessel")
    doc["winding"] = {**doc["winding"], "circuits": CIRCUITS, "points_per_pass": POINTS}
    for lay in doc["layer"]:
        lay.pop("close_by", None)   # p = 400 cannot be closed by a small change of the angle: by dwell
    return doc


CASES: dict[str, tuple[str, Callable[[], dict[str, Any]] | None]] = {
    "vessel-pipeline": ("(a) vessel [winding] line, run_pipeline", None),
    "vessel-helical": ("(b) vessel helical 40, winder run", job_vessel_helical),
    "pipe-helical": ("(c) pipe helical 55 on pins, winder run", job_pipe_helical),
    "bottle-helical": ("(d) bottle helical (minimax), winder run", job_bottle_helical),
    "bottle-csv": ("(d2) bottle from CSV profile, winder run", job_bottle_csv),
    "vessel-polar": ("(e) vessel polar, winder run", job_vessel_polar),
    "vessel-nongeodesic": ("(f) vessel constant-lambda, winder run", job_vessel_nongeodesic),
    "vessel-laminate": ("(g) vessel hoop + helical, winder run", job_vessel_laminate),
    "vessel-example": ("(h) vessel example, [winding] 400 x 8000", job_vessel_example),
}
# (h): every layer of the shipped vessel at 400 x 8 000 (polar and helical: 12.9 M points); its helical layer,
# closed by dwell, slips on the dwell parallels (a limit the run reports, exit 1): --force writes it anyway
FORCE = {"vessel-example"}


COLD_NUMBA = False


def _run(mode: str, args: list[str], budget: str | None, d: Path) -> dict[str, Any]:
    env = {k: v for k, v in os.environ.items() if k != "WINDER_MAX_MEMORY"}
    env.update({"PYTHONPATH": str(ROOT), "COLUMNS": "120"})
    if COLD_NUMBA:  # an empty numba cache: the first run after installing without `make venv`'s warm-up
        cache = d / f"numba-cache-{time.monotonic_ns()}"
        env["NUMBA_CACHE_DIR"] = str(cache)
    if budget is not None:
        env["WINDER_MAX_MEMORY"] = budget
    js = d / "usage.json"
    js.unlink(missing_ok=True)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", _WRAP, str(js), mode, *args], capture_output=True, text=True,
                         env=env, cwd=ROOT, check=False)
    wall = time.perf_counter() - t0
    r: dict[str, Any] = json.loads(js.read_text()) if js.exists() else {"rc": out.returncode}
    r.update(wall=wall, stderr=out.stderr, returncode=out.returncode, budget=budget)
    return r


def budget_estimate_mb(name: str, job_path: Path) -> float:
    """The memory budget's estimate of the job (engine.budget, MB): an upper bound of its peak RSS."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from engine import budget
    from engine.job import build_mandrel, load_job

    job = load_job(job_path)
    if name == "vessel-pipeline":
        job = job.replace(winding={**job.winding.model_dump(), "circuits": CIRCUITS, "points_per_pass": POINTS})
    mandrel = build_mandrel(job, job_path)
    budget.set_max_memory(2**45)
    try:
        if name == "vessel-pipeline":
            est = budget.check_winding_spec(job.winding, float(mandrel.r_max), job.band.width_mm,
                                            job.band.thickness_mm)
        else:
            est = budget.check_laminate(job, mandrel)
    finally:
        budget.set_max_memory(None)
    return est.bytes / 2**20


def run_case(name: str, d: Path) -> dict[str, Any]:
    """One case in a fresh process; a ``winder run`` case first with the default memory budget."""
    _label, make = CASES[name]
    if make is None:
        return {**_run("pipeline", [str(EX / "pressure_vessel.toml"), str(CIRCUITS), str(POINTS)], None, d),
                "refused": None, "estimate_mb": budget_estimate_mb(name, EX / "pressure_vessel.toml")}
    job = d / f"{name}.toml"
    job.write_text(tomli_w.dumps(make()), encoding="utf-8")
    estimate = budget_estimate_mb(name, job)
    args = ["run", str(job), "-o", str(d / f"{name}.ngc"), "--quiet", "--report", str(d / f"{name}.json")]
    if name in FORCE:
        args.append("--force")
    r = _run("cli", args, None, d)
    refused = None
    if r["returncode"] == 2 and "memory budget" in r["stderr"]:
        refused = r["stderr"].strip().splitlines()[-1]
        r = _run("cli", args, "64G", d)
    r["refused"] = refused
    r["estimate_mb"] = estimate
    rep = d / f"{name}.json"
    if rep.exists():
        data = json.loads(rep.read_text())
        r["stages"] = data.get("stage_times_s", {})
        r["blocks"] = data.get("blocks")
        r["program_time_s"] = data.get("program_time_s")
        rep.unlink()
    (d / f"{name}.ngc").unlink(missing_ok=True)
    return r


def _mark(ratio: float) -> str:
    return "!" if ratio > 1.0 else "~" if ratio > 0.9 else " "


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", action="append", choices=list(CASES), help="run only these cases (repeatable)")
    ap.add_argument("--list", action="store_true", help="list the cases and stop")
    ap.add_argument("--keep", metavar="DIR", help="write the job files to DIR and keep them")
    ap.add_argument("--cold-numba", action="store_true",
                    help="each run with an empty numba cache (the time law's kernels compiled in the run)")
    args = ap.parse_args()
    global COLD_NUMBA
    COLD_NUMBA = args.cold_numba
    if args.list:
        for k, (label, _m) in CASES.items():
            print(f"{k:<20} {label}")
        return 0
    names = args.case or list(CASES)
    print(f"big jobs, {CIRCUITS} circuits x {POINTS} points per pass; load average {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores; targets {WALL_TARGET_S:g} s wall, {RSS_TARGET_MB:g} MB peak RSS")
    rows = []
    fails = 0
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(args.keep) if args.keep else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        for name in names:
            load = os.getloadavg()[0]
            r = run_case(name, d)
            r["load"] = load
            rows.append((name, r))
            if r.get("refused"):
                print(f"  {name}: REFUSED by the default memory budget: {r['refused']}")
            if r["returncode"] not in (0,):
                print(f"  {name}: exit {r['returncode']}: {r['stderr'].strip()[-600:]}")
            stg = ", ".join(f"{k} {v:.2f}" for k, v in (r.get("stages") or {}).items())
            print(f"  {name}: stages {stg}", flush=True)
    print(f"\n{'case':<44} {'wall s':>7} {'CPU s':>7} {'RSS MB':>7} {'child MB':>8} {'wall/12s':>9} "
          f"{'RSS/1.2GB':>9} {'est. MB':>8} {'RSS/est':>7}  load  budget")
    for name, r in rows:
        cpu = r.get("cpu_self", float("nan")) + r.get("cpu_children", 0.0)
        rss = max(r.get("rss_self_mb", float("nan")), r.get("rss_children_mb", 0.0))
        child = r.get("rss_children_mb", float("nan"))
        rw, rm = r["wall"] / WALL_TARGET_S, rss / RSS_TARGET_MB
        bad = r["returncode"] != 0 or rw > 1.0 or rm > 1.0 or bool(r.get("refused"))
        fails += bad
        budget = "REFUSED" if r.get("refused") else ("default" if r["budget"] is None else r["budget"])
        print(f"{CASES[name][0]:<44} {r['wall']:7.2f} {cpu:7.2f} {r.get('rss_self_mb', float('nan')):7.0f} "
              f"{child:8.0f} {rw:8.2f}{_mark(rw)} {rm:8.2f}{_mark(rm)} {r['estimate_mb']:8.0f} "
              f"{rss / r['estimate_mb']:7.2f}  {r['load']:4.2f}  {budget}"
              + ("" if r["returncode"] == 0 else f"  exit {r['returncode']}"))
    print(f"\n{len(rows) - fails} of {len(rows)} cases within both targets "
          "(RSS ratio: the larger of the process' and its largest child's peak)")
    over = [name for name, r in rows if max(r.get("rss_self_mb", 0.0), r.get("rss_children_mb", 0.0))
            > r["estimate_mb"]]
    print("the memory budget's estimate (engine.budget) bounds every peak" if not over else
          f"the memory budget's estimate is BELOW the peak of: {', '.join(over)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
