"""Cheap invariants of the frozen build's recipe (installer/); the build itself is `make installer-test`."""

from __future__ import annotations

import ast
import configparser
import importlib.util
import os
import runpy
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
INSTALLER = ROOT / "installer"
SPEC = INSTALLER / "winder.spec"
HOOK = INSTALLER / "hooks" / "pyi_rth_winder.py"
DESKTOP = INSTALLER / "winder.desktop"
ICONS = ROOT / "resources" / "icons"


def _load(name: str) -> ModuleType:
    """Import ``installer/<name>.py`` (installer/ is not a package)."""
    if str(INSTALLER) not in sys.path:
        sys.path.insert(0, str(INSTALLER))
    spec = importlib.util.spec_from_file_location(f"winder_installer_{name}", INSTALLER / f"{name}.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _spec_constants() -> dict[str, object]:
    """The literal top-level assignments of the spec (it is Python, run by PyInstaller)."""
    tree = ast.parse(SPEC.read_text(encoding="utf-8"), filename=str(SPEC))
    out: dict[str, object] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            try:
                out[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                pass
    return out


def test_spec_parses_and_bundles_every_resource_dir() -> None:
    consts = _spec_constants()
    listed = set(consts["RESOURCE_DIRS"])
    present = {p.name for p in (ROOT / "resources").iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert present <= listed, f"resources/ folders missing from RESOURCE_DIRS in winder.spec: {present - listed}"
    assert {"machines", "controllers", "cutting", "examples", "icons"} <= listed


def test_spec_files_exist() -> None:
    consts = _spec_constants()
    assert (ROOT / str(consts["ENTRY"])).is_file()
    hooks = consts["RUNTIME_HOOKS"]
    assert isinstance(hooks, list) and hooks
    for h in hooks:
        assert (ROOT / h).is_file()
    assert (ROOT / str(consts["ICON_PNG"])).is_file()
    text = SPEC.read_text(encoding="utf-8")
    for needed in ('collect_submodules("engine")', 'collect_submodules("winder_gui")', '"vtkmodules.all"',
                   'CASADI_PLUGINS', 'HOST_LIBS', 'name="winder"'):
        assert needed in text


def test_entry_script_compiles_and_calls_the_cli() -> None:
    src = (INSTALLER / "winder_entry.py").read_text(encoding="utf-8")
    compile(src, "winder_entry.py", "exec")
    assert "from engine.cli import entry" in src and "entry()" in src


def test_runtime_hook_points_occt_at_the_bundle(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    res = tmp_path / "opencascade" / "resources"
    (res / "UnitsAPI").mkdir(parents=True)
    (res / "UnitsAPI" / "Lexi_Expr.dat").write_text("")
    monkeypatch.setattr(sys, "_MEIPASS", str(tmp_path), raising=False)
    monkeypatch.setenv("CASROOT", "/somewhere/else/occt-7.5")
    monkeypatch.setenv("CSF_ShadersDirectory", "/somewhere/else/occt-7.5/Shaders")
    monkeypatch.delenv("CSF_UnitsLexicon", raising=False)
    monkeypatch.delenv("CSF_OCCTResourcePath", raising=False)
    for name in ("CSF_UnitsDefinition", "CSF_SHMessage", "CSF_XSMessage", "CSF_STEPDefaults"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("FONTCONFIG_FILE", "/etc/fonts/fonts.conf")  # left alone when set
    runpy.run_path(str(HOOK))
    assert os.environ["CASROOT"] == str(tmp_path / "opencascade")
    assert os.environ["CSF_UnitsLexicon"] == str(res / "UnitsAPI" / "Lexi_Expr.dat")
    assert os.environ["CSF_OCCTResourcePath"] == str(res)
    assert "CSF_ShadersDirectory" not in os.environ  # the host's, for another OCCT, is dropped


def _desktop_entry() -> configparser.SectionProxy:
    cp = configparser.ConfigParser(interpolation=None, delimiters=("=",))
    cp.optionxform = str  # keys are case-sensitive
    cp.read_string(DESKTOP.read_text(encoding="utf-8"))
    assert cp.sections()[0] == "Desktop Entry"
    return cp["Desktop Entry"]


def test_desktop_entry_is_valid() -> None:
    tool = shutil.which("desktop-file-validate")
    if tool:
        r = subprocess.run([tool, str(DESKTOP)], capture_output=True, text=True)
        assert r.returncode == 0 and not r.stdout.strip(), r.stdout + r.stderr
    e = _desktop_entry()
    assert e["Type"] == "Application"
    assert e["Name"] and e["Exec"].split()[0] == "winder"
    assert e["Terminal"] == "false"
    for key in ("Categories", "MimeType", "Keywords"):
        assert e[key].endswith(";"), key
    assert (ICONS / f"{e['Icon']}.svg").is_file() and (ICONS / f"{e['Icon']}.png").is_file()


def test_icons_are_well_formed() -> None:
    root = ET.parse(ICONS / "winder.svg").getroot()
    assert root.tag.endswith("svg") and root.get("viewBox") == "0 0 256 256"
    png = (ICONS / "winder.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (width, height) == (256, 256)


def test_install_script_rewrites_exec() -> None:
    text = (INSTALLER / "install-desktop-entry.sh").read_text(encoding="utf-8")
    assert text.startswith("#!/bin/sh") and "s|^Exec=.*|Exec=" in text and "--remove" in text


def test_archive_name_and_version() -> None:
    build = _load("build")
    from engine import __version__

    assert build.version() == __version__
    assert build.archive_name("0.1.0", build.platform_tag("Linux", "x86_64")) == "winder-0.1.0-linux-x86_64.tar.gz"
    assert build.archive_name("0.1.0", build.platform_tag("Windows", "AMD64")) == "winder-0.1.0-windows-amd64.zip"
    assert build.platform_tag("Darwin", "arm64") == "macos-arm64"


def test_smoke_cases_follow_the_cli(tmp_path: Path) -> None:
    smoke = _load("smoke_test")
    cli = tmp_path / "engine" / "cli"
    cli.mkdir(parents=True)
    (cli / "mandrel.py").write_text("")
    names = {c.command for c in smoke.select_cases(tmp_path)}
    assert names == {"mandrel"}
    (cli / "run.py").write_text("")  # `winder run` lands: its NC output is compared automatically
    cases = smoke.select_cases(tmp_path)
    assert any(c.command == "run" and c.output and c.output.endswith(".ngc") for c in cases)
    real = {c.command for c in smoke.select_cases(ROOT)}
    assert real == {c.command for c in smoke.ALL_CASES if (ROOT / "engine" / "cli" / f"{c.command}.py").is_file()}


def test_smoke_json_comparison() -> None:
    smoke = _load("smoke_test")
    a = {"total_time_s": 6.5, "compute_s": 0.9, "rows": [1.0, 2.0], "name": "x"}
    assert smoke.json_differences(a, dict(a, compute_s=1.7)) == ([], 0)  # run time ignored
    diffs, _ = smoke.json_differences(a, dict(a, total_time_s=6.6))  # a result is not
    assert diffs == ["$.total_time_s: 6.5 != 6.6"]
    assert smoke.json_differences(a, dict(a, rows=[1.0, 2.0 * (1 + 1e-12)])) == ([], 1)
    assert smoke.json_differences(a, dict(a, rows=[1.0]))[0]
    assert smoke.mask_text("FILE_NAME('x','2026-11-22T08:01:02',") == smoke.mask_text(
        "FILE_NAME('x','2025-01-02T03:04:05',")
    assert smoke.selftest_times("winder: window shown after 0.812 s\nwinder: mandrel shown after 0.905 s\n") == {
        "window": 0.812, "mandrel": 0.905}


def test_resource_path_source_and_frozen(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from engine.resources import resource_path, resources_root

    assert resources_root() == ROOT / "resources"
    assert resource_path("machines", "lathe4.toml").is_file()
    monkeypatch.setattr(sys, "frozen", True, raising=False)
    monkeypatch.setattr(sys, "_MEIPASS", str(tmp_path), raising=False)
    assert resource_path("controllers") == tmp_path / "resources" / "controllers"


def test_source_digest_tells_stale_builds(tmp_path: Path) -> None:
    build = _load("build")
    for d in build.SOURCE_DIRS:
        (tmp_path / d / "__pycache__").mkdir(parents=True)
        (tmp_path / d / "a.py").write_text("x = 1\n")
    before = build.source_digest(tmp_path)
    (tmp_path / "engine" / "__pycache__" / "a.cpython-311.pyc").write_bytes(b"\0")  # byte code: not a source
    assert build.source_digest(tmp_path) == before
    (tmp_path / "engine" / "cli.py").write_text("NAME = 'run'\n")  # a new sub-command: stale
    assert build.source_digest(tmp_path) != before


def test_host_library_filter() -> None:
    import re

    tree = ast.parse(SPEC.read_text(encoding="utf-8"))
    patterns = [n.args[0].value for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, "attr", "") == "compile" and n.args and isinstance(n.args[0], ast.Constant)]
    assert len(patterns) == 1
    host = re.compile(patterns[0])
    for name in ("libGL.so.1", "libEGL.so.1", "libX11.so.6", "libX11-xcb.so.1", "libxcb.so.1", "libXext.so.6",
                 "libstdc++.so.6", "libgcc_s.so.1", "libglib-2.0.so.0", "libdbus-1.so.3", "libgtk-3.so.0",
                 "libwayland-client.so.0"):
        assert host.match(name), name
    for name in ("libXau-154567c4.so.6.0.0", "libxcb-9065bb12.so.1.1.0", "libxcb-cursor.so.0", "libxkbcommon.so.0",
                 "libfontconfig.so.1", "libpython3.11.so.1.0", "libvtkx11.so", "libQt6XcbQpa.so.6",
                 "libgfortran-8f1e9814.so.5.0.0", "libcasadi.so.3.7"):
        assert not host.match(name), name
