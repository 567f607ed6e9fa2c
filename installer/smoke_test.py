"""Smoke test of the frozen build (``make installer-test``): does ``dist/winder`` do what the source does?

::

    .venv/bin/python installer/smoke_test.py            # after installer/build.py
    .venv/bin/python installer/smoke_test.py --quick    # skip the slow STEP case and the X11 run

1. Sizes of ``dist/winder`` and its archive.
2. Start-up: ``winder --version`` and ``winder --selftest`` (offscreen: window shown, first mandrel
   plotted), frozen and from source, with the times.
3. The same CLI commands through the frozen and the source install, in the same scratch folder with
   the same relative paths; JSON outputs compared value by value (timing fields ignored), written
   files (NC program, STEP) compared as text (time stamps masked).  A command enters the list only
   if its sub-command exists in the source (``engine/cli/<name>.py``), so ``winder run`` is picked
   up as soon as it lands; a sub-command missing from the frozen build then fails (stale build).
4. Clean machine: the archive is unpacked into a temporary folder and run with ``env -i`` from
   another folder; as root (or with user namespaces) a private mount namespace also hides the
   source tree, the virtual environment and the build's Python installation behind empty tmpfs.
5. Under ``xvfb-run`` (if present): the selftest with the real X11/OpenGL 3D view (VTK).

Exit code 0 when everything passed, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "installer"))
from build import archive_name, mib, platform_tag, source_digest, tree_size, version  # noqa: E402

SOURCE_CMD = [sys.executable, "-m", "engine"]
CLEAN_PATH = "/usr/bin:/bin"
TIMEOUT_S = 600
VESSEL = "examples/pressure_vessel.toml"

# Keys whose values measure the computer, not the result.
VOLATILE_KEY = re.compile(r"^(compute|elapsed|wall|cpu)(_time)?_(s|ms)$")
# ISO-like time stamps (STEP headers, NC program comments).
TIMESTAMP = re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?")


@dataclass(frozen=True)
class Case:
    """One command run through both installs.  ``args`` are relative to the scratch folder."""

    label: str
    command: str  # the sub-command ('' for top-level options); gates the case on engine/cli/<command>.py
    args: tuple[str, ...]
    output: str | None = None  # a file the command writes, compared as text; else stdout as JSON
    slow: bool = False


ALL_CASES = (
    Case("mandrel (job)", "mandrel", ("mandrel", VESSEL, "--json")),
    Case("mandrel (DXF, ezdxf)", "mandrel", ("mandrel", "examples/vessel_profile.dxf", "--json")),
    Case("mandrel -> STEP (cadquery)", "mandrel", ("mandrel", VESSEL, "--step", "out.step"), output="out.step"),
    Case("mandrel (STEP in, OCP)", "mandrel", ("mandrel", "examples/vessel.step", "--json"), slow=True),
    Case("trajectory", "trajectory", ("trajectory", VESSEL, "--json")),
    Case("turning", "turning", ("turning", "--example", "paper", "--json")),
    Case("slot", "slot", ("slot", "--rho", "22", "--tool-radius", "-95", "--ratio", "-2", "--length", "2:20:2",
                          "--tol", "0.005", "--json")),
    Case("timeparam (tube)", "timeparam", ("timeparam", "--example", "--json")),
    Case("timeparam (TOPP-RA)", "timeparam", ("timeparam", "--example", "--method", "toppra", "--json")),
    Case("run -> NC", "run", ("run", VESSEL, "-o", "out.ngc"), output="out.ngc"),
)


def select_cases(root: Path = ROOT, quick: bool = False) -> list[Case]:
    """The cases whose sub-command exists in the source tree at ``root``."""
    cli = root / "engine" / "cli"
    return [c for c in ALL_CASES
            if (not c.command or (cli / f"{c.command}.py").is_file()) and not (quick and c.slow)]


def json_differences(a: object, b: object, where: str = "$", rel: float = 1e-9) -> tuple[list[str], int]:
    """Differences between two JSON values and the count of floats equal only to ``rel``.

    Keys matching :data:`VOLATILE_KEY` (run times) are skipped.
    """
    diffs: list[str] = []
    close = 0
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if VOLATILE_KEY.match(str(k)):
                continue
            if k not in a or k not in b:
                diffs.append(f"{where}.{k}: only in {'frozen' if k in b else 'source'}")
                continue
            d, c = json_differences(a[k], b[k], f"{where}.{k}", rel)
            diffs += d
            close += c
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.append(f"{where}: length {len(a)} != {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            d, c = json_differences(x, y, f"{where}[{i}]", rel)
            diffs += d
            close += c
    elif isinstance(a, float) and isinstance(b, float | int) and not isinstance(b, bool):
        if a != b:
            if math.isclose(a, b, rel_tol=rel, abs_tol=1e-12):
                close += 1
            else:
                diffs.append(f"{where}: {a!r} != {b!r}")
    elif a != b or type(a) is not type(b):
        diffs.append(f"{where}: {a!r} != {b!r}")
    return diffs, close


def mask_text(text: str) -> str:
    """``text`` with time stamps replaced, for comparing written files."""
    return TIMESTAMP.sub("<time>", text)


@dataclass
class Run:
    rc: int
    out: str
    err: str
    seconds: float


def run(cmd: Sequence[str], cwd: Path, env: dict[str, str] | None = None) -> Run:
    t0 = time.perf_counter()
    try:
        p = subprocess.run(list(cmd), cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        return Run(124, exc.stdout or "", f"timed out after {TIMEOUT_S} s", time.perf_counter() - t0)
    return Run(p.returncode, p.stdout, p.stderr, time.perf_counter() - t0)


def clean_env(**extra: str) -> dict[str, str]:
    """What ``env -i PATH=/usr/bin:/bin HOME=$HOME`` leaves, plus ``extra`` (Windows: the system folders)."""
    if os.name == "nt":
        sysroot = os.environ.get("SYSTEMROOT", r"C:\Windows")
        base = {"SYSTEMROOT": sysroot, "PATH": rf"{sysroot}\System32;{sysroot}",
                "USERPROFILE": os.environ.get("USERPROFILE", ""), "TEMP": tempfile.gettempdir()}
        return {**base, **extra}
    return {"PATH": CLEAN_PATH, "HOME": os.environ.get("HOME", "/tmp"), **extra}


def source_env(src: Path, **extra: str) -> dict[str, str]:
    """The environment of the source install: this Python with ``src`` (a source tree) first on the path."""
    env = dict(os.environ, **extra)
    env["PYTHONPATH"] = str(src)
    return env


SELFTEST_TIMES = re.compile(r"winder: (window|mandrel) shown after ([0-9.]+) s")


def selftest_times(stderr: str) -> dict[str, float]:
    """``{"window": s, "mandrel": s}`` from the lines ``winder --selftest`` prints."""
    return {m.group(1): float(m.group(2)) for m in SELFTEST_TIMES.finditer(stderr)}


@dataclass
class Report:
    lines: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    def ok(self, msg: str) -> None:
        self.lines.append(f"  ok    {msg}")
        print(f"smoke: ok    {msg}", flush=True)

    def fail(self, msg: str, detail: str = "") -> None:
        self.failures.append(msg)
        self.lines.append(f"  FAIL  {msg}")
        print(f"smoke: FAIL  {msg}", flush=True)
        if detail:
            print(textwrap_indent(detail.strip()[-3000:]), flush=True)

    def info(self, msg: str) -> None:
        self.lines.append(f"        {msg}")
        print(f"smoke:       {msg}", flush=True)


def textwrap_indent(s: str) -> str:
    return "\n".join("        | " + line for line in s.splitlines())


def check_startup(rep: Report, exe: Path, scratch: Path, src_root: Path) -> None:
    ver = version()
    fro = run([str(exe), "--version"], scratch, clean_env())
    src = run([*SOURCE_CMD, "--version"], scratch, source_env(src_root))
    if fro.rc == 0 and fro.out.strip() == f"winder {ver}" == src.out.strip():
        rep.ok(f"--version: {fro.out.strip()!r} in {fro.seconds:.2f} s (source {src.seconds:.2f} s)")
    else:
        rep.fail("--version", f"frozen rc={fro.rc} out={fro.out!r} err={fro.err}\nsource out={src.out!r}")
    for attempt in (1, 2):
        fro = run([str(exe), "--selftest"], scratch, clean_env(QT_QPA_PLATFORM="offscreen"))
        t = selftest_times(fro.err)
        if fro.rc != 0 or "mandrel" not in t:
            rep.fail("--selftest (offscreen)", f"rc={fro.rc}\n{fro.err}")
            return
        if attempt == 2:
            src = run([*SOURCE_CMD, "--selftest"], scratch, source_env(src_root, QT_QPA_PLATFORM="offscreen"))
            ts = selftest_times(src.err)
            rep.ok(f"--selftest (offscreen): window {t.get('window', math.nan):.2f} s, mandrel "
                   f"{t['mandrel']:.2f} s, exit {fro.seconds:.2f} s (source: {ts.get('window', math.nan):.2f} / "
                   f"{ts.get('mandrel', math.nan):.2f} / {src.seconds:.2f} s)")


def compare_case(rep: Report, case: Case, exe: Path, scratch: Path, src_root: Path) -> None:
    outs = {}
    for who, cmd, env in (("source", SOURCE_CMD, source_env(src_root)), ("frozen", [str(exe)], clean_env())):
        d = scratch / who
        if case.output:
            (d / case.output).unlink(missing_ok=True)
        r = run([*cmd, *case.args], d, env)
        if r.rc != 0:
            rep.fail(f"{case.label}: {who} exit code {r.rc}", f"$ winder {shlex.join(case.args)}\n{r.err}")
            return
        if case.output:
            p = d / case.output
            if not p.is_file():
                rep.fail(f"{case.label}: {who} wrote no {case.output}")
                return
            outs[who] = (p.read_text(encoding="utf-8", errors="replace"), r.seconds)
        else:
            outs[who] = (r.out, r.seconds)
    (src, t_src), (fro, t_fro) = outs["source"], outs["frozen"]
    timing = f"({t_fro:.1f} s frozen, {t_src:.1f} s source)"
    if case.output:
        a, b = mask_text(src), mask_text(fro)
        if a == b:
            rep.ok(f"{case.label}: {case.output} identical, {len(b.splitlines())} lines {timing}")
        else:
            import difflib

            diff = "".join(list(difflib.unified_diff(a.splitlines(True), b.splitlines(True), "source", "frozen"))[:40])
            rep.fail(f"{case.label}: {case.output} differs", diff)
        return
    try:
        ja, jb = json.loads(src), json.loads(fro)
    except json.JSONDecodeError as exc:
        rep.fail(f"{case.label}: output is not JSON ({exc})", fro[:500])
        return
    diffs, close = json_differences(ja, jb)
    if diffs:
        rep.fail(f"{case.label}: {len(diffs)} differences", "\n".join(diffs[:20]))
    else:
        note = f", {close} floats equal to 1e-9 only" if close else ", identical"
        rep.ok(f"{case.label}: JSON{note} {timing}")


def copy_examples(src_root: Path, dest: Path) -> None:
    shutil.copytree(src_root / "resources" / "examples", dest / "examples", dirs_exist_ok=True)


def namespace_prefix(hide: Sequence[Path]) -> tuple[list[str], str] | None:
    """A command prefix running its argument in a mount namespace where ``hide`` are empty."""
    mounts = "".join(f"mount -t tmpfs winder-hidden {shlex.quote(str(p))} && " for p in hide)
    script = mounts + 'exec "$@"'
    candidates = []
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        candidates.append((["unshare", "--mount", "--propagation", "private"], "root mount namespace"))
    candidates.append((["unshare", "--user", "--map-root-user", "--mount", "--propagation", "private"],
                       "user + mount namespace"))
    if not shutil.which("unshare"):
        return None
    for pre, how in candidates:
        cmd = [*pre, "sh", "-c", script, "sh"]
        probe = subprocess.run([*cmd, "true"], capture_output=True)
        if probe.returncode == 0:
            return cmd, how
    return None


def paths_to_hide() -> list[Path]:
    """The source tree, the virtual environment and the build's Python (unless it is the system one)."""
    hide = [ROOT, Path(sys.prefix), Path(sys.base_prefix)]
    out: list[Path] = []
    for p in hide:
        p = p.resolve()
        if str(p) in ("/", "/usr", "/usr/local", "/opt", "/home", "/root") or not p.is_dir():
            continue
        if any(p == q or p.is_relative_to(q) for q in out):
            continue
        out = [q for q in out if not q.is_relative_to(p)] + [p]
    return out


def check_clean_machine(rep: Report, archive: Path | None, app: Path, scratch: Path, src_root: Path) -> None:
    home = Path(tempfile.mkdtemp(prefix="winder-unpacked-"))
    try:
        if archive is not None and archive.suffix == ".gz":
            with tarfile.open(archive) as t:
                t.extractall(home, filter="tar")
            what = f"{archive.name} unpacked"
        else:
            shutil.copytree(app, home / "winder", symlinks=True)
            what = "dist/winder copied"
        exe = home / "winder" / "winder"
        elsewhere = home / "cwd"
        elsewhere.mkdir()
        copy_examples(src_root, elsewhere)
        hide = paths_to_hide()
        ns = namespace_prefix(hide)
        pre, how = ns if ns else ([], "")
        isolation = (f"{how}: {', '.join(map(str, hide))} hidden" if ns
                     else "NOT isolated (no unshare / namespaces): env -i and another folder only")
        rep.info(f"clean machine: {what} to {home}; {isolation}")

        r = run([*pre, str(exe), "--version"], elsewhere, clean_env())
        _verdict(rep, r, "clean env: --version", r.out.strip() == f"winder {version()}")
        r = run([*pre, str(exe), "--selftest"], elsewhere, clean_env(QT_QPA_PLATFORM="offscreen"))
        t = selftest_times(r.err)
        _verdict(rep, r, f"clean env: --selftest (mandrel shown after {t.get('mandrel', math.nan):.2f} s)",
                 "mandrel" in t)
        # The computations with the bundled resources (machine templates, cutting data, controllers).
        ref_dir = scratch / "source"
        for case in select_cases(src_root, quick=True):
            if case.command not in ("mandrel", "turning", "run"):
                continue
            if case.output:
                (elsewhere / case.output).unlink(missing_ok=True)
            r = run([*pre, str(exe), *case.args], elsewhere, clean_env())
            if case.output:
                got = (elsewhere / case.output).read_text() if (elsewhere / case.output).is_file() else ""
                want = (ref_dir / case.output).read_text() if (ref_dir / case.output).is_file() else None
                same = r.rc == 0 and want is not None and mask_text(got) == mask_text(want)
            else:
                want = run([*SOURCE_CMD, *case.args], ref_dir, source_env(src_root))
                same = r.rc == 0 and want.rc == 0 and not json_differences(json.loads(want.out), json.loads(r.out))[0]
            _verdict(rep, r, f"clean env: {case.label} same as source", same)
    finally:
        shutil.rmtree(home, ignore_errors=True)


def _verdict(rep: Report, r: Run, label: str, good: bool) -> None:
    if r.rc == 0 and good:
        rep.ok(f"{label} [{r.seconds:.2f} s]")
    else:
        rep.fail(label, f"rc={r.rc}\nstdout: {r.out[-1500:]}\nstderr: {r.err[-1500:]}")


def check_x11(rep: Report, exe: Path, scratch: Path, src_root: Path) -> None:
    """The selftest with the real 3D view (VTK/OpenGL) under a virtual X server."""
    if not shutil.which("xvfb-run"):
        rep.info("xvfb-run not found: real-GL selftest skipped")
        return
    inner = ('exec env -i PATH="$PATH" HOME="$HOME" DISPLAY="$DISPLAY" XAUTHORITY="$XAUTHORITY" '
             'PYTHONPATH="${PYTHONPATH:-}" QT_QPA_PLATFORM=xcb "$@"')
    xvfb = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", "sh", "-c", inner, "sh"]
    fro = run([*xvfb, str(exe), "--selftest"], scratch, clean_env())
    t = selftest_times(fro.err)
    if fro.rc == 0 and "mandrel" in t:
        rep.ok(f"--selftest under Xvfb with the VTK 3D view: mandrel shown after {t['mandrel']:.2f} s")
        return
    src = run([*xvfb, *SOURCE_CMD, "--selftest"], scratch,
              source_env(src_root, PATH=CLEAN_PATH))
    if src.rc != 0:
        rep.info(f"--selftest under Xvfb fails from source too (rc={src.rc}): not a packaging problem")
    else:
        rep.fail("--selftest under Xvfb (VTK 3D view) fails frozen, passes from source", fro.err)


def source_under_test(rep: Report, app: Path) -> Path:
    """The source tree to compare with: the build's snapshot (``build/source``) if intact, else the repository."""
    try:
        info = json.loads((app / "BUILD-INFO.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        rep.info("no BUILD-INFO.json: comparing with the working tree")
        return ROOT
    rep.info(f"build: {info.get('built_at')} in {info.get('build_seconds')} s from "
             f"{info.get('from_git') or 'the working tree'} (commit {str(info.get('git_commit'))[:10]})")
    snap = Path(str(info.get("source_snapshot", "")))
    digest = info.get("source_digest")
    if snap.is_dir() and source_digest(snap) == digest:
        live = "identical" if source_digest() == digest else "has changed since; not compared"
        rep.info(f"source install under test: the build's snapshot {snap} (the working tree {live})")
        return snap
    if source_digest() == digest:
        rep.info("source install under test: the working tree (identical to the build's sources)")
    else:
        rep.info("source install under test: the working tree, which CHANGED since the build: rebuild "
                 "(make installer) before reading differences as packaging bugs")
    return ROOT


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dist", type=Path, default=ROOT / "dist", help="folder holding winder/ and the archive")
    ap.add_argument("--quick", action="store_true", help="skip the slow STEP case and the Xvfb run")
    ap.add_argument("--no-isolation", action="store_true", help="skip the clean-machine run")
    args = ap.parse_args(argv)

    app = args.dist / "winder"
    exe = app / ("winder.exe" if os.name == "nt" else "winder")
    if not exe.is_file():
        print(f"smoke: {exe} is missing: build it first (make installer)", file=sys.stderr)
        return 1
    rep = Report()
    archive = args.dist / archive_name(version(), platform_tag())
    size = f"{app.name}/ {mib(tree_size(app))}"
    size += f", {archive.name} {mib(archive.stat().st_size)}" if archive.is_file() else ", no archive"
    rep.info(f"size: {size}")
    src_root = source_under_test(rep, app)

    scratch = Path(tempfile.mkdtemp(prefix="winder-smoke-"))
    try:
        for who in ("source", "frozen"):
            copy_examples(src_root, scratch / who)
        check_startup(rep, exe, scratch, src_root)
        for case in select_cases(src_root, quick=args.quick):
            compare_case(rep, case, exe, scratch, src_root)
        if not args.no_isolation:
            check_clean_machine(rep, archive if archive.is_file() else None, app, scratch, src_root)
        if not args.quick and sys.platform.startswith("linux"):
            check_x11(rep, exe, scratch, src_root)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    print("\nsmoke test summary")
    print("\n".join(rep.lines))
    if rep.failures:
        print(f"smoke: {len(rep.failures)} FAILED: " + "; ".join(rep.failures))
        return 1
    print("smoke: all passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
