"""Pipeline stage times per example and time-law method, and `winder run` wall times.

Run: ``.venv/bin/python benchmarks/bench_pipeline.py [--quick]`` (``--quick``: the vessel only).
Prints, per example: the upstream stage times (mandrel .. axes, shared by every method), then per
method (blocks = (17)/(18), tube, dp, toppra): the blocks and nc stage times, the time-law phases,
the program time and the largest block acceleration ratio; finally `winder run` on the vessel
(default method and tube) as a subprocess, including interpreter start-up.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.job import load_job  # noqa: E402
from engine.pipeline import run_pipeline  # noqa: E402

EXAMPLES = ROOT / "resources" / "examples"
METHODS = ("blocks", "tube", "dp", "toppra")


def bench_example(name: str) -> None:
    path = EXAMPLES / f"{name}.toml"
    job = load_job(path)
    t0 = time.perf_counter()
    base = run_pipeline(job, path, upto="axes")
    up = time.perf_counter() - t0
    st = ", ".join(f"{k} {v:.3f}" for k, v in base.stage_times.items())
    print(f"\n{name}: {base.axes.q.shape[0]} path points, {base.line.circuits} circuits; upstream {up:.2f} s ({st})")
    ref = None
    for method in METHODS:
        j = job.replace(timelaw={**job.timelaw.model_dump(), "method": method})
        t0 = time.perf_counter()
        res = run_pipeline(j, path, previous=base)
        wall = time.perf_counter() - t0
        rep = res.report()
        acc = max(rep["block_accel_ratio"].values())   # the corner steps spread over their blocks
        tl = rep.get("timelaw")
        extra = ""
        if tl:
            ph = tl["phase_s"]
            extra = (f" | law {tl['total_time_s']:.2f} s, nodes {tl['nodes']}, iterations {tl['iterations']}, "
                     f"phases nodes {ph['nodes']:.2f} / laws {ph['laws']:.2f} / blocks {ph['blocks']:.2f} s, "
                     f"split {tl['blocks_split']}, at (17) time {tl['blocks_at_min_time']}, "
                     f"time added {tl['time_added_s']:.2f} s, law accel ratio {tl['max_accel_ratio']:.3f}")
        ref = rep["program_time_s"] if method == "blocks" else ref
        ratio = rep["program_time_s"] / ref if ref else float("nan")
        print(f"  {method:7s} blocks {res.stage_times['blocks']:.2f} s, nc {res.stage_times['nc']:.2f} s "
              f"(wall {wall:.2f}) -> {rep['blocks']} blocks, program {rep['program_time_s']:.1f} s "
              f"({ratio:.3f} x (18)), max block accel ratio {acc:.2f}, violations {len(res.violations)}{extra}")


def bench_cli() -> None:
    winder = ROOT / ".venv" / "bin" / "winder"
    src = (EXAMPLES / "pressure_vessel.toml").read_text()
    with tempfile.TemporaryDirectory() as d:
        tube = Path(d) / "vessel_tube.toml"
        tube.write_text(src + '\n[timelaw]\nmethod = "tube"\n')
        for label, job in (("default (blocks)", EXAMPLES / "pressure_vessel.toml"), ("tube", tube)):
            t0 = time.perf_counter()
            proc = subprocess.run([str(winder), "run", str(job), "-o", str(Path(d) / "v.ngc")],
                                  capture_output=True, text=True, env={**os.environ, "COLUMNS": "120"})
            wall = time.perf_counter() - t0
            stages = [ln for ln in proc.stderr.splitlines() if ln.startswith("stages:")]
            print(f"winder run pressure_vessel, {label}: {wall:.2f} s wall (exit {proc.returncode}); "
                  f"{stages[0] if stages else proc.stderr[-300:]}")


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    names = ["pressure_vessel"] if "--quick" in sys.argv else ["pipe", "pressure_vessel", "bottle"]
    for name in names:
        bench_example(name)
    print()
    bench_cli()


if __name__ == "__main__":
    main()
