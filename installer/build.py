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
import hashlib
import json
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


SOURCE_DIRS = ("engine", "winder_gui", "resources", "installer")


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 of what goes into the build (``SOURCE_DIRS``), to tell a stale build from a fresh one."""
    h = hashlib.sha256()
    for d in SOURCE_DIRS:
        for p in sorted((root / d).rglob("*")):
            if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"):
                h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def is_fresh(digest: str, archive: Path | None) -> bool:
    """Whether ``dist/winder`` was built from sources with this ``digest`` (and ``archive`` exists)."""
    try:
        info = json.loads((APP / "BUILD-INFO.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return info.get("source_digest") == digest and (archive is None or archive.is_file())


def git_commit() -> str:
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10)
    except OSError:
        return ""
    return r.stdout.strip() if r.returncode == 0 else ""


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


def _pyinstaller_version() -> str:
    import PyInstaller

    return PyInstaller.__version__


def add_desktop_files() -> None:
    """Linux: ``winder.desktop`` and ``install-desktop-entry.sh`` next to the executable."""
    shutil.copy2(INSTALLER / "winder.desktop", APP / "winder.desktop")
    script = APP / "install-desktop-entry.sh"
    shutil.copy2(INSTALLER / "install-desktop-entry.sh", script)
    script.chmod(0o755)


def make_archive(dest: Path) -> float:
    """Pack ``dist/winder`` (top folder ``winder/``; macOS: ``winder.app``) into ``dest``; return the time in s."""
    t0 = time.perf_counter()
    tmp = dest.with_name(dest.name + ".part")
    src = DIST / "winder.app" if sys.platform == "darwin" and (DIST / "winder.app").is_dir() else APP
    if dest.suffix == ".zip":
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=6) as z:
            for p in sorted(src.rglob("*")):
                z.write(p, p.relative_to(DIST))
    else:
        with tarfile.open(tmp, "w:gz", compresslevel=6) as t:
            t.add(src, arcname=src.name, filter=_tar_filter)
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
    ap.add_argument("--if-stale", action="store_true",
                    help="do nothing if dist/winder was built from the current sources (and the archive exists)")
    args = ap.parse_args(argv)

    ver, tag = version(), platform_tag()
    digest = source_digest()
    if args.if_stale and is_fresh(digest, None if args.no_archive else DIST / archive_name(ver, tag)):
        print(f"build: {APP.relative_to(ROOT)} is up to date with the sources (no rebuild)")
        return 0
    t_build = run_pyinstaller(clean=not args.no_clean)
    exe = APP / ("winder.exe" if os.name == "nt" else "winder")
    if not exe.exists():
        raise SystemExit(f"build: PyInstaller finished but {exe} is missing")
    if sys.platform.startswith("linux"):
        add_desktop_files()
    size = tree_size(APP)
    info = {"version": ver, "platform": tag, "git_commit": git_commit(), "source_digest": digest,
            "python": platform.python_version(), "pyinstaller": _pyinstaller_version(),
            "build_seconds": round(t_build, 1), "size_bytes": size,
            "built_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (APP / "BUILD-INFO.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    print(f"build: {APP.relative_to(ROOT)} built in {t_build:.0f} s, {mib(size)} on disk", flush=True)
    if not args.no_archive:
        arch = DIST / archive_name(ver, tag)
        t_arch = make_archive(arch)
        print(f"build: {arch.relative_to(ROOT)} {mib(arch.stat().st_size)} (packed in {t_arch:.0f} s)")
    print(f"build: try it:  {exe.relative_to(ROOT)} --version   (smoke test: make installer-test)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
