"""Issue 16, target 1: the tube time law against TOPP-RA at any node density.

Run: ``.venv/bin/python benchmarks/bench_timelaw_scale.py [--quick]``

The paper's 7-axis example path (engine.timeparam_example, limits of Tables 4-5, M = 100) resampled to
N = 893 (the paper), 3 000, 10 000, 30 000 nodes, and the same path continued 30x as long at the paper's
node spacing (N = 26 761).  Per case, TOPP-RA and the tube run alternately (interleaved, the machine is
shared), ``--repeat`` times each; printed: the medians of the solve times, the traversal times and
their ratios, the tube's iterations and node grouping, and the worst acceleration ratio inside the
intervals.  Targets: time <= 1.005 x TOPP-RA, no run at the iteration cap, compute <= 1.0 x TOPP-RA.
numba is imported and the compiled passes are warmed up first (as in a long-running process).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.timeparam import parametrize  # noqa: E402
from engine.timeparam_example import N_PAPER, S_N_PAPER, example_limits, example_path  # noqa: E402


def cases(quick: bool) -> list[tuple[str, tuple]]:
    out = [(f"N = {n}", (n,)) for n in (N_PAPER, 3000, 10000, 30000)]
    long_n = (N_PAPER - 1) * 30 + 1
    out.append((f"30x longer, N = {long_n}", (long_n, 30 * S_N_PAPER, S_N_PAPER)))
    return out[:2] if quick else out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="two cases, two repeats")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rep = 2 if args.quick else args.repeat
    lim = replace(example_limits(), levels=100)
    try:
        import numba  # noqa: F401  - a long-running process has it loaded; the passes compile once
    except ImportError:
        print("numba missing: the numpy passes run")
    s, X, dX, ddX = example_path(300)
    parametrize(s, X, dX, ddX, lim, method="toppra")
    parametrize(*example_path(3000), lim)                 # warm-up: compiles/loads the kernels
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; M = {lim.levels}; "
          f"medians of {rep} interleaved runs")
    print(f"{'case':<26}{'TOPP-RA s':>10}{'tube s':>9}{'ratio':>9}{'TOPP-RA cpu':>12}{'tube cpu':>10}"
          f"{'ratio':>7}{'iters':>6}{'group':>6}{'a/A':>10}")
    worst_t, worst_c, capped = 0.0, 0.0, False
    for name, args_ in cases(args.quick):
        s, X, dX, ddX = example_path(*args_)
        tr, tt, laws = [], [], {}
        for _ in range(rep):
            for method, acc in (("toppra", tr), ("tube", tt)):
                t0 = time.process_time()
                laws[method] = parametrize(s, X, dX, ddX, lim, method=method)
                acc.append(time.process_time() - t0)
        ref, law = laws["toppra"], laws["tube"]
        ratio_t = law.total_time_s / ref.total_time_s
        ratio_c = statistics.median(tt) / statistics.median(tr)
        its = len(law.iterations)
        capped |= its >= lim.max_iterations
        worst_t, worst_c = max(worst_t, ratio_t), max(worst_c, ratio_c)
        print(f"{name:<26}{ref.total_time_s:10.4f}{law.total_time_s:9.4f}{ratio_t:9.5f}"
              f"{statistics.median(tr):12.3f}{statistics.median(tt):10.3f}{ratio_c:7.2f}{its:6d}"
              f"{law.node_group:6d}{law.max_accel_ratio:10.6f}")
    print("targets:")
    print(f"  traversal time <= 1.005 x TOPP-RA at every N: worst {worst_t:.5f} -> "
          f"{'PASS' if worst_t <= 1.005 else 'FAIL'}")
    print(f"  no run at the iteration cap: {'PASS' if not capped else 'FAIL'}")
    print(f"  compute <= 1.0 x TOPP-RA (CPU time, same run): worst {worst_c:.2f} -> "
          f"{'PASS' if worst_c <= 1.0 else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
