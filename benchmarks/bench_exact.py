"""Issue 17 figures: convergence of the minimax line with the points per pass, the cost of the
breakpoint nodes and of the narrowest-band LP, the payout bands of the examples.

Run: ``.venv/bin/python benchmarks/bench_exact.py [--seeds 4]``.  Prints

* for random waisted splines: max |λ| at 500 / 2 000 / 20 000 points per pass and its spread, and
  the time of one winding line at 2 000 points with and without the knots as nodes;
* for the examples: the min-range band (u range) against every feasible geometric law's, the
  (13)-then-(14) band and the seconds of the extra min (u_max − u_min) LP.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from engine import mandrel as M
from engine.job import WindingSpec, build_mandrel, load_job
from engine.mandrel import Mandrel
from engine.payout import ContactLine, geometric_law, min_range_law
from engine.winding import winding_line, winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]


def waisted(seed: int) -> Mandrel:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(7, 12))
    z = np.unique(np.round(np.concatenate([[0.0], np.sort(rng.uniform(6, 294, n - 2)), [300.0]]), 3))
    t = z / 300.0
    r = 60.0 * (0.35 + 0.65 * np.sin(np.pi * t) ** 0.7) * (
        1 - (1 - rng.uniform(0.55, 0.8)) * np.exp(-((t - rng.uniform(0.4, 0.6)) / 0.12) ** 2))
    r[0], r[-1] = rng.uniform(12, 20), rng.uniform(12, 20)
    return Mandrel.from_points(z, r)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args()
    print("minimax on random waisted splines: max |λ| by points per pass")
    for seed in range(args.seeds):
        m = waisted(seed)
        lam = {}
        for n in (500, 2000, 20000):
            lam[n] = winding_line(m, 6.0, 0.5, WindingSpec(points_per_pass=n)).max_abs_lambda
        t0 = time.perf_counter()
        winding_line(m, 6.0, 0.5, WindingSpec(points_per_pass=2000))
        with_nodes = time.perf_counter() - t0
        orig = M.Mandrel.breakpoints
        M.Mandrel.breakpoints = lambda self: np.zeros(0)  # type: ignore[method-assign]
        try:
            t0 = time.perf_counter()
            old = winding_line(m, 6.0, 0.5, WindingSpec(points_per_pass=2000)).max_abs_lambda
            without = time.perf_counter() - t0
        finally:
            M.Mandrel.breakpoints = orig  # type: ignore[method-assign]
        spread = max(lam.values()) - min(lam.values())
        print(f"  seed {seed}: λ500 {lam[500]:.9f}  λ2000 {lam[2000]:.9f}  λ20000 {lam[20000]:.9f}  spread {spread:.2e}"
              f"  | without knot nodes λ2000 {old:.9f} ({old - lam[20000]:+.2e})"
              f"  | time 2000 pts {with_nodes:.2f} s (without nodes {without:.2f} s)")
    print("payout bands (min-range vs feasible geometric laws, default grid)")
    for name in ("pipe", "pressure_vessel", "bottle"):
        path = ROOT / "resources" / "examples" / f"{name}.toml"
        job = load_job(path)
        mandrel = build_mandrel(job, path)
        line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
        t0 = time.perf_counter()
        mr = min_range_law(line, mandrel, job.payout)
        total = time.perf_counter() - t0
        sol = mr.report["solver"]
        laws = []
        for law in ("parallel", "equidistant", "equal-tangent"):
            try:
                g = geometric_law(line, mandrel, law, job.payout)
            except Exception:  # noqa: BLE001 - an infeasible law is just not compared
                continue
            laws.append(f"{law} {g.report['u_range']:.4f}{'' if g.feasible else ' (infeasible)'}")
        print(f"  {name}: min-range {mr.report['u_range']:.4f} ({sol['band_from'][:14]}…), (13)-(14) band "
              f"{sol['u_max_14'] - sol['u_min_13']:.4f}, range LP {sol['range_lp']['seconds']:.2f} s of {total:.2f} s"
              f" | {', '.join(laws)}")


if __name__ == "__main__":
    main()
