"""``winder timeparam``: CLI tests."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine.cli import main
from engine.timeparam_example import EXAMPLE_LIMITS, example_path

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def short_case(tmp_path: Path) -> tuple[Path, Path]:
    s, X, dX, ddX = example_path()
    npz = tmp_path / "path.npz"
    np.savez(npz, s=s[:300], X=X[:300], dX=dX[:300], ddX=ddX[:300])
    lim = tmp_path / "limits.toml"
    lim.write_text(EXAMPLE_LIMITS.read_text(encoding="utf-8").replace("s = 1300.00", "s = 900.00"),
                   encoding="utf-8")
    return npz, lim


def test_cli_json_has_the_documented_keys(short_case, capsys) -> None:
    npz, lim = short_case
    assert main(["timeparam", str(npz), "--limits", str(lim), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("method", "total_time_s", "compute_s", "max_accel_ratio", "energy", "iterations", "s", "sdot", "t"):
        assert key in out
    assert out["method"] == "tube" and len(out["s"]) == 300
    it = out["iterations"][1]
    for key in ("r", "total_time_s", "specific_time", "half_width", "w_touches", "o_touches", "decrease_percent"):
        assert key in it
    assert out["max_accel_ratio"] <= 1.0 + 1e-9
    assert out["total_time_s"] == pytest.approx(out["t"][-1])


@pytest.mark.parametrize("method", ["dp", "toppra"])
def test_cli_methods_and_npz_out(short_case, tmp_path, capsys, method) -> None:
    npz, lim = short_case
    out_npz = tmp_path / "law.npz"
    assert main(["timeparam", str(npz), "--limits", str(lim), "--method", method, "--levels", "150",
                 "--npz-out", str(out_npz)]) == 0
    text = capsys.readouterr().out
    assert f"method {method}" in text and "total time" in text
    with np.load(out_npz) as z:
        assert z["sdot"].shape == (300,) and z["t"][-1] > 0


def test_cli_errors_are_clean(short_case, tmp_path, capsys) -> None:
    npz, lim = short_case
    assert main(["timeparam", str(npz)]) == 2
    assert "--limits" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('v_max = [1.0]\na_max = [1.0]\n', encoding="utf-8")
    assert main(["timeparam", str(npz), "--limits", str(bad)]) == 2
    assert "p = 7" in capsys.readouterr().err
    zero = tmp_path / "zero.toml"
    zero.write_text(lim.read_text(encoding="utf-8").replace("sdot_max = 200.0", "sdot_max = 0.0"), encoding="utf-8")
    assert main(["timeparam", str(npz), "--limits", str(zero)]) == 2
    err = capsys.readouterr().err
    assert "'feed'" in err and "854.27" in err and "Traceback" not in err


def test_cli_example_subprocess() -> None:
    exe = ROOT / ".venv" / "bin" / "winder"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "engine"]
    res = subprocess.run([*cmd, "timeparam", "--example", "--json"], capture_output=True, text=True, timeout=300,
                         cwd=ROOT)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert len(out["s"]) == 893 and out["s"][-1] == pytest.approx(2846.9)
    assert len(out["iterations"]) >= 3 and out["max_accel_ratio"] <= 1.0 + 1e-9


def test_cli_npz_out_on_a_dense_path(tmp_path, capsys) -> None:
    """A dense path runs the tube on node groups: the iterations are saved on their own nodes (iter_s),
    the law on every node."""
    s, X, dX, ddX = example_path(3000)
    npz = tmp_path / "dense.npz"
    np.savez(npz, s=s, X=X, dX=dX, ddX=ddX)
    out_npz = tmp_path / "law.npz"
    assert main(["timeparam", str(npz), "--limits", str(EXAMPLE_LIMITS), "--npz-out", str(out_npz)]) == 0
    capsys.readouterr()
    with np.load(out_npz) as z:
        assert z["sdot"].shape == (3000,)
        n_it = z["iter_r"].size
        assert 1 < z["iter_s"].size < 3000 and z["iter_sdot"].shape == (n_it, z["iter_s"].size)
        assert z["iter_s"][0] == s[0] and z["iter_s"][-1] == s[-1]


def test_cli_final_sweep_and_no_sweep(short_case, tmp_path, capsys) -> None:
    """The tube's law is swept at the end (a line says how much it saved; the JSON has ``sweep_gain_s``);
    ``--no-sweep`` and ``sweep = false`` in the limits file keep the tube's own law: its last iteration."""
    npz, lim = short_case
    assert main(["timeparam", str(npz), "--limits", str(lim)]) == 0
    text = capsys.readouterr().out
    assert "final sweep:" in text and "faster than the tube's law" in text
    assert main(["timeparam", str(npz), "--limits", str(lim), "--json"]) == 0
    swept = json.loads(capsys.readouterr().out)
    assert swept["sweep_gain_s"] > 0
    assert swept["total_time_s"] == pytest.approx(swept["iterations"][-1]["total_time_s"] - swept["sweep_gain_s"],
                                                  rel=1e-12)
    lim_off = tmp_path / "limits_off.toml"
    lim_off.write_text("sweep = false\n" + lim.read_text(encoding="utf-8"), encoding="utf-8")   # before the tables
    for args in (["--limits", str(lim), "--no-sweep"], ["--limits", str(lim_off)]):
        assert main(["timeparam", str(npz), *args, "--json"]) == 0
        plain = json.loads(capsys.readouterr().out)
        assert plain["sweep_gain_s"] == 0.0
        assert plain["total_time_s"] == pytest.approx(plain["iterations"][-1]["total_time_s"], rel=1e-12)
        assert plain["total_time_s"] > swept["total_time_s"] and plain["max_accel_ratio"] <= 1.0 + 1e-9
        assert [it["total_time_s"] for it in plain["iterations"]] == [it["total_time_s"] for it in
                                                                       swept["iterations"]]
