"""Build the frozen one-folder winder application (``make installer``).

::

    .venv/bin/python installer/build.py              # dist/winder/ + dist/winder-<version>-<platform>.tar.gz
    .venv/bin/python installer/build.py --no-archive # the folder only

Runs PyInstaller on ``installer/winder.spec`` (work files in ``build/pyinstaller``), adds the
desktop entry and its installer script to ``dist/winder/`` (Linux), packs the folder and prints
the build time and sizes.  Needs the ``[installer]`` extra (``pip install -e ".[installer]"``).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import subprocess
import sys
import tarfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INSTALLER = ROOT / "installer"
SPEC = INSTALLER / "winder.spec"
DIST = ROOT / "dist"
WORK = ROOT / "build" / "pyinstaller"
APP = DIST / "winder"


def version() -> str:
    """The application version, read from ``engine/__init__.py`` (no import needed)."""
    m = re.search(r'__version__ = "([^"]+)"', (ROOT / "engine" / "__init__.py").read_text(encoding="utf-8"))
    if not m:
        raise SystemExit("build: no __version__ in engine/__init__.py")
    return m.group(1)


def platform_tag(system: str | None = None, machine: str | None = None) -> str:
    """``linux-x86_64``, ``windows-amd64``, ``macos-arm64`` ... for the archive name."""
    system = (system or platform.system()).lower()
    machine = (machine or platform.machine()).lower()
    system = {"darwin": "macos"}.get(system, system)
    return f"{system}-{machine}"


def archive_name(ver: str, tag: str) -> str:
    """``winder-<version>-<tag>.tar.gz`` (``.zip`` on Windows)."""
    return f"winder-{ver}-{tag}" + (".zip" if tag.startswith("windows") else ".tar.gz")


def tree_size(path: Path) -> int:
    """Bytes in the files under ``path`` (symbolic links not followed)."""
    total = 0
    for p in path.rglob("*"):
        if p.is_file() and not p.is_symlink():
            total += p.stat().st_size
    return total


def mib(n: float) -> str:
    return f"{n / 2**20:.0f} MiB"


def run_pyinstaller(clean: bool) -> float:
    """Run PyInstaller on the spec; return the wall time in s."""
    try:
        import PyInstaller  # noqa: F401
    except ImportError:
        raise SystemExit('build: PyInstaller is missing: .venv/bin/pip install -e ".[installer]"') from None
    cmd = [sys.executable, "-m", "PyInstaller", "--noconfirm", "--log-level", "WARN",
           "--distpath", str(DIST), "--workpath", str(WORK), str(SPEC)]
    if clean:
        cmd.insert(3, "--clean")
    print("build:", " ".join(cmd), flush=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=ROOT, check=True)
    return time.perf_counter() - t0


def add_desktop_files() -> None:
    """Linux: ``winder.desktop`` and ``install-desktop-entry.sh`` next to the executable."""
    shutil.copy2(INSTALLER / "winder.desktop", APP / "winder.desktop")
    script = APP / "install-desktop-entry.sh"
    shutil.copy2(INSTALLER / "install-desktop-entry.sh", script)
    script.chmod(0o755)


def make_archive(dest: Path) -> float:
    """Pack ``dist/winder`` (top folder ``winder/``) into ``dest``; return the wall time in s."""
    t0 = time.perf_counter()
    tmp = dest.with_name(dest.name + ".part")
    if dest.suffix == ".zip":
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=6) as z:
            for p in sorted(APP.rglob("*")):
                z.write(p, p.relative_to(DIST))
    else:
        with tarfile.open(tmp, "w:gz", compresslevel=6) as t:
            t.add(APP, arcname="winder", filter=_tar_filter)
    os.replace(tmp, dest)
    return time.perf_counter() - t0


def _tar_filter(info: tarfile.TarInfo) -> tarfile.TarInfo:
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    return info


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-archive", action="store_true", help="do not pack dist/winder")
    ap.add_argument("--no-clean", action="store_true", help="reuse PyInstaller's cache in build/pyinstaller")
    args = ap.parse_args(argv)

    ver, tag = version(), platform_tag()
    t_build = run_pyinstaller(clean=not args.no_clean)
    exe = APP / ("winder.exe" if os.name == "nt" else "winder")
    if not exe.exists():
        raise SystemExit(f"build: PyInstaller finished but {exe} is missing")
    if sys.platform.startswith("linux"):
        add_desktop_files()
    size = tree_size(APP)
    print(f"build: {APP.relative_to(ROOT)} built in {t_build:.0f} s, {mib(size)} on disk", flush=True)
    if not args.no_archive:
        arch = DIST / archive_name(ver, tag)
        t_arch = make_archive(arch)
        print(f"build: {arch.relative_to(ROOT)} {mib(arch.stat().st_size)} (packed in {t_arch:.0f} s)")
    print(f"build: try it:  {exe.relative_to(ROOT)} --version   (smoke test: make installer-test)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
