"""Issue 16, targets 2 and 3: whole programs and start-up.

Run: ``.venv/bin/python benchmarks/bench_program_scale.py [--quick | --big]``

1. Start-up: ``winder --version``, ``winder run`` of the pipe and of the pressure vessel (subprocesses,
   the interpreter start included; medians of 5, runs interleaved).  Targets 0.15 s, 1 s, 1.5 s.
2. Scaling: the pressure vessel's whole pipeline (default time law) with the points per pass doubling
   at 20 circuits, and the circuits doubling at 2 000 points per pass; wall time and peak RSS of each
   run in a fresh process, and the fitted exponents ``cost ∝ size^k`` (least squares on log-log).
   Targets: k <= 1 in points per pass, k < 1 in circuits.
3. The big job: 400 circuits x 8 000 points per pass (6.5 M path points): wall and peak RSS.
   Targets 12 s and 1.2 GB; wall, CPU and peak RSS per stage.  (``--quick`` skips it and halves the
   scaling runs; ``--big`` runs it alone.)

Every figure is printed as wall time and CPU time (user + system of the process; the machine may be
shared, which inflates wall time) with the load average when it was taken.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "resources" / "examples"

_RUN = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from engine.job import load_job
from engine.pipeline import run_pipeline
path, circuits, points = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
job = load_job(path)
job = job.replace(winding={**job.winding.model_dump(), "circuits": circuits, "points_per_pass": points})
STAGES = ("mandrel", "winding", "payout", "axes", "blocks", "nc")
cpu_at = {}
class Clock:  # CPU time and peak RSS when each stage is done (the pipeline reports "<stage> done")
    def progress(self, fraction, message=""):
        name = message[:-5] if message.endswith(" done") else None
        if name in STAGES:
            cpu_at[name] = (time.process_time(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    def cancelled(self):
        return False
    def partial(self, result):
        pass
t1 = time.perf_counter()
c1 = time.process_time()
res = run_pipeline(job, path, state=Clock())
t2 = time.perf_counter()
c2 = time.process_time()
prev, stage_cpu, stage_rss = c1, {}, {}
for k in STAGES:
    if k in cpu_at:
        stage_cpu[k], stage_rss[k] = cpu_at[k][0] - prev, cpu_at[k][1]
        prev = cpu_at[k][0]
print(json.dumps({"wall": t2 - t1, "cpu": c2 - c1, "imports": t1 - t0, "stages": res.stage_times,
                  "stage_cpu": stage_cpu, "stage_peak_mb": stage_rss,
                  "points": int(res.line.n_points), "blocks": int(res.blocks.index.size - 1),
                  "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "WINDER_MAX_MEMORY": "64G", "COLUMNS": "120"}


def run_job(circuits: int, points: int, name: str = "pressure_vessel") -> dict:
    out = subprocess.run([sys.executable, "-c", _RUN, str(EX / f"{name}.toml"), str(circuits), str(points)],
                         capture_output=True, text=True, env=_env(), cwd=ROOT)
    if out.returncode:
        raise SystemExit(out.stderr[-2000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def fit_exponent(x: list[float], y: list[float]) -> float:
    lx, ly = [math.log(v) for v in x], [math.log(v) for v in y]
    mx, my = statistics.fmean(lx), statistics.fmean(ly)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / sum((a - mx) ** 2 for a in lx)


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def startup(rep: int) -> tuple[dict[str, float], dict[str, float]]:
    cmds = {
        "winder --version": [sys.executable, "-m", "engine", "--version"],
        "winder run pipe": None,
        "winder run pressure_vessel": None,
    }
    times: dict[str, list[float]] = {k: [] for k in cmds}
    cpus: dict[str, list[float]] = {k: [] for k in cmds}
    with tempfile.TemporaryDirectory() as d:
        cmds["winder run pipe"] = [sys.executable, "-m", "engine", "run", str(EX / "pipe.toml"), "-o",
                                   str(Path(d) / "p.ngc"), "--quiet"]
        cmds["winder run pressure_vessel"] = [sys.executable, "-m", "engine", "run", str(EX / "pressure_vessel.toml"),
                                              "-o", str(Path(d) / "v.ngc"), "--quiet"]
        for _ in range(rep):
            for k, cmd in cmds.items():
                t0, c0 = time.perf_counter(), _children_cpu()
                subprocess.run(cmd, capture_output=True, env=_env(), cwd=ROOT, check=False)
                times[k].append(time.perf_counter() - t0)
                cpus[k].append(_children_cpu() - c0)
    return ({k: statistics.median(v) for k, v in times.items()}, {k: statistics.median(v) for k, v in cpus.items()})


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--big", action="store_true", help="the 400 x 8 000 job only")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if args.big:
        big_job()
        return 0
    st, st_cpu = startup(3 if args.quick else 5)
    targets = {"winder --version": 0.15, "winder run pipe": 1.0, "winder run pressure_vessel": 1.5}
    print(f"start-up (subprocess wall and CPU, median; load average {os.getloadavg()[0]:.2f}):")
    for k, v in st.items():
        c = st_cpu[k]
        print(f"  {k:<28} wall {v:6.3f} s (ratio {v / targets[k]:.2f})  CPU {c:6.3f} s (ratio {c / targets[k]:.2f})"
              f"  target {targets[k]:.2f} s -> wall {'PASS' if v <= targets[k] else 'FAIL'}, "
              f"CPU {'PASS' if c <= targets[k] else 'FAIL'}")

    pts = [1000, 2000, 4000] if args.quick else [1000, 2000, 4000, 8000]
    circ = [10, 20, 40] if args.quick else [25, 50, 100, 200]
    print("\nscaling, pressure vessel, whole pipeline in a fresh process:")
    rows = {}
    for label, series in (("points per pass (20 circuits)", [(20, p) for p in pts]),
                          ("circuits (2000 points per pass)", [(c, 2000) for c in circ])):
        walls, cpus, rss, sizes = [], [], [], []
        print(f"  {label}:")
        for c, p in series:
            r = run_job(c, p)
            sizes.append(p if label.startswith("points") else c)
            walls.append(r["wall"])
            cpus.append(r["cpu"])
            rss.append(r["rss_mb"])
            stg = ", ".join(f"{k} {v:.2f}" for k, v in r["stages"].items())
            print(f"    {c:4d} x {p:5d}: {r['points']:8d} points, wall {r['wall']:6.2f} s, CPU {r['cpu']:6.2f} s, "
                  f"{r['rss_mb']:6.0f} MB ({stg})")
        k_t, k_c, k_m = fit_exponent(sizes, walls), fit_exponent(sizes, cpus), fit_exponent(sizes, rss)
        rows[label] = (k_c, k_m)
        print(f"    fitted exponent: wall k = {k_t:.2f}, CPU k = {k_c:.2f}, peak RSS k = {k_m:.2f}")
    kp, kc = rows["points per pass (20 circuits)"][0], rows["circuits (2000 points per pass)"][0]
    print(f"  target: CPU time linear in points per pass (k <= 1.0): k = {kp:.2f} -> "
          f"{'PASS' if kp <= 1.05 else 'FAIL'}")
    print(f"  target: CPU time sub-linear in circuits (k < 1.0): k = {kc:.2f} -> {'PASS' if kc < 1.0 else 'FAIL'}")
    if not args.quick:
        big_job()
    return 0


def big_job() -> None:
    """The 400 x 8 000 job in a fresh process: wall, CPU and peak RSS, per stage and in all."""
    load0 = os.getloadavg()[0]
    r = run_job(400, 8000)
    print(f"\nbig job 400 circuits x 8000 points per pass: {r['points']} points, {r['blocks']} blocks; "
          f"wall {r['wall']:.1f} s, CPU {r['cpu']:.1f} s, peak RSS {r['rss_mb']:.0f} MB; "
          f"load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after")
    print("  per stage: wall / CPU s, peak RSS so far MB")
    for k, v in r["stages"].items():
        print(f"    {k:<8} {v:6.2f} / {r['stage_cpu'].get(k, float('nan')):6.2f}   "
              f"{r['stage_peak_mb'].get(k, float('nan')):6.0f}")
    print(f"  target <= 12 s: wall ratio {r['wall'] / 12:.2f} -> {'PASS' if r['wall'] <= 12 else 'FAIL'}; "
          f"CPU ratio {r['cpu'] / 12:.2f} -> {'PASS' if r['cpu'] <= 12 else 'FAIL'}")
    print(f"  target peak RSS <= 1.2 GB: ratio {r['rss_mb'] / 1228.8:.2f} -> "
          f"{'PASS' if r['rss_mb'] <= 1228.8 else 'FAIL'}")


if __name__ == "__main__":
    sys.exit(main())
