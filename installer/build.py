"""Build the frozen one-folder winder application (``make installer``).

::

    .venv/bin/python installer/build.py              # dist/winder/ + dist/winder-<version>-<platform>.tar.gz
    .venv/bin/python installer/build.py --no-archive # the folder only

The sources (``engine``, ``winder_gui``, ``resources``, ``installer``) are first copied to
``build/source`` — from the working tree, or with ``--from-git REV`` exactly as committed (what a
clean clone holds) — and PyInstaller runs on ``build/source/installer/winder.spec`` (work files
in ``build/pyinstaller``): edits made while it runs do not leak into the build, and the smoke
test runs that same snapshot as "the source install".  Then the desktop entry and its installer
script go to ``dist/winder/`` (Linux), ``BUILD-INFO.json`` is written, the folder is packed, and
the build time and sizes are printed.  Needs the ``[installer]`` extra (``pip install -e ".[installer]"``).
"""

from __future__ import annotations

import argparse
import hashlib
import io
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
DIST = ROOT / "dist"
WORK = ROOT / "build" / "pyinstaller"
STAGE = ROOT / "build" / "source"
APP = DIST / "winder"


def version(root: Path = ROOT) -> str:
    """The application version, read from ``<root>/engine/__init__.py`` (no import needed)."""
    m = re.search(r'__version__ = "([^"]+)"', (root / "engine" / "__init__.py").read_text(encoding="utf-8"))
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


def stage_sources(rev: str | None = None) -> Path:
    """Copy ``SOURCE_DIRS`` to ``build/source`` from the working tree, or from git ``rev``; return it."""
    if STAGE.exists():
        shutil.rmtree(STAGE)
    STAGE.mkdir(parents=True)
    if rev:
        tar = subprocess.run(["git", "archive", "--format=tar", rev, *SOURCE_DIRS], cwd=ROOT, capture_output=True)
        if tar.returncode != 0:
            raise SystemExit(f"build: git archive {rev} failed: {tar.stderr.decode(errors='replace').strip()}")
        with tarfile.open(fileobj=io.BytesIO(tar.stdout)) as t:
            t.extractall(STAGE, filter="data")
    else:
        for d in SOURCE_DIRS:
            shutil.copytree(ROOT / d, STAGE / d, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo",
                                                                            "_aot_kernels*"))
    return STAGE


def build_kernels(stage: Path) -> None:
    """The engine's kernels compiled ahead of time (``engine/aot.py``) from the staged sources
    into the staged ``engine`` package, so that the frozen app runs them without numba (it is left out);
    where they cannot be built, the app runs the numpy code (the same answers, slower) and this says so."""
    env = {**os.environ, "PYTHONPATH": str(stage)}
    proc = subprocess.run([sys.executable, "-m", "engine.aot", "--quiet"], cwd=stage, env=env,
                          capture_output=True, text=True)
    print(f"build: {(proc.stdout + proc.stderr).strip()}", flush=True)


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 of what goes into the build (``SOURCE_DIRS``), to tell a stale build from a fresh one."""
    h = hashlib.sha256()
    for d in SOURCE_DIRS:
        for p in sorted((root / d).rglob("*")):
            if (p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo")
                    and not p.name.startswith("_aot_kernels")):  # (built from the sources: build_kernels)
                h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def is_fresh(digest: str, archive: Path | None) -> bool:
    """Whether ``dist/winder`` was built from sources with this ``digest`` (and ``archive`` exists)."""
    try:
        info = json.loads((APP / "BUILD-INFO.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return info.get("source_digest") == digest and (archive is None or archive.is_file())


def git_commit(rev: str = "HEAD") -> str:
    try:
        r = subprocess.run(["git", "rev-parse", rev], cwd=ROOT, capture_output=True, text=True, timeout=10)
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


def host_libraries(app: Path = APP) -> list[str]:
    """Shared libraries the bundle's ELF files need but do not carry (Linux, needs ``readelf``).

    These must come from the user's machine: the C library, GL/X11 and the others the spec keeps
    out on purpose; anything unexpected here is a library the build forgot.
    """
    readelf = shutil.which("readelf")
    if not readelf or not sys.platform.startswith("linux"):
        return []
    files = [p for p in app.rglob("*")
             if p.is_file() and not p.is_symlink() and (".so" in p.name or p == app / "winder")]
    present = {p.name for p in app.rglob("*")}
    needed: set[str] = set()
    for i in range(0, len(files), 200):
        r = subprocess.run([readelf, "-d", "-W", *map(str, files[i:i + 200])], capture_output=True, text=True)
        needed |= set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", r.stdout))
    return sorted(needed - present)


def mib(n: float) -> str:
    return f"{n / 2**20:.0f} MiB"


def run_pyinstaller(spec: Path, clean: bool) -> float:
    """Run PyInstaller on ``spec``; return the wall time in s."""
    try:
        import PyInstaller  # noqa: F401
    except ImportError:
        raise SystemExit('build: PyInstaller is missing: .venv/bin/pip install -e ".[installer]"') from None
    cmd = [sys.executable, "-m", "PyInstaller", "--noconfirm", "--log-level", "WARN",
           "--distpath", str(DIST), "--workpath", str(WORK), str(spec)]
    if clean:
        cmd.insert(3, "--clean")
    print("build:", " ".join(cmd), flush=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=ROOT, check=True)
    return time.perf_counter() - t0


def _pyinstaller_version() -> str:
    import PyInstaller

    return PyInstaller.__version__


def add_desktop_files(installer: Path = INSTALLER) -> None:
    """Linux: ``winder.desktop`` and ``install-desktop-entry.sh`` next to the executable."""
    shutil.copy2(installer / "winder.desktop", APP / "winder.desktop")
    script = APP / "install-desktop-entry.sh"
    shutil.copy2(installer / "install-desktop-entry.sh", script)
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
    ap.add_argument("--from-git", metavar="REV", help="build the committed sources of REV (e.g. HEAD), not the "
                    "working tree: what a clean clone would build")
    ap.add_argument("--if-stale", action="store_true",
                    help="do nothing if dist/winder was built from the current sources (and the archive exists)")
    args = ap.parse_args(argv)

    ver, tag = version(), platform_tag()
    if args.if_stale and not args.from_git and is_fresh(source_digest(),
                                                        None if args.no_archive else DIST / archive_name(ver, tag)):
        print(f"build: {APP.relative_to(ROOT)} is up to date with the sources (no rebuild)")
        return 0
    stage = stage_sources(args.from_git)
    digest = source_digest(stage)
    build_kernels(stage)
    print(f"build: sources of {args.from_git or 'the working tree'} staged in {stage.relative_to(ROOT)}", flush=True)
    ver = version(stage)
    t_build = run_pyinstaller(stage / "installer" / "winder.spec", clean=not args.no_clean)
    exe = APP / ("winder.exe" if os.name == "nt" else "winder")
    if not exe.exists():
        raise SystemExit(f"build: PyInstaller finished but {exe} is missing")
    if sys.platform.startswith("linux"):
        add_desktop_files(stage / "installer")
    size = tree_size(APP)
    info = {"version": ver, "platform": tag, "git_commit": git_commit(args.from_git or "HEAD"),
            "from_git": args.from_git, "source_digest": digest, "source_snapshot": str(stage),
            "python": platform.python_version(), "pyinstaller": _pyinstaller_version(),
            "build_seconds": round(t_build, 1), "size_bytes": size, "host_libraries": host_libraries(),
            "built_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (APP / "BUILD-INFO.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    print(f"build: {APP.relative_to(ROOT)} built in {t_build:.0f} s, {mib(size)} on disk", flush=True)
    if info["host_libraries"]:
        print("build: taken from the user's machine:", " ".join(info["host_libraries"]), flush=True)
    if not args.no_archive:
        arch = DIST / archive_name(ver, tag)
        t_arch = make_archive(arch)
        print(f"build: {arch.relative_to(ROOT)} {mib(arch.stat().st_size)} (packed in {t_arch:.0f} s)")
    print(f"build: try it:  {exe.relative_to(ROOT)} --version   (smoke test: make installer-test)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
