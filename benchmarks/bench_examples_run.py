"""Issue 16: `winder run` of the shipped examples and `winder --version`, start-up included.

Run: ``.venv/bin/python benchmarks/bench_examples_run.py [--repeat 5]``

Each case runs as a fresh process (``python -m engine ...``, as the ``winder`` script does), the cases
interleaved, ``--repeat`` times; printed: the medians of wall and CPU time (user + system of the child
and the processes it forked) and the targets (vessel <= 1.5 s, pipe <= 1 s, ``--version`` <= 0.15 s).
``winder run`` runs a laminate's layers side by side on the CPUs available (wall < CPU); the ``-j1``
rows run them one after the other; the ``numpy passes`` rows run without the engine's compiled kernels
(``WINDER_AOT=0``: the ahead-of-time kernels of engine/aot.py off - the time laws', the payout's, the
dome's sums, the Clairaut passes' -, numba not loaded), for the ratio those kernels give.  The machine is
shared: the load average is printed; on a loaded machine CPU time is the steadier figure.  Bytecode is
written and used (as an installed program has it): ``PYTHONDONTWRITEBYTECODE`` is removed from the
children's environment and a first unmeasured run of every case warms the caches (bytecode, numba's
on-disk cache).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "resources" / "examples"
TARGETS = {"pressure_vessel": 1.5, "pipe": 1.0, "--version": 0.15}


def _run(args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall, cpu) seconds of one child process (``args`` may start with ``{"VAR": "value"}``: its environment)."""
    if args and isinstance(args[0], dict):
        env, args = {**env, **args[0]}, args[1:]
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "engine", *args], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"{args}: exit {proc.returncode}\n{err}")
    return wall, ru.ru_utime + ru.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory() as tmp:
        cases = {
            "pressure_vessel": ["run", str(EX / "pressure_vessel.toml"), "-o", f"{tmp}/v.ngc", "--quiet"],
            "pipe": ["run", str(EX / "pipe.toml"), "-o", f"{tmp}/p.ngc", "--quiet"],
            "--version": ["--version"],
            # the layers one after the other in one process (the default runs them side by side)
            "pressure_vessel -j1": ["run", str(EX / "pressure_vessel.toml"), "-o", f"{tmp}/v1.ngc", "--quiet",
                                    "--jobs", "1"],
            "pipe -j1": ["run", str(EX / "pipe.toml"), "-o", f"{tmp}/p1.ngc", "--quiet", "--jobs", "1"],
            "pressure_vessel numpy passes": [{"WINDER_AOT": "0"}, "run", str(EX / "pressure_vessel.toml"), "-o",
                                             f"{tmp}/vn.ngc", "--quiet"],
            "pipe numpy passes": [{"WINDER_AOT": "0"}, "run", str(EX / "pipe.toml"), "-o", f"{tmp}/pn.ngc", "--quiet"],
        }
        for a in cases.values():                       # warm-up: bytecode, numba cache
            _run(a, env)
        load0 = os.getloadavg()[0]
        res: dict[str, list[tuple[float, float]]] = {k: [] for k in cases}
        for _ in range(args.repeat):
            for k, a in cases.items():
                res[k].append(_run(a, env))
        load1 = os.getloadavg()[0]
    print(f"load average {load0:.2f} -> {load1:.2f} on {os.cpu_count()} cores; medians of {args.repeat} "
          f"interleaved runs")
    print(f"{'case':<30}{'wall s':>9}{'cpu s':>9}{'target s':>10}  verdict wall / CPU")
    med = {k: (statistics.median(w for w, _ in r), statistics.median(c for _, c in r)) for k, r in res.items()}
    for k, (wall, cpu) in med.items():
        t = TARGETS[k.split()[0]]
        print(f"{k:<30}{wall:9.3f}{cpu:9.3f}{t:10.2f}  {'PASS' if wall <= t else 'FAIL'} / "
              f"{'PASS' if cpu <= t else 'FAIL'}")
    for ex in ("pressure_vessel", "pipe"):
        (w1, c1), (w0, c0) = med[ex], med[f"{ex} numpy passes"]
        print(f"{ex}: compiled kernels / numpy passes: wall {w1 / w0:.3f}, CPU {c1 / c0:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
