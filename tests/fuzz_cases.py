"""A seeded, bounded mutation fuzzer of the ``winder`` command line (issue 19).

Inputs: job files (TOML), generatrix profiles (CSV, DXF, STEP), time-law paths (``.npz``) and limits,
and command-line arguments, each a random mutation of a valid example (numbers replaced by extremes,
lines deleted or duplicated, text truncated or spliced with bytes, kinds and types swapped, deep
nesting, huge tables).  Every case runs ``engine.cli.main(argv)`` in a worker process (one Python
for many cases: no start-up cost per case); the driver kills and restarts the worker when a case
hangs or crashes it.  For every case it checks:

* exit code 0, 1 or 2 (argparse's usage error is 2);
* no traceback (an exception escaping ``main``), no Python warning line (``RuntimeWarning: ...``);
* finished within ``time_budget_s`` of CPU time (a wall-clock limit of 3x that + 30 s catches hangs);
* peak memory (VmHWM of the worker, reset before each case) within ``memory_budget_bytes``;
* no partial output: no temporary file left beside the outputs, nothing written on exit code 2, and
  a previous output file unchanged unless the command succeeded.

Used by ``tests/test_fuzz.py`` (a fixed seed and a 90 s budget in CI) and by
``benchmarks/fuzz_winder.py`` (thousands of cases, counts printed).
"""

from __future__ import annotations

import io
import json
import os
import random
import re
import select
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"

EXTREMES = ["0", "-1", "1e-9", "1e-300", "1e308", "-1e308", "1e9", "1e12", "nan", "inf", "-inf", "0.0001",
            "9223372036854775807", "18446744073709551616", "1" + "0" * 40, '"x"', "[]", "{}", "true", "-0.0",
            "5000", "1e6", "3", "100000", "[1e308, 1e308]", "[0, 0]", "[-1, 5]", '"1e9"', "1e-6", "2.5"]

JOB_FIELDS = {
    "mandrel": ["radius_mm", "cylinder_length_mm", "length_mm", "r0_mm", "r1_mm", "pole_radius_mm", "dome_ratio",
                "body_length_mm", "waist_radius_mm", "neck_radius_mm", "kind", "z_mm", "r_mm"],
    "band": ["width_mm", "thickness_mm", "friction"],
    "winding": ["points_per_pass", "circuits", "pattern_p", "pattern_q", "layers", "dwell_deg", "pole_c_mm", "mode",
                "close_by", "lead"],
    "payout": ["law", "clearance_mm", "eye_radius_mm", "free_length_max_mm", "grid_points", "u_min",
               "free_length_mm", "offset_mm", "impregnation_k", "workspace_r_mm", "workspace_z_mm"],
    "machine": ["template"],
    "timelaw": ["method", "levels", "penalty", "tube_share", "stop_percent", "sweep", "sdot_max", "sddot_max"],
    "post": ["post", "controller", "tolerance_mm", "min_block_time_s"],
}
STRINGS = ['"vessel"', '"pipe"', '"points"', '"file"', '"cone"', '"bottle"', '"lathe9"', '""', '"../../etc/passwd"',
           '"geodesic"', '"minimax"', '"angle"', '"parallel"', '"curve"', '"dp"', '"toppra"', '"gcode"', '"csv"',
           '"marlin"', '"robot_cell"', '"gantry6"', '"lathe4"']

SMALL_PIPE = """schema_version = 1
name = "fuzz pipe"
[mandrel]
kind = "pipe"
radius_mm = 40.0
length_mm = 200.0
[band]
width_mm = 10.0
thickness_mm = 0.4
friction = 0.2
[winding]
mode = "geodesic"
points_per_pass = 100
dwell_deg = [180.0, 180.0]
[[winding.angles]]
z_mm = 100.0
angle_deg = 55.0
[payout]
law = "min-range"
grid_points = 200
[machine]
template = "lathe2"
[machine.axes.X]
max = 1800.0
[timelaw]
method = "blocks"
[post]
post = "linuxcnc"
"""

SMALL_VESSEL = """schema_version = 1
name = "fuzz vessel"
[mandrel]
kind = "vessel"
radius_mm = 50.0
cylinder_length_mm = 100.0
dome = "isotensoid"
pole_radius_mm = [15.0, 20.0]
[band]
width_mm = 10.0
thickness_mm = 0.3
friction = 0.2
[winding]
mode = "auto"
points_per_pass = 100
[payout]
law = "min-range"
grid_points = 200
[machine]
template = "lathe4"
[timelaw]
method = "tube"
levels = 40
[post]
post = "fanuc"
"""

FILE_JOB = """schema_version = 1
name = "fuzz profile"
[mandrel]
kind = "file"
path = "{profile}"
[band]
width_mm = 10.0
[winding]
points_per_pass = 100
[payout]
grid_points = 200
[machine]
template = "lathe4"
[timelaw]
method = "blocks"
"""

SMALL_LAYERED = """schema_version = 2
name = "fuzz laminate"
[mandrel]
kind = "pipe"
radius_mm = 40.0
length_mm = 200.0
[band]
width_mm = 10.0
thickness_mm = 0.4
friction = 0.2
[winding]
mode = "geodesic"
points_per_pass = 100
dwell_deg = [180.0, 180.0]
[[winding.angles]]
z_mm = 100.0
angle_deg = 55.0
[payout]
law = "min-range"
grid_points = 200
[machine]
template = "lathe2"
[machine.axes.X]
max = 1800.0
[timelaw]
method = "blocks"
[post]
post = "linuxcnc"
[[layer]]
kind = "hoop"
name = "inner hoop"
passes = 1
[[layer]]
kind = "helical"
name = "helical 55"
repeat = 1
[[layer]]
kind = "skip"
angle_deg = 30.0
[[layer]]
kind = "hoop"
name = "outer hoop"
terminal = true
"""

SMALL_LAYERED_VESSEL = """schema_version = 2
name = "fuzz vessel laminate"
[mandrel]
kind = "vessel"
radius_mm = 50.0
cylinder_length_mm = 100.0
dome = "isotensoid"
pole_radius_mm = [15.0, 20.0]
[band]
width_mm = 10.0
thickness_mm = 0.3
friction = 0.2
[winding]
mode = "auto"
points_per_pass = 100
[payout]
law = "min-range"
grid_points = 200
[machine]
template = "lathe4"
[timelaw]
method = "blocks"
[post]
post = "fanuc"
[[layer]]
kind = "polar"
name = "polar"
[[layer]]
kind = "hoop"
name = "hoop"
[layer.band]
width_mm = 8.0
"""

LAYER_ATTACKS = [("passes", ["1000", "1000000", "0", "-1", "1e308", "500"]),
                 ("repeat", ["1000", "1000000000", "0", "999"]),
                 ("z_range_mm", ["[-1e6, 1e6]", "[500, 900]", "[100, 100]", "[1e308, -1e308]", "[nan, 5]",
                                 "[-50, 10]"]),
                 ("overlap", ["0.999999", "1", "-0.5", "nan"]),
                 ("points_per_turn", ["2000", "8", "1e9", "7"]),
                 ("angle_deg", ["1e308", "-1e308", "1e-300", "89.9999999", "0.0000001", "nan", "720000"]),
                 ("circuits", ["1000000000", "100000", "1"]),
                 ("pattern_p", ["1000000000000", "997", "50000"]),
                 ("points_per_pass", ["200000", "50"]),
                 ("dwell_deg", ["[1e308, 1e308]", "[1e6, 0]", "[3600, 3600]"]),
                 ("lead_in_mm", ["1e308", "1e9", "-1"]),
                 ("lead_out_deg", ["1e308", "1e9", "3600000"]),
                 ("pole_c_mm", ["[1e6, 1e6]", "[0, 0]", "[39.999, 39.999]"]),
                 ("kind", ['"hoop"', '"polar"', '"skip"', '"helical"', '"bogus"', "3"]),
                 ("enabled", ["false", "0", '"yes"']),
                 ("terminal", ["true", "1"]),
                 ("band", ["{ width_mm = 1e-9 }", "{ width_mm = 1e6 }", "{ thickness_mm = 1e308 }",
                           "{ width_mm = 0.001, thickness_mm = 1e-9 }", "{ tows = 1000 }", "{ friction = 1e-9 }",
                           "{ width_mm = 100 }", "{ nosuch = 1 }"])]


def mutate_layers(text: str, rng: random.Random) -> str:
    """Mutations of the ``[[layer]]`` tables: a field of one layer set to an extreme (huge passes or
    repeat, an absurd band, a hoop range outside the mandrel, a skip of 1e308 deg), layers duplicated
    many times or all removed."""
    x = rng.random()
    if x < 0.12:  # many layers: a long laminate (every copy is a layer to wind)
        n = rng.choice([50, 2000, 100_000, 1_000_000])
        layer = rng.choice(['[[layer]]\nkind = "skip"\nangle_deg = 1.0\n', '[[layer]]\nkind = "hoop"\n',
                            '[[layer]]\nkind = "helical"\n'])
        return text + layer * n
    if x < 0.16:
        return re.sub(r"(?ms)^\[\[layer\]\].*", "", text) + "[[layer]]\n"
    starts = [m.start() for m in re.finditer(r"(?m)^\[\[layer\]\]$", text)]
    if not starts:
        return text + "[[layer]]\nkind = \"hoop\"\n"
    k = rng.randrange(len(starts))
    key, vals = rng.choice(LAYER_ATTACKS)
    val = rng.choice(vals)
    end = starts[k + 1] if k + 1 < len(starts) else len(text)
    block = text[starts[k]:end]
    if key == "band" and "[layer.band]" in block:
        block = block.split("[layer.band]")[0]
    if re.search(rf"(?m)^{key}\s*=", block):
        block = re.sub(rf"(?m)^{key}\s*=.*$", f"{key} = {val}", block, count=1)
    else:
        block = block.replace("[[layer]]\n", f"[[layer]]\n{key} = {val}\n", 1)
    return text[:starts[k]] + block + text[end:]


NC_PROGRAM = """%
(fuzz program)
G21 G90 G94
G0 X0 Y0 Z0
G1 X10 Y90 F1000
G1 X20 Y180 Z5 F1200
G1 X30 Y270 Z0 F900
G1 X40 Y360 F1000
M2
%
"""

LIMITS = """v_max = [100.0, 50.0]
a_max = [500.0, 300.0]
levels = 40
"""


@dataclass
class Case:
    """One fuzz input: files to create in a fresh folder, the arguments (``{d}`` = that folder)."""

    name: str
    argv: list[str]
    files: dict[str, bytes] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    previous: dict[str, bytes] = field(default_factory=dict)  # outputs that exist before the run


@dataclass
class Outcome:
    """What happened to one case, and the checks it broke (``problems``: kind -> detail)."""

    case: str
    argv: list[str]
    rc: int | None = None
    elapsed_s: float = 0.0
    cpu_s: float = 0.0
    peak_rss: int = 0
    stderr: str = ""
    problems: dict[str, str] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------
# Mutators
# ------------------------------------------------------------------------------------------------
def _set_field(text: str, rng: random.Random) -> str:
    sec = rng.choice(list(JOB_FIELDS))
    key = rng.choice(JOB_FIELDS[sec])
    val = rng.choice(EXTREMES + STRINGS if rng.random() < 0.3 else EXTREMES)
    lines = text.splitlines()
    cur = ""
    for i, ln in enumerate(lines):
        m = re.match(r"^\[([^\]]+)\]", ln)
        if m:
            cur = m.group(1)
        elif cur == sec and re.match(rf"^{re.escape(key)}\s*=", ln):
            lines[i] = f"{key} = {val}"
            return "\n".join(lines) + "\n"
    for i, ln in enumerate(lines):  # absent: add it under the section header
        if ln.strip() == f"[{sec}]":
            lines.insert(i + 1, f"{key} = {val}")
            return "\n".join(lines) + "\n"
    return text + f"\n[{sec}]\n{key} = {val}\n"


def _mutate_text(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    op = rng.randrange(8)
    if op == 0 and lines:
        del lines[rng.randrange(len(lines))]
    elif op == 1 and lines:
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif op == 2:
        return text[: rng.randrange(len(text) + 1)]
    elif op == 3:
        i = rng.randrange(len(text) + 1)
        junk = "".join(chr(rng.randrange(1, 0x2FF)) for _ in range(rng.randrange(1, 12)))
        return text[:i] + junk + text[i:]
    elif op == 4:
        nums = list(re.finditer(r"-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?", text))
        if nums:
            m = rng.choice(nums)
            return text[: m.start()] + rng.choice(EXTREMES[:15]) + text[m.end():]
    elif op == 5 and lines:
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif op == 6:
        depth = rng.choice([10, 70, 300, 3000])
        lines.append("deep = " + "[" * depth + "]" * depth)
    else:
        lines.append(rng.choice(["[[layer]]", "[mandrel]", "x = 1", "[winding]\nlayers = 2", "schema_version = 7",
                                 "name = '" + "n" * 5000 + "'"]))
    return "\n".join(lines) + "\n"


SIZE_ATTACKS = [("winding", "circuits", ["1e9", "1000000000000", "100000", "3000"]),
                ("winding", "pattern_p", ["1000000000", "1e12", "50000", "997"]),
                ("winding", "layers", ["1000000", "1e6", "5000", "40"]),
                ("winding", "points_per_pass", ["200000", "199999", "50"]),
                ("winding", "dwell_deg", ["[1e308, 1e308]", "[1e6, 0]", "[3600, 3600]"]),
                ("band", "width_mm", ["1e-9", "1e-300", "0.001", "1e6"]),
                ("mandrel", "radius_mm", ["1e6", "1e-6", "1e308", "100000"]),
                ("mandrel", "cylinder_length_mm", ["1e6", "1e308", "0"]),
                ("mandrel", "length_mm", ["1e6", "1e-9", "1e308"]),
                ("payout", "grid_points", ["100000", "50"]),
                ("payout", "clearance_mm", ["1e308", "1e6", "0"]),
                ("timelaw", "levels", ["5000", "4096", "2000"]),
                ("timelaw", "method", ['"tube"', '"dp"', '"toppra"']),
                ("post", "min_block_time_s", ["1e308", "1e-300", "100"]),
                ("post", "tolerance_mm", ["1e308", "1e-300", "1e-9"]),
                ("band", "friction", ["1e-9", "0", "1e308"])]


def _size_attack(text: str, rng: random.Random) -> str:
    sec, key, vals = rng.choice(SIZE_ATTACKS)
    lines = text.splitlines()
    cur = ""
    for i, ln in enumerate(lines):
        m = re.match(r"^\[([^\]]+)\]", ln)
        if m:
            cur = m.group(1)
        elif cur == sec and re.match(rf"^{re.escape(key)}\s*=", ln):
            lines[i] = f"{key} = {rng.choice(vals)}"
            return "\n".join(lines) + "\n"
    for i, ln in enumerate(lines):
        if ln.strip() == f"[{sec}]":
            lines.insert(i + 1, f"{key} = {rng.choice(vals)}")
            return "\n".join(lines) + "\n"
    return text


def mutate_job(text: str, rng: random.Random) -> str:
    """One to three mutations of a job document: a size attack (a count, a length or a band width
    far out of range), a field set to an extreme value, or a textual mutation."""
    for _ in range(rng.randint(1, 3)):
        x = rng.random()
        text = _size_attack(text, rng) if x < 0.4 else _set_field(text, rng) if x < 0.75 else _mutate_text(text, rng)
    return text


def _mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    op = rng.randrange(5)
    if op == 0:
        return data[: rng.randrange(len(data) + 1)]
    if op == 1:
        b = bytearray(data)
        for _ in range(rng.randint(1, 20)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if op == 2:
        i = rng.randrange(len(data) + 1)
        return data[:i] + os.urandom(rng.randint(1, 64)) + data[i:]
    if op == 3:
        i, j = sorted((rng.randrange(len(data) + 1), rng.randrange(len(data) + 1)))
        return data[:i] + data[j:]
    i, j = sorted((rng.randrange(len(data) + 1), rng.randrange(len(data) + 1)))
    return data[:j] + data[i:j] + data[j:]


def mutate_profile(data: bytes, rng: random.Random) -> bytes:
    """A CSV/DXF/STEP profile: numbers replaced by extremes, lines dropped, bytes flipped or spliced."""
    if rng.random() < 0.6:
        text = data.decode("utf-8", "replace")
        for _ in range(rng.randint(1, 3)):
            text = _mutate_text(text, rng) if rng.random() < 0.5 else _replace_numbers(text, rng)
        return text.encode("utf-8", "replace")
    return _mutate_bytes(data, rng)


def _replace_numbers(text: str, rng: random.Random) -> str:
    nums = list(re.finditer(r"-?\d+\.\d+(?:[eE][+-]?\d+)?", text))
    for m in sorted(rng.sample(nums, min(len(nums), rng.randint(1, 4))), key=lambda m: -m.start()):
        text = text[: m.start()] + rng.choice(["nan", "1e308", "-1e308", "0.0", "1e-300", "-5.0", "1e12", "inf",
                                               "12345678.9"]) + text[m.end():]
    return text


def dense_csv(n: int, rng: random.Random) -> bytes:
    """A generatrix table of ``n`` points (a scanned profile), r = 50 + 5 sin."""
    import numpy as np

    z = np.linspace(0.0, 300.0, n)
    r = 50.0 + 5.0 * np.sin(z / 30.0) + rng.choice([0.0, 1e-6]) * np.cos(z)
    buf = io.StringIO()
    buf.write("z_mm,r_mm\n")
    np.savetxt(buf, np.column_stack([z, r]), delimiter=",", fmt="%.9f")
    return buf.getvalue().encode()


def npz_bytes(rng: random.Random, mutate: bool) -> bytes:
    """A time-law path ``s, X, dX, ddX`` (p = 2), valid or mutated."""
    import numpy as np

    n = 60
    s = np.linspace(0.0, 100.0, n)
    X = np.column_stack([np.sin(s / 20), s])
    dX = np.column_stack([np.cos(s / 20) / 20, np.ones(n)])
    ddX = np.column_stack([-np.sin(s / 20) / 400, np.zeros(n)])
    arrs: dict[str, Any] = {"s": s, "X": X, "dX": dX, "ddX": ddX}
    if mutate:
        op = rng.randrange(9)
        k = rng.choice(list(arrs))
        if op == 0:
            arrs[k] = arrs[k].copy()
            arrs[k].flat[rng.randrange(arrs[k].size)] = rng.choice([np.nan, np.inf, -np.inf, 1e308])
        elif op == 1:
            arrs[k] = arrs[k].reshape(-1)[: rng.randrange(1, 200)]
        elif op == 2:
            arrs[k] = np.array(["a", "b"])
        elif op == 3:
            del arrs[k]
        elif op == 4:
            arrs[k] = np.zeros((2, 3, 4))
        elif op == 5:
            arrs["s"] = arrs["s"][::-1].copy()
        elif op == 6:
            arrs[k] = np.array(3.0)
        elif op == 7:
            arrs[k] = np.zeros((n, rng.choice([0, 40])))
        else:
            buf = io.BytesIO()
            np.savez(buf, **arrs)
            return _mutate_bytes(buf.getvalue(), rng)
    buf = io.BytesIO()
    np.savez(buf, **arrs)
    return buf.getvalue()


def npz_bomb() -> bytes:
    """An .npz whose array header claims 10^12 float64 values (8 TB) over a few bytes of data."""
    hdr = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000,), }"
    hdr = hdr + " " * (63 - len(hdr) % 64) + "\n"
    npy = b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little") + hdr.encode() + b"\0" * 64
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k in ("s", "X", "dX", "ddX"):
            zf.writestr(f"{k}.npy", npy)
    return buf.getvalue()


# ------------------------------------------------------------------------------------------------
# Cases
# ------------------------------------------------------------------------------------------------
def _out(rng: random.Random, name: str) -> tuple[str, bool]:
    """An output argument: mostly a fresh file, sometimes a folder, a missing folder, a weird name."""
    x = rng.random()
    if x < 0.75:
        return "{d}/" + name, True
    return rng.choice(["{d}", "{d}/missing/" + name, "{d}/" + "n" * 300 + name[-4:], "{d}/sub/../" + name,
                       "/proc/version"]), False


def make_case(i: int, rng: random.Random, heavy: bool = True) -> Case:
    """Case ``i``: a random kind (job, profile, npz, arguments), random mutations."""
    kinds = (["job"] * 6 + ["layered"] * 6 + ["csv"] * 3 + ["dxf"] * 2 + ["npz"] * 2 + ["args"] * 3 + ["nc"]
             + (["step"] if heavy else []))
    kind = rng.choice(kinds)
    name = f"{i:05d}-{kind}"
    files: dict[str, bytes] = {}
    outputs: list[str] = []
    previous: dict[str, bytes] = {}
    if kind == "job":
        base = rng.choice([SMALL_PIPE, SMALL_VESSEL])
        files["job.toml"] = mutate_job(base, rng).encode("utf-8", "replace")
        cmd = rng.choice(["run", "run", "trajectory", "payout", "mandrel"])
        argv = [cmd, "{d}/job.toml"]
        if cmd == "run":
            o, ok = _out(rng, "out.ngc")
            argv += ["-o", o, "--quiet"]
            if ok:
                outputs.append("out.ngc")
                if rng.random() < 0.3:
                    previous["out.ngc"] = b"G0 X0 ; the previous program\n"
            if rng.random() < 0.3:
                argv += ["--report", "{d}/report.json"]
                outputs.append("report.json")
            if rng.random() < 0.1:
                argv.append("--force")
        elif cmd in ("trajectory", "payout"):
            argv.append("--json")
            if rng.random() < 0.4:
                o, ok = _out(rng, "line.csv")
                argv += ["--csv", o]
                outputs += ["line.csv"] if ok else []
        else:
            argv.append("--json")
    elif kind == "layered":
        text = rng.choice([SMALL_LAYERED, SMALL_LAYERED_VESSEL])
        for _ in range(rng.randint(1, 2)):
            text = mutate_layers(text, rng)
        if rng.random() < 0.3:
            text = mutate_job(text, rng)
        files["job.toml"] = text.encode("utf-8", "replace")
        cmd = rng.choice(["run", "run", "layup", "layup", "report", "trajectory"])
        argv = [cmd, "{d}/job.toml"]
        if cmd == "run":
            o, ok = _out(rng, "out.ngc")
            argv += ["-o", o, "--quiet"]
            outputs += ["out.ngc"] if ok else []
            if ok and rng.random() < 0.3:
                previous["out.ngc"] = b"G0 X0 ; the previous program\n"
            if rng.random() < 0.1:
                argv.append("--force")
        elif cmd == "layup":
            argv += ["--json"] + (["--no-program"] if rng.random() < 0.3 else [])
            if rng.random() < 0.3:
                o, ok = _out(rng, "t.csv")
                argv += ["--thickness", o]
                outputs += ["t.csv"] if ok else []
        elif cmd == "report":
            o, ok = _out(rng, "r.html")
            argv += ["-o", o, "--quiet"]
            outputs += ["r.html"] if ok else []
        else:
            argv.append("--json")
    elif kind == "nc":
        prog = NC_PROGRAM
        for _ in range(rng.randint(1, 3)):
            prog = _mutate_text(prog, rng)
        if rng.random() < 0.1:
            prog = "G1 X1 Y1 F100\nG1 X2 Y2\n" * rng.choice([1000, 200_000])
        files["prog.ngc"] = prog.encode("utf-8", "replace")
        argv = ["simulate", "{d}/prog.ngc", "--json", "--machine", rng.choice(["lathe2", "lathe4", "nosuch", ""])]
        if rng.random() < 0.3:
            files["job.toml"] = mutate_job(SMALL_PIPE, rng).encode("utf-8", "replace")
            argv += ["--job", "{d}/job.toml"]
    elif kind in ("csv", "dxf", "step"):
        src = {"csv": EXAMPLES / "bottle_profile.csv", "dxf": EXAMPLES / "vessel_profile.dxf",
               "step": EXAMPLES / "vessel.step"}[kind]
        data = src.read_bytes()
        if kind == "csv" and rng.random() < 0.1:
            data = dense_csv(rng.choice([5_000, 50_000] + ([300_000] if heavy else [])), rng)
        elif rng.random() < 0.9:
            data = mutate_profile(data, rng)
        files[f"profile.{kind}"] = data
        if rng.random() < 0.5:
            argv = ["mandrel", f"{{d}}/profile.{kind}", "--json"]
            if rng.random() < 0.2:
                argv += ["--stl", "{d}/m.stl", "--stl-tolerance", rng.choice(["0.05", "1e-9", "nan", "-1", "10"])]
                outputs.append("m.stl")
        else:
            files["job.toml"] = FILE_JOB.format(profile=f"profile.{kind}").encode()
            argv = [rng.choice(["trajectory", "run"]), "{d}/job.toml"]
            if argv[0] == "run":
                argv += ["-o", "{d}/out.ngc", "--quiet"]
                outputs.append("out.ngc")
    elif kind == "npz":
        files["path.npz"] = npz_bomb() if rng.random() < 0.1 else npz_bytes(rng, rng.random() < 0.85)
        limits = LIMITS if rng.random() < 0.6 else mutate_job(LIMITS, rng).replace("[mandrel]", "")
        files["limits.toml"] = limits.encode()
        argv = ["timeparam", "{d}/path.npz", "--limits", "{d}/limits.toml", "--json",
                "--method", rng.choice(["tube", "dp", "toppra"])]
        if rng.random() < 0.3:
            argv += ["--levels", rng.choice(["2", "5000", "-3", "100", "4096"])]
        if rng.random() < 0.3:
            o, ok = _out(rng, "law.npz")
            argv += ["--npz-out", o]
            outputs += ["law.npz"] if ok else []
    else:
        files["job.toml"] = SMALL_PIPE.encode()
        argv = rng.choice([
            ["mandrel", "{d}/job.toml", "--stl", "{d}/m.stl", "--stl-tolerance", rng.choice(EXTREMES[:12])],
            ["payout", "{d}/job.toml", "--points", rng.choice(["0", "-5", "1e9", "49", "100001", "x"]), "--json"],
            ["payout", "{d}/job.toml", "--k", rng.choice(["0", "1", "7"]), "--law", rng.choice(
                ["parallel", "equidistant", "equal-tangent", "curve", "min-range", "bogus"])],
            ["run", "{d}/job.toml", "-o", "{d}/o.ngc", "--post", rng.choice(["", "gcode", "csv", "x" * 100]),
             "--quiet", "--max-memory", rng.choice(["1G", "0", "-1", "1e30", "garbage", "64M", "100k"])],
            ["timeparam", "--example", "--levels", rng.choice(["2", "4096", "4097", "0", "99999999999"]), "--json"],
            ["slot", "--rho", rng.choice(["22", "0", "-1", "1e308", "nan"]), "--tool-radius",
             rng.choice(["-95", "0", "1e308", "inf"]), "--ratio", rng.choice(["-2", "0", "1e9"]),
             "--length", rng.choice(["2:20:2", "1:1e9:1e-9", "0:0:0", "a:b:c", "20:2:2"]), "--json"],
            ["turning", "--example", rng.choice(["paper", "nosuch", ""]), "--json"],
            ["turning", "--example", "paper", "--set", rng.choice(["a.b=1e308", "x=y", "=", "material.k=nan"])],
            [rng.choice(["nosuch", "run", "--version", "-h", "mandrel"])],
        ])
        if argv[0] == "run" and len(argv) > 3:
            outputs.append("o.ngc")
        if argv[:2] == ["mandrel", "{d}/job.toml"]:
            outputs.append("m.stl")
    return Case(name, argv, files, outputs, previous)


# ------------------------------------------------------------------------------------------------
# Worker: runs cases in-process (started by Runner)
# ------------------------------------------------------------------------------------------------
def _vm_hwm() -> int:
    with open("/proc/self/status", encoding="ascii") as fh:
        for ln in fh:
            if ln.startswith("VmHWM:"):
                return int(ln.split()[1]) * 1024
    return 0


def _cpu_s() -> float:
    """CPU time of this process and its finished children (s): the time measure that does not depend
    on how loaded the machine is."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def worker_main() -> None:  # pragma: no cover - runs in the worker process
    """Read one JSON request a line from stdin, run ``engine.cli.main``, answer one JSON line."""
    import contextlib
    import traceback
    import warnings

    proto = os.fdopen(os.dup(1), "w")
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # C-level output must not mix with the answers
    warnings.simplefilter("default")
    import numpy  # noqa: F401 - import before measuring

    from engine.cli import main

    for req_line in sys.stdin:
        req = json.loads(req_line)
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
        except OSError:
            pass
        out, err = io.StringIO(), io.StringIO()
        exc_text = None
        t0 = time.perf_counter()
        c0 = _cpu_s()
        rc: Any = None
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main(req["argv"])
            except SystemExit as e:
                rc = e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
            except BaseException:  # noqa: BLE001 - this is what the fuzzer looks for
                exc_text = traceback.format_exc()
        elapsed = time.perf_counter() - t0
        proto.write(json.dumps({"rc": rc, "exc": exc_text, "err": err.getvalue()[-4000:],
                                "elapsed": elapsed, "cpu": _cpu_s() - c0, "peak": _vm_hwm()}) + "\n")
        proto.flush()


class Runner:
    """Runs cases in a worker process; restarts it after a hang or a crash."""

    def __init__(self, python: str = sys.executable, pythonpath: str | None = None,
                 memory_budget_bytes: int = 2 * 2**30, engine_budget: str = "1G",
                 address_limit_bytes: int = 10 * 2**30) -> None:
        self.python = python
        self.pythonpath = pythonpath or str(ROOT)
        self.memory_budget = memory_budget_bytes
        self.engine_budget = engine_budget
        self.address_limit = address_limit_bytes
        self.proc: subprocess.Popen[str] | None = None

    def _start(self) -> subprocess.Popen[str]:
        env = dict(os.environ, PYTHONPATH=self.pythonpath + os.pathsep + str(Path(__file__).parent),
                   WINDER_MAX_MEMORY=self.engine_budget, WINDER_IMPORT_TIMEOUT="20", QT_QPA_PLATFORM="offscreen",
                   OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONWARNINGS="default")
        limit = self.address_limit

        def pre() -> None:
            import resource

            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))  # protects the machine, not a check
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
            try:  # the worker ends with the driver (PR_SET_PDEATHSIG = 1)
                import ctypes

                ctypes.CDLL(None).prctl(1, signal.SIGKILL)
            except (OSError, AttributeError):
                pass

        return subprocess.Popen([self.python, "-c", "import fuzz_cases; fuzz_cases.worker_main()"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True, env=env, preexec_fn=pre,
                                cwd=self.pythonpath.split(os.pathsep)[0])  # sys.path[0] of "-c" is the cwd

    def close(self) -> None:
        """End the worker (if any) and close its pipes."""
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            for f in (self.proc.stdin, self.proc.stdout):
                if f is not None:
                    f.close()
            self.proc = None

    def run(self, case: Case, workdir: Path, time_budget_s: float) -> Outcome:
        """Run ``case`` in a fresh folder below ``workdir``; return the outcome with its problems."""
        d = workdir / case.name
        d.mkdir(parents=True)
        for name, data in {**case.files, **case.previous}.items():
            (d / name).write_bytes(data)
        argv = [a.replace("{d}", str(d)) for a in case.argv]
        res = Outcome(case.name, argv)
        if self.proc is None or self.proc.poll() is not None:
            self.proc = self._start()
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps({"argv": argv}) + "\n")
        self.proc.stdin.flush()
        t0 = time.monotonic()
        # wall clock: a generous limit for a real hang (the machine may be loaded); the budget is CPU time
        ready, _, _ = select.select([self.proc.stdout], [], [], 3.0 * time_budget_s + 30.0)
        if not ready:
            res.elapsed_s = time.monotonic() - t0
            res.problems["hang"] = f"no answer after {res.elapsed_s:.0f} s"
            self.close()
            return res
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            res.problems["crash"] = f"worker died: {signal.Signals(-code).name if code < 0 else code}"
            self.close()
            return res
        ans = json.loads(line)
        res.rc, res.elapsed_s, res.peak_rss, res.stderr = ans["rc"], ans["elapsed"], ans["peak"], ans["err"]
        res.cpu_s = ans["cpu"]
        if ans["exc"]:
            res.problems["traceback"] = ans["exc"].strip().splitlines()[-1]
        if res.rc not in (0, 1, 2):
            res.problems["exit code"] = repr(res.rc)
        if "Traceback (most recent call last)" in res.stderr:
            res.problems["traceback"] = "printed: " + res.stderr.strip().splitlines()[-1]
        m = re.search(r"^.*\b\w+Warning: .*$", res.stderr, re.M)
        if m:
            res.problems["warning"] = m.group(0)[:200]
        if res.cpu_s > time_budget_s:
            res.problems["slow"] = f"{res.cpu_s:.1f} s of CPU > {time_budget_s:g} s (wall {res.elapsed_s:.1f} s)"
        if res.peak_rss > self.memory_budget:
            res.problems["memory"] = f"peak {res.peak_rss / 2**20:.0f} MB > {self.memory_budget / 2**20:.0f} MB"
        err_line = next((ln for ln in res.stderr.splitlines() if ": error: " in ln), "")
        if res.rc == 2 and err_line and "usage:" not in res.stderr and case.files:
            # a bad input names its place: the file (or the option), and in a job file the line of the field
            paths = [a for a in argv if "/" in a]
            if not any(a in err_line for a in [*paths, str(d)]) and "field '" not in err_line:
                res.problems["unlocated"] = err_line[:200]
            else:
                m = re.search(r"(\S+\.toml), field '([^']+)'", err_line)
                if m:  # a field of a file it has no line in is a default (e.g. no [machine] table): no line
                    try:
                        text = Path(m.group(1)).read_text(encoding="utf-8", errors="replace")
                    except OSError:
                        text = ""
                    top = m.group(2).split(".")[0]
                    if re.search(rf"(?m)^\s*(\[\[?{re.escape(top)}\b|{re.escape(top)}\s*[.=])", text):
                        res.problems["no line"] = err_line[:200]
        left = [p.name for p in d.iterdir() if ".winder-" in p.name or re.match(r"^\..+\.\w{8}\.\w+$", p.name)]
        if left:
            res.problems["temp file"] = ", ".join(left)
        for name in case.outputs:
            p = d / name
            if res.rc == 2 and p.exists() and name not in case.previous:
                res.problems["partial output"] = f"{name} written although the exit code is 2"
            if name in case.previous and res.rc != 0 and p.read_bytes() != case.previous[name]:
                res.problems["previous file"] = f"{name} changed although the command failed"
        return res


def run_fuzz(n_cases: int, seed: int, workdir: Path, *, time_budget_s: float = 30.0, total_budget_s: float = 1e9,
             heavy: bool = True, runner: Runner | None = None, log: Any = None, progress: Any = None,
             every: int = 50) -> list[Outcome]:
    """Generate and run up to ``n_cases`` cases (seeded); stop early after ``total_budget_s``.

    ``log(text)`` gets every case with a problem, ``progress(outcomes)`` the outcomes so far after
    every ``every`` cases.  The cases depend on the seed only (not on the outcomes), so two runs with
    the same seed (e.g. two versions of the engine) see the same cases in the same order."""
    rng = random.Random(seed)
    own = runner is None
    runner = runner or Runner()
    out: list[Outcome] = []
    t0 = time.monotonic()
    try:
        for i in range(n_cases):
            if time.monotonic() - t0 > total_budget_s:
                break
            case = make_case(i, rng, heavy=heavy)
            res = runner.run(case, workdir, time_budget_s)
            out.append(res)
            if not res.problems:
                shutil.rmtree(workdir / case.name, ignore_errors=True)  # keep the folders of failures only
            if log is not None and res.problems:
                log(f"{res.case}: {res.problems} argv={res.argv}")
            if progress is not None and len(out) % every == 0:
                progress(out)
    finally:
        if own:
            runner.close()
    return out


def summarise(outcomes: list[Outcome]) -> dict[str, int]:
    """Counts: cases, exit codes, and each kind of problem."""
    counts: dict[str, int] = {"cases": len(outcomes)}
    for o in outcomes:
        counts[f"rc {o.rc}"] = counts.get(f"rc {o.rc}", 0) + 1
        for k in o.problems:
            counts[k] = counts.get(k, 0) + 1
    return counts
