"""``winder turning``: spindle speed and feed for one-pass turning by LP (MATH.md §C).

Examples::

    winder turning --example paper                 # the paper's case, handbook coefficients
    winder turning --example paper-expert --json   # the paper's Mathcad rows: n = 967.78, S = 1.35
    winder turning case.toml --snap --disable roughness --set workpiece.depth_mm=2.5
    winder turning --list                          # materials, tools, machines, examples

Exit codes: 0 an optimum was found; 2 bad input or an infeasible set-up (the message names the
conflicting constraints).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

NAME = "turning"
HELP = "Turning-mode optimiser: spindle speed n and feed S minimising machine time (LP, MATH.md §C)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``winder turning``."""
    parser.add_argument("case", nargs="?", default=None, metavar="CASE.toml",
                        help="case file (see resources/cutting/cases/*.toml)")
    parser.add_argument("--example", metavar="NAME", default=None,
                        help="use a shipped case: paper, paper-expert, ...")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--snap", action="store_true",
                        help="also give the best feasible pair on the machine's discrete speeds/feeds")
    parser.add_argument("--disable", action="append", default=[], metavar="NAME",
                        help="switch a constraint off (repeatable), e.g. tool_life, roughness")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a case entry, e.g. workpiece.depth_mm=2 or tool.material=\"VK8\"")
    parser.add_argument("--data", metavar="DIR", default=None,
                        help="cutting-data directory (default resources/cutting)")
    parser.add_argument("--list", action="store_true", help="list materials, tools, machines and examples")


def _apply_set(doc: dict[str, Any], item: str) -> None:
    from engine.errors import InputError

    if "=" not in item:
        raise InputError(f"expected SECTION.KEY=VALUE, got {item!r}", field="--set")
    key, raw = item.split("=", 1)
    from engine.fileio import loads_toml

    try:
        value = loads_toml(f"v = {raw.strip()}").get("v", raw.strip())
    except InputError:
        value = raw.strip()  # a bare word is taken as text
    parts = [p for p in key.strip().split(".") if p]
    if not parts:
        raise InputError(f"expected SECTION.KEY=VALUE, got {item!r}", field="--set")
    node = doc
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if not isinstance(node, dict):
            raise InputError(f"{p!r} is not a table", field=f"--set {key}")
    node[parts[-1]] = value


def run(args: argparse.Namespace) -> int:
    """Load the case, optimise, print the report."""
    from engine.cli import dump_json
    from engine.errors import InputError
    from engine.turning import (
        _read_toml,
        case_from_dict,
        cutting_dir,
        example_case_path,
        load_data,
        optimise,
        result_to_json,
    )

    data = load_data(args.data)
    if args.list:
        sys.stdout.write(format_listing(data, cutting_dir()))
        return 0
    if (args.case is None) == (args.example is None):
        raise InputError("give either a case file or --example NAME", field="CASE.toml")
    path = example_case_path(args.example) if args.example is not None else args.case
    doc = _read_toml(Path(path))
    for item in args.set:
        _apply_set(doc, item)
    if args.disable:
        cons = doc.setdefault("constraints", {})
        cons["disable"] = list(dict.fromkeys([*cons.get("disable", []), *args.disable]))
    try:
        case = case_from_dict(doc, file=path)
    except InputError as exc:  # a bad value that came from --set is the option's, not the file's
        set_keys = {item.partition("=")[0].strip() for item in args.set}
        f = exc.location.field or ""
        key = next((k for k in set_keys if f and (k == f or k.startswith(f + "."))), None)
        if key is not None:
            raise InputError(exc.message, field=f"--set {key}") from None
        raise
    res = optimise(case, data, snap=args.snap)
    if args.json:
        dump_json(result_to_json(res))
    else:
        sys.stdout.write(format_report(res, case.title or str(path)))
    return 0


def _fmt(v: Any, spec: str = ".4g", unit: str = "") -> str:
    if v is None:
        return "—"
    return f"{v:{spec}}{(' ' + unit) if unit else ''}"


def format_report(res: Any, title: str = "") -> str:  # res: engine.turning.TurningResult
    """Human-readable report: optimum, physical quantities, constraint table."""
    q = res.quantities
    out = []
    if title:
        out.append(title)
    out.append(f"Optimum: n = {res.n_rpm:.2f} rpm, S = {res.feed_mm_rev:.4g} mm/rev   "
               f"(x1 = ln n = {res.x1:.4f}, x2 = ln S = {res.x2:.4f})")
    out.append(f"  cutting speed V = {_fmt(q['speed_m_min'], '.4g', 'm/min')}, feed {_fmt(q['feed_mm_min'], '.4g')}"
               f" mm/min, machine time {_fmt(q['machine_time_min'], '.4g', 'min')}"
               f" ({_fmt(q['machine_time_s'], '.3g', 's')})")
    if q.get("force_pz_n") is not None:
        out.append(f"  forces P_z = {_fmt(q['force_pz_n'], '.5g')} N, P_y = {_fmt(q['force_py_n'], '.5g')} N, "
                   f"P_x = {_fmt(q['force_px_n'], '.5g')} N; cutting power {_fmt(q['power_kw'], '.3g', 'kW')}")
        out.append(f"  tool life T = {_fmt(q['tool_life_min'], '.4g', 'min')}, Rz = {_fmt(q['rz_um'], '.3g', 'um')},"
                   f" part deflection {_fmt(q['deflection_mm'], '.3g', 'mm')}")
    out.append("")
    out.append(f"  {'row':<4} {'constraint':<16} {'a':>6} {'b':>6} {'rhs':>9} {'slack':>9} {'use':>6}  status")
    for r in res.rows:
        if r.enabled:
            s = res.slack.get(r.name)
            status = "ACTIVE" if r.name in res.active else ""
            out.append(f"  {r.paper:<4} {r.name:<16} {r.a:>6.3g} {r.b:>6.3g} {r.rhs:>9.4f} {s:>9.4f} "
                       f"{100 * res.utilisation[r.name]:>5.1f}%  {status}")
        else:
            out.append(f"  {r.paper:<4} {r.name:<16} {r.a:>6.3g} {r.b:>6.3g} {r.rhs:>9.4f} {'':>9} {'':>6}  off")
    if res.snapped is not None:
        sn = res.snapped
        out.append("")
        if sn.get("feasible"):
            out.append(f"On the machine's series: n = {sn['n_rpm']:g} rpm, S = {sn['feed_mm_rev']:g} mm/rev, "
                       f"V = {_fmt(sn['speed_m_min'], '.4g', 'm/min')}, machine time "
                       f"{_fmt(sn['machine_time_min'], '.4g', 'min')} "
                       f"({100 * sn['ratio_to_continuous']:.1f} % of the continuous n*S)")
        else:
            out.append(f"On the machine's series: {sn['message']}")
    for n in res.notes:
        out.append(f"Note: {n}")
    return "\n".join(out) + "\n"


def format_listing(data: Any, root: Any) -> str:
    """The database contents, one line per entry."""
    out = ["Workpiece materials:"]
    out += [f"  {k:<12} {v.get('name', '')} [{v.get('group', '?')}]" for k, v in data.materials.items()]
    out.append("Tool materials:")
    out += [f"  {k:<12} {v.get('name', '')}" for k, v in data.tools.items()]
    out.append("Machines:")
    out += [f"  {k:<12} {v.get('name', '')}" for k, v in data.machines.items()]
    out.append("Examples (--example):")
    out += [f"  {p.stem}" for p in sorted((root / "cases").glob("*.toml"))]
    return "\n".join(out) + "\n"
