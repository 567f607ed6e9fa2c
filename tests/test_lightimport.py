"""engine._lightimport: SciPy imported without NumPy's unused lazy submodules, and SciPy's HiGHS without all
of scipy.optimize (issue 16, start-up) - the same modules, the same numbers, NumPy left as it was."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


_STATE = (
    "import json, sys, numpy as np\n"
    "names = sorted(np.__all__); d = sorted(dir(np))\n"
)


def test_scipy_without_numpy_lazy_submodules_and_numpy_unchanged() -> None:
    plain = _run(_STATE + "print(json.dumps({'all': names, 'dir': d}))")
    got = _run(
        "import engine, sys\n"
        "from engine import _lightimport\n"
        "assert _lightimport._FINDER in sys.meta_path\n"
        "import numpy as np\n"
        "import scipy.sparse, scipy.linalg\n"
        "from scipy._lib import array_api_compat\n"
        "from scipy._lib._array_api import array_namespace\n"
        "xp = array_namespace(np.ones(3))\n"
        "a = xp.asarray([[2.0, 1.0], [1.0, 3.0]])\n"
        "assert abs(float(xp.linalg.det(a)) - 5.0) < 1e-12 and float(xp.sum(xp.fft.fft(xp.ones(4))).real) == 4.0\n"
        "loaded = [m for m in ('numpy.f2py', 'numpy.testing', 'unittest', 'charset_normalizer') if m in sys.modules]\n"
        "finder_left = _lightimport._FINDER in sys.meta_path\n"
        + _STATE +
        "import numpy.testing\n"
        "np.testing.assert_allclose(scipy.linalg.solve(a, [1.0, 2.0]), np.linalg.solve(a, [1.0, 2.0]))\n"
        "print(json.dumps({'all': names, 'dir': d, 'loaded': loaded, 'finder_left': finder_left}))\n"
    )
    assert got["loaded"] == []            # the clone no longer imports them
    assert got["finder_left"] is False     # the finder answered once and removed itself
    assert got["all"] == plain["all"] and got["dir"] == plain["dir"]  # NumPy's namespace as it was


def test_no_effect_once_scipy_base_is_imported() -> None:
    got = _run(
        "import sys, json\n"
        "import scipy.sparse\n"
        "from engine import _lightimport\n"
        "print(json.dumps({'finder': _lightimport._FINDER in sys.meta_path, 'f2py': 'numpy.f2py' in sys.modules}))\n"
    )
    assert got == {"finder": False, "f2py": True}  # scipy came first: the ordinary (heavier) import, nothing hooked


def test_highs_extension_without_scipy_optimize_then_scipy_optimize_uses_it() -> None:
    got = _run(
        "import sys, json\n"
        "from engine import _lightimport, payout\n"
        "core = payout._highs_core()\n"
        "before = 'scipy.optimize' in sys.modules\n"
        "import scipy.optimize\n"
        "from scipy.optimize._highspy import _highs_wrapper\n"
        "same = sys.modules['scipy.optimize._highspy._core'] is core and _highs_wrapper._h is core\n"
        "r = scipy.optimize.linprog([-1.0, -2.0], A_ub=[[1.0, 1.0]], b_ub=[4.0], bounds=[(0, 3), (0, 3)])\n"
        "missing = _lightimport.extension_module('scipy.optimize._no_such_ext')\n"
        "print(json.dumps({'before': before, 'same': same, 'fun': r.fun, 'missing': missing}))\n"
    )
    assert got["before"] is False          # HiGHS came without the rest of scipy.optimize
    assert got["same"] is True             # loaded once: scipy.optimize took this module
    assert abs(got["fun"] + 7.0) < 1e-9    # x = (1, 3)
    assert got["missing"] is None


def test_winder_process_looks_for_no_pydantic_plugins_unless_the_user_says() -> None:
    code = (
        "import json, os, sys\n"
        "from unittest import mock\n"
        "import pydantic.plugin._loader as loader\n"
        "from engine import cli\n"
        "with mock.patch.object(loader, 'entry_points', return_value=[]) as ep:\n"
        "    rc = cli.main(['mandrel', 'resources/examples/pipe.toml'])\n"
        "print(json.dumps({'rc': rc, 'env': os.environ.get('PYDANTIC_DISABLE_PLUGINS'), 'scanned': ep.called}))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYDANTIC_DISABLE_PLUGINS"}
    for user, want in ((None, "__all__"), ("some_plugin", "some_plugin")):
        e = {**env, "PYTHONPATH": str(ROOT), **({"PYDANTIC_DISABLE_PLUGINS": user} if user else {})}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT, env=e)
        assert out.returncode == 0, out.stderr
        got = json.loads(out.stdout.strip().splitlines()[-1])
        assert got["env"] == want
        # the job schema built without the scan; the user's own setting is kept (and pydantic then looks)
        assert got == {"rc": 0, "env": want, "scanned": user is not None}


def test_ckdtree_without_scipy_spatial_then_scipy_spatial_uses_it() -> None:
    got = _run(
        "import sys, json\n"
        "import numpy as np\n"
        "from engine import _lightimport\n"
        "K = _lightimport.ckdtree()\n"
        "before = 'scipy.spatial' in sys.modules\n"
        "d, i = K(np.array([[0.0, 0.0], [3.0, 4.0]])).query([[3.0, 3.0]])\n"
        "import scipy.spatial\n"
        "print(json.dumps({'before': before, 'same': scipy.spatial.cKDTree is K, 'd': float(d[0]), 'i': int(i[0])}))\n"
    )
    assert got == {"before": False, "same": True, "d": 1.0, "i": 1}


def test_example_runs_import_only_the_scipy_parts_they_use(tmp_path) -> None:
    """Start-up (issue 16): a `winder run` of the examples, in one process and with its layers side by side,
    imports none of scipy.optimize, scipy.spatial, scipy.special, scipy.sparse.linalg, scipy.linalg,
    numpy.f2py or numpy.testing (each a heavy import the run does not need)."""
    heavy = ("scipy.optimize", "scipy.spatial", "scipy.special", "scipy.sparse.linalg", "scipy.linalg", "numpy.f2py",
             "numpy.testing")
    for example in ("pipe", "pressure_vessel"):
        for jobs in ("1", "2"):
            out = subprocess.run(
                [sys.executable, "-c",
                 "import sys, json\n"
                 f"sys.argv = ['winder', 'run', 'resources/examples/{example}.toml', "
                 f"'-o', {str(tmp_path / 'o.ngc')!r}, '--quiet']\n"
                 "from engine.cli import main\n"
                 "rc = main()\n"
                 f"print(json.dumps({{'rc': rc, 'heavy': [m for m in {heavy!r} if m in sys.modules]}}))\n"],
                capture_output=True, text=True, timeout=300, cwd=ROOT,
                env={**os.environ, "PYTHONPATH": str(ROOT), "WINDER_JOBS": jobs})
            assert out.returncode == 0, out.stderr
            got = json.loads(out.stdout.strip().splitlines()[-1])
            assert got == {"rc": 0, "heavy": []}, (example, jobs, got)
