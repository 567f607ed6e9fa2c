"""The engine must never import Qt or the GUI (checked by scanning the import graph for real)."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_engine_imports_no_qt() -> None:
    code = textwrap.dedent(
        """
        import importlib, pkgutil, sys
        import engine
        for info in pkgutil.walk_packages(engine.__path__, "engine."):
            if info.name != "engine.__main__":
                importlib.import_module(info.name)
        bad = sorted(m for m in sys.modules
                     if m.split(".")[0] in {"PySide6", "shiboken6", "pyqtgraph", "pyvistaqt", "winder_gui"})
        print(",".join(bad))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"engine imported Qt/GUI modules: {out.stdout.strip()}"
