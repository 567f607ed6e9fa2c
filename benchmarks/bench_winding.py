"""Benchmark of the winding-line engine (a plain script, not a test).

Run: ``.venv/bin/python benchmarks/bench_winding.py``.  Prints wall times (best of several runs)
for a 100-circuit pattern on the example pressure vessel (isotensoid domes, unequal poles:
constant-λ shooting) at 2000 points a pass, and the ratio to the 0.5 s target.
"""

from __future__ import annotations

import time
from pathlib import Path

from engine.job import WindingSpec, build_mandrel, load_job
from engine.winding import winding_line

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 0.5


def _best(fn, repeat: int = 5) -> tuple[float, object]:
    best = float("inf")
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    job = load_job(ROOT / "resources/examples/pressure_vessel.toml")
    spec = WindingSpec(points_per_pass=2000, circuits=100)
    t_mandrel, mandrel = _best(lambda: build_mandrel(job))
    t_all, line = _best(lambda: winding_line(build_mandrel(job), job.band.width_mm, job.band.friction, spec))
    print(f"mandrel build                      : {t_mandrel * 1e3:8.1f} ms")
    print(f"winding line, 100 circuits (total) : {t_all * 1e3:8.1f} ms   "
          f"target {TARGET_S * 1e3:.0f} ms, ratio {t_all / TARGET_S:.2f}")
    print(f"  points {len(line.z)}, per circuit {line.points_per_circuit}, mode {line.mode}, "
          f"lambda {line.max_abs_lambda:.6f}, p/q {line.pattern_p}/{line.pattern_q}")
    for name, spec2 in (
        ("geodesic (pole C = 44 mm)", WindingSpec(mode="geodesic", points_per_pass=2000, circuits=100)),
        ("constant-lambda", WindingSpec(mode="constant-lambda", points_per_pass=2000, circuits=100)),
    ):
        t, ln = _best(lambda s=spec2: winding_line(mandrel, job.band.width_mm, job.band.friction, s))
        print(f"{name:35s}: {t * 1e3:8.1f} ms   ratio {t / TARGET_S:.2f}  ({len(ln.z)} points)")
    bottle = load_job(ROOT / "resources/examples/bottle.toml")
    t, ln = _best(lambda: winding_line(build_mandrel(bottle), bottle.band.width_mm, bottle.band.friction,
                                       bottle.winding), repeat=3)
    print(f"{'bottle example (auto/minimax)':35s}: {t * 1e3:8.1f} ms   ({ln.circuits} circuits)")


if __name__ == "__main__":
    main()
