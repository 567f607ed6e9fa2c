"""Long mutation fuzz of the ``winder`` command line (issue 19): thousands of cases, counts printed.

    python benchmarks/fuzz_winder.py --cases 3000 --seed 1 [--engine /work/main] [--time 60]

``--engine`` chooses the source tree whose ``engine`` is fuzzed (default: this one), so the same
cases can be run before and after a change.  The cases, the checks and the worker are in
``tests/fuzz_cases.py`` (the suite runs a short seeded budget of them, tests/test_fuzz.py).  Prints
the counts (exit codes, tracebacks, hangs, crashes, memory, warnings, partial outputs) and the
first cases of each problem.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fuzz_cases import Runner, run_fuzz, summarise  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--engine", default=str(Path(__file__).resolve().parents[1]),
                    help="source tree with the engine to fuzz")
    ap.add_argument("--time", type=float, default=60.0, help="time budget of one case (s)")
    ap.add_argument("--memory", type=float, default=2.5, help="peak memory budget of one case (GB)")
    ap.add_argument("--light", action="store_true", help="no STEP cases and no 300k-point profiles")
    ap.add_argument("--verbose", action="store_true", help="print every case with a problem")
    args = ap.parse_args()
    t0 = time.monotonic()
    runner = Runner(pythonpath=args.engine, memory_budget_bytes=int(args.memory * 2**30))
    with tempfile.TemporaryDirectory(prefix="winder-fuzz-") as d:
        try:
            def progress(outs: list) -> None:
                c = summarise(outs)
                print(f"after {len(outs)} cases ({time.monotonic() - t0:.0f} s): "
                      + ", ".join(f"{k} {v}" for k, v in sorted(c.items()) if k != "cases"), flush=True)

            outs = run_fuzz(args.cases, args.seed, Path(d), time_budget_s=args.time, heavy=not args.light,
                            runner=runner, log=(lambda t: print(t, flush=True)) if args.verbose else None,
                            progress=progress)
        finally:
            runner.close()
    counts = summarise(outs)
    print(f"engine {args.engine}, seed {args.seed}, {len(outs)} cases in {time.monotonic() - t0:.0f} s")
    for k, v in sorted(counts.items()):
        print(f"  {k:16s} {v}")
    shown: dict[str, int] = {}
    for o in outs:
        for k, v in o.problems.items():
            if shown.get(k, 0) < 5:
                shown[k] = shown.get(k, 0) + 1
                print(f"{k}: {o.case}: {v}\n    argv: {' '.join(o.argv)}")
    slow = sorted(outs, key=lambda o: -o.elapsed_s)[:3]
    print("slowest: " + ", ".join(f"{o.case} {o.elapsed_s:.1f} s" for o in slow))
    big = max(outs, key=lambda o: o.peak_rss)
    print(f"largest peak memory: {big.case} {big.peak_rss / 2**20:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
