"""Memory the pipeline keeps per winding-line point: the figure behind engine.budget.BYTES_PER_LINE_POINT.

    python benchmarks/bench_budget.py

Runs ``winder run`` on the example vessel with 100, 200 and 400 circuits (time law "tube", the
default), each in a fresh process, and prints the peak resident memory (``ru_maxrss`` of the child),
the number of line points, and the slope (bytes per point) between the runs: the fixed cost of the
interpreter and libraries drops out of the slope.  Also prints the budget's estimate for each job.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine import budget  # noqa: E402
from engine.job import load_job  # noqa: E402
from engine.winding import winding_line_for_job  # noqa: E402


def main() -> int:
    base = (ROOT / "resources" / "examples" / "pressure_vessel.toml").read_text()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for circuits in (100, 200, 400):
            job = Path(d) / f"c{circuits}.toml"
            job.write_text(base.replace("points_per_pass = 2000", f"points_per_pass = 2000\ncircuits = {circuits}"))
            points = winding_line_for_job(load_job(job), job).z.size
            est = budget.check_winding_spec(load_job(job).winding, 100.0, 8.0)
            proc = subprocess.Popen([sys.executable, "-m", "engine", "run", str(job), "-o", str(Path(d) / "o.ngc"),
                                     "--quiet", "--force"], env={**os.environ, "PYTHONPATH": str(ROOT)},
                                    stderr=subprocess.DEVNULL)
            _, _status, usage = os.wait4(proc.pid, 0)
            peak = usage.ru_maxrss * 1024
            rows.append((circuits, points, peak, est.bytes))
            print(f"circuits {circuits:4d}: {points:9d} line points, peak RSS {peak / 2**20:7.0f} MB, "
                  f"budget estimate {est.bytes / 2**20:7.0f} MB ({est.count:.0f} points)")
    for (c0, p0, m0, _), (c1, p1, m1, _) in zip(rows, rows[1:]):
        print(f"{c0} -> {c1} circuits: {(m1 - m0) / (p1 - p0):.0f} bytes per line point "
              f"(engine.budget.BYTES_PER_LINE_POINT = {budget.BYTES_PER_LINE_POINT})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
