"""Issue 16: where the CPU time of `winder run` goes on the shipped examples, stage by stage.

Run: ``.venv/bin/python benchmarks/bench_examples_stages.py [--repeat 3] [--examples pipe pressure_vessel]``

Each run is a fresh process (``python -c``: the same work as ``winder run EXAMPLE -o ... --quiet -j 1``, in one
process so that every stage's CPU is counted here, not in forked layer children) with
CPU timers (``time.process_time``) wrapped around the stage functions; the examples are interleaved and
the medians printed.  Stages nest (the payout's sub-stages are part of the payout; the time laws are
part of the blocks stage's caller): the lines marked with ``-`` are parts of the line above them.
``start-up`` is the process's CPU time before the run starts (Python, numpy, the CLI); the heavy
modules are imported where they are first used, so their import time is in that stage (the first
contour imports scipy.spatial; the narrowest band imports scipy.optimize for SciPy's HiGHS).
``other`` is ``total`` less
start-up and the top-level stages (job loading, the mandrel, layer bookkeeping); ``total`` is the
process's whole CPU time (user + system).  The timers cost < 1 %; ``bench_examples_run.py`` measures
the targets themselves.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "resources" / "examples"

# (label, module, attribute path); a missing attribute is skipped (the code moves on)
STAGES = [
    ("winding line", "engine.winding", "winding_line"),
    ("payout (all layers)", "engine.payout", "payout_for_job"),
    ("- contour", "engine.payout", "_Contour.__init__"),
    ("- envelope", "engine.payout", "_prepare"),
    ("- (13) max min u", "engine.payout", "_fast_lp13"),
    ("- (14) min max u", "engine.payout", "_fast_lp14"),
    ("- narrowest band (HiGHS)", "engine.payout", "_solve_range_stage"),
    ("- (15) jerk QP", "engine.payout", "_fast_qp_stage"),
    ("- line check", "engine.payout", "_line_check"),
    ("extend to line", "engine.payout", "extend_to_line"),
    ("axes", "engine.pipeline", "_axes_stage"),
    ("blocks (linear approx.)", "engine.blocks", "make_blocks"),
    ("time laws", "engine.pipeline", "_time_law_blocks"),
    ("- parametrize", "engine.pipeline", "_parametrize"),
    ("join layers + NC", "engine.laminate", "_join"),
]

CHILD = r'''
import functools, importlib, json, resource, sys, time
acc = {}
def wrap(label, modname, attr):
    try:
        obj = importlib.import_module(modname)
        parts = attr.split(".")
        for p in parts[:-1]:
            obj = getattr(obj, p)
        f = getattr(obj, parts[-1])
    except (ImportError, AttributeError):
        return
    @functools.wraps(f)
    def w(*a, **k):
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            acc[label] = acc.get(label, 0.0) + time.process_time() - t
    setattr(obj, parts[-1], w)
from engine.cli import main
ru0 = resource.getrusage(resource.RUSAGE_SELF)
for label, m, a in json.loads(sys.argv[1]):
    wrap(label, m, a)
try:
    rc = main(["run", sys.argv[2], "-o", sys.argv[3], "--quiet", "-j", "1"])
except SystemExit as e:
    rc = e.code
if rc:
    raise SystemExit(f"exit {rc}")
ru = resource.getrusage(resource.RUSAGE_SELF)
acc["start-up"] = ru0.ru_utime + ru0.ru_stime
acc["total"] = ru.ru_utime + ru.ru_stime
print(json.dumps(acc))
'''


def _child(example: str, out: str, env: dict[str, str]) -> dict[str, float]:
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(STAGES), str(EX / f"{example}.toml"), out],
                          cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{example}: exit {proc.returncode}\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--examples", nargs="+", default=["pipe", "pressure_vessel"])
    args = ap.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    res: dict[str, list[dict[str, float]]] = {e: [] for e in args.examples}
    with tempfile.TemporaryDirectory() as tmp:
        for e in args.examples:                       # warm-up: bytecode
            _child(e, f"{tmp}/{e}.ngc", env)
        load0 = os.getloadavg()[0]
        for _ in range(args.repeat):
            for e in args.examples:
                res[e].append(_child(e, f"{tmp}/{e}.ngc", env))
        load1 = os.getloadavg()[0]
    print(f"load average {load0:.2f} -> {load1:.2f} on {os.cpu_count()} cores; CPU s, medians of {args.repeat} "
          "interleaved fresh processes")
    for e in args.examples:
        for r in res[e]:
            top = sum(v for k, v in r.items() if k in {s[0] for s in STAGES} and not k.startswith("-"))
            r["other"] = r["total"] - r["start-up"] - top
    labels = ["start-up"] + [s[0] for s in STAGES] + ["other", "total"]
    print(f"{'stage':<28}" + "".join(f"{e:>18}" for e in args.examples))
    for lab in labels:
        vals = [statistics.median(r.get(lab, 0.0) for r in res[e]) for e in args.examples]
        print(f"{lab:<28}" + "".join(f"{v:18.3f}" for v in vals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
