"""Time-to-show of the desktop application (target: window on screen in < 3 s).

Launches ``winder resources/examples/pressure_vessel.toml`` under ``QT_QPA_PLATFORM=offscreen`` with
``WINDER_QUIT_WHEN_SHOWN=ready`` (the app quits by itself once the window is painted and the first
mandrel is plotted) and prints, per run and as the median of the runs:

- window shown: launch → main window painted (reported by the app, clock started by this script);
- mandrel shown: launch → first mandrel plotted (built in a worker thread);
- process total: launch → process exit (includes interpreter shutdown).

Run: ``.venv/bin/python benchmarks/bench_gui_startup.py [runs]``.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 3.0


def one_run() -> dict[str, float]:
    exe = ROOT / ".venv" / "bin" / "winder"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "engine"]
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", WINDER_QUIT_WHEN_SHOWN="ready")
    t0 = time.time()
    env["WINDER_T0"] = repr(t0)
    proc = subprocess.run(
        [*cmd, "resources/examples/pressure_vessel.toml"], cwd=ROOT, env=env, capture_output=True, text=True,
        timeout=120,
    )
    total = time.time() - t0
    if proc.returncode != 0:
        raise SystemExit(f"winder exited with {proc.returncode}:\n{proc.stderr}")
    out = {"process total": total}
    for key in ("window shown", "mandrel shown"):
        m = re.search(rf"winder: {key} after ([0-9.]+) s", proc.stderr)
        if m is None:
            raise SystemExit(f"no '{key}' line in the output:\n{proc.stderr}")
        out[key] = float(m.group(1))
    return out


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    results = []
    for i in range(runs):
        r = one_run()
        results.append(r)
        print(f"run {i + 1}: " + ", ".join(f"{k} {v:.3f} s" for k, v in r.items()))
    print()
    for key in ("window shown", "mandrel shown", "process total"):
        med = statistics.median(r[key] for r in results)
        print(f"median {key:14s} {med:6.3f} s   ratio to the {TARGET_S:.0f} s target: {med / TARGET_S:.2f}")


if __name__ == "__main__":
    main()
