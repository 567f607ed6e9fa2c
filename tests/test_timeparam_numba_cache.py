"""The compiled kernels load from numba's on-disk cache in a new process (issue 16): a kernel that is
not found there is compiled again by every process, about 1.4 s of a run (a compiled function calling
another one built in the same closure was such a case)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = """
import json
import numpy as np
from engine import timeparam_jit as J
assert J.warm()
J.hulls(np.array([[[1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [-1.0, 0.0], [0.0, -1.0], [-0.5, -0.5]]]),
        (np.array([0, 1, 2]), np.array([3, 4, 5])))
out = {}
for name in ("_KERNEL", "_WINDOWS", "_FUSED", "_CHAINS", "_HULL_SYM", "_HULL", "_SWEEP"):
    for k, d in enumerate(getattr(J, name)):
        for f in (d if isinstance(d, tuple) else (d,)):
            if f is not None and hasattr(f, "stats"):
                out[f"{name}[{k}].{f.py_func.__name__}"] = [sum(f.stats.cache_hits.values()),
                                                          sum(f.stats.cache_misses.values())]
print(json.dumps(out))
"""


def test_kernels_come_from_the_cache_in_a_new_process() -> None:
    pytest.importorskip("numba")
    import json

    runs = []
    for _ in range(2):                      # the first may compile and write the cache
        proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True,
                              timeout=900)
        assert proc.returncode == 0, proc.stderr
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    second = runs[1]
    used = {"_HULL[0]._hulls", "_HULL_SYM[0]._graham", "_HULL_SYM[0]._prep", "_CHAINS[0]._chains_k",
            "_SWEEP[0]._sweep_back", "_SWEEP[0]._fwd"}
    assert used <= set(second)
    assert all(second[k][0] > 0 for k in used), second          # loaded from the cache
    missed = {k: v for k, v in second.items() if v[1] > 0}
    assert not missed, f"compiled again in a new process (hits, misses): {missed}"
