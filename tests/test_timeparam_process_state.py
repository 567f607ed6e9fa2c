"""A program does not depend on whether numba happens to be loaded in the process (issue 15: the GUI,
which warms numba, exports what `winder run` writes).  The compiled hull and the numpy hull may keep
a different one of two nearly coincident vertices; the pipe example's NC differed in one F word."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = """
import sys
from engine import timeparam_jit
if sys.argv[1] == "warm":
    assert timeparam_jit.warm(), "numba kernels unavailable"
    import numba  # noqa: F401
else:
    assert "numba" not in sys.modules
from engine.cli import main
code = main(["run", sys.argv[2], "-o", sys.argv[3], "--quiet"])
assert sys.argv[1] != "cold" or "numba" not in sys.modules, "a small job loaded numba"
sys.exit(code)
"""


@pytest.mark.parametrize("example", ["pipe.toml"])
def test_same_program_with_and_without_numba_loaded(tmp_path: Path, example: str) -> None:
    pytest.importorskip("numba")
    job = str(ROOT / "resources" / "examples" / example)
    out = {}
    for mode in ("cold", "warm"):
        dst = tmp_path / f"{mode}.ngc"
        proc = subprocess.run([sys.executable, "-c", SCRIPT, mode, job, str(dst)], cwd=ROOT,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        out[mode] = dst.read_bytes()
    assert out["warm"] == out["cold"]
