"""Payout stage benchmark: laws side by side on the example vessel, and the (13)–(15) solve times.

Run: ``.venv/bin/python benchmarks/bench_payout.py [--points 1000 4000] [--solver fast highs] [--qp-time-limit 60]``.
Prints, for k = 0 and k = 1, the pull-speed band of every law (the min-range law must have the
smallest range) and the wall time of each technological problem at the given grid sizes, for the
fast path (interval propagation + interior-point QP, the default) and/or the HiGHS formulations
(the reference; ``--solver highs``), with the optimum values so the two can be compared.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import engine.payout as P
from engine.job import build_mandrel, load_job
from engine.winding import winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "resources" / "examples" / "pressure_vessel.toml"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, nargs="*", default=[1000, 4000])
    ap.add_argument("--compare-points", type=int, default=1000)
    ap.add_argument("--qp-time-limit", type=float, default=60.0)
    ap.add_argument("--solver", nargs="*", default=["fast"], choices=["fast", "highs"])
    ap.add_argument("--repeat", type=int, default=1, help="runs per timing; the median is printed")
    args = ap.parse_args()
    P._QP_TIME_LIMIT = args.qp_time_limit
    job = load_job(JOB)
    mandrel = build_mandrel(job, JOB)
    t0 = time.perf_counter()
    line = winding_line_for_job(job, JOB)
    circ = line.one_circuit
    print(f"{job.name}: winding line {line.z.size} points, {line.circuits} circuits "
          f"({time.perf_counter() - t0:.2f} s); one circuit {circ.z.size} points, s = {circ.s[-1]:.1f} mm")
    z0, z1 = mandrel.z_min, mandrel.z_max
    curve = [(z0 - 150.0, 60.0), (z0, 150.0), (z1, 150.0), (z1 + 150.0, 60.0)]
    print(f"\nLaws side by side ({args.compare_points} grid points, x = s, u dimensionless, U = 1):")
    print(f"{'law':<14} {'k':>2} {'u_min':>9} {'u_max':>9} {'range':>9} {'jerk':>10} {'l_min':>7} {'l_max':>7}  ok")
    for k in (0, 1):
        spec = job.payout.model_copy(update={"impregnation_k": k, "grid_points": args.compare_points,
                                             "curve_zr_mm": curve})
        ranges = {}
        for law in P.LAWS:
            e = P.payout_law(circ, mandrel, spec, law=law)
            r = e.report
            ranges[law] = r["u_range"]
            bad = [n for n, c in r["constraints"].items() if not c["ok"]]
            print(f"{law:<14} {k:>2} {r['u_min']:9.4f} {r['u_max']:9.4f} {r['u_range']:9.4f} {r['jerk']:10.3f} "
                  f"{r['l_min']:7.1f} {r['l_max']:7.1f}  {'yes' if r['feasible'] else 'NO: ' + ','.join(bad)}")
        best = min(v for kk, v in ranges.items() if kk != "min-range")
        print(f"   min-range range / best geometric range = {ranges['min-range'] / best:.3f}"
              if best > 1e-12 else f"   min-range range {ranges['min-range']:.2e} (a geometric law is already flat)")
    print("\nTechnological problems (13), (14), (15): wall time in s")
    print(f"{'points':>6} {'k':>2} {'solver':>6} {'(13)':>7} {'(14)':>7} {'(15)':>7} {'total':>7} "
          f"{'u_min (13)':>13} {'u_max (14)':>13} {'jerk (15)':>13}  iterations / qp backend")
    totals: dict[tuple[int, int, str], float] = {}
    for n in args.points:
        for k in (0, 1):
            for solver in args.solver:
                spec = job.payout.model_copy(update={"impregnation_k": k, "grid_points": n})
                runs = [P.min_range_law(circ, mandrel, spec, solver=solver) for _ in range(max(1, args.repeat))]
                e = runs[0]
                sv = e.report["solver"]
                s = {key: statistics.median(r.report["solver"]["seconds"][key] for r in runs)
                     for key in ("13", "14", "15", "total")}
                totals[(n, k, solver)] = s["total"]
                fb = f" fallback {sv['fallback']}" if sv.get("fallback") else ""
                print(f"{e.x.size:6d} {k:>2} {solver:>6} {s['13']:7.3f} {s['14']:7.3f} {s['15']:7.3f} "
                      f"{s['total']:7.3f} {sv['u_min_13']:13.9f} {sv['u_max_14']:13.9f} {sv['jerk_15']:13.6f}  "
                      f"{sv['iterations']} {sv['qp']}{fb}  feasible {e.report['feasible']}")
    for n in args.points:
        for k in (0, 1):
            if (n, k, "fast") in totals and (n, k, "highs") in totals:
                print(f"speed-up {n} points k = {k}: HiGHS / fast = "
                      f"{totals[(n, k, 'highs')] / max(totals[(n, k, 'fast')], 1e-9):.1f}x")
    print(f"\ntarget: (13)+(14)+(15) at 4000 points under 1 s together (times: median of {max(1, args.repeat)})")
    print("\nCancel latency: longest time between two cancellation polls of the whole payout stage")
    print("(min_range_law on the job's first circuit: envelope + (13)–(15); start and end count as polls)")
    for n in dict.fromkeys([job.payout.grid_points, *args.points]):
        for solver in args.solver:
            spec_n = job.payout.model_copy(update={"grid_points": n})
            st = PollTimer()
            t0 = time.perf_counter()
            P.min_range_law(circ, mandrel, spec_n, state=st, solver=solver)
            st.stamp()
            gaps = [b - a for a, b in zip([t0, *st.times], st.times)]
            worst = max(gaps)
            where = st.messages[gaps.index(worst)]
            print(f"{n:6d} points {solver:>5}: {len(st.times) - 1:5d} polls in {st.times[-1] - t0:6.3f} s, "
                  f"max gap {worst * 1e3:7.1f} ms (ending in phase {where!r})")
    print("target: well under 500 ms")


class PollTimer:
    """A job state that time-stamps every cancellation poll (and never cancels)."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.messages: list[str] = []
        self._msg = "start"

    def stamp(self) -> None:
        self.times.append(time.perf_counter())
        self.messages.append(self._msg)

    def progress(self, fraction: float, message: str = "") -> None:
        self._msg = message

    def cancelled(self) -> bool:
        self.stamp()
        return False

    def partial(self, result: object) -> None:
        pass


if __name__ == "__main__":
    main()
