"""``winder mandrel FILE [--json] [--step OUT.step] [--stl OUT.stl]``: inspect and export a mandrel."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from engine.errors import InputError

NAME = "mandrel"
HELP = "Summarise a mandrel (job .toml, .csv table, .dxf profile or .step solid); export STEP/STL."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="job (.toml), generatrix table (.csv), profile (.dxf) or solid (.step)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--step", metavar="OUT.step", help="export the mandrel solid as STEP")
    parser.add_argument("--stl", metavar="OUT.stl", help="export the mandrel surface as STL")
    parser.add_argument("--smooth", type=float, metavar="MM",
                        help="CSV tables: fit the smoothest spline within MM of the points (reports the deviation)")
    parser.add_argument("--dxf", metavar="OUT.dxf", help="export the generatrix as a DXF profile (lines/arcs exact)")
    parser.add_argument("--sketch", metavar="OUT.toml",
                        help="write the generatrix as a [mandrel] sketch of exact segments (kind = 'segments')")
    parser.add_argument("--stl-tolerance", type=float, default=0.05, metavar="MM", help="STL chord tolerance (mm)")


def load_any_mandrel(path: str | Path) -> Any:
    """A mandrel from a job file or a profile file, chosen by suffix."""
    p = Path(path)
    if p.suffix.lower() == ".toml":
        from engine.job import build_mandrel, load_job

        return build_mandrel(load_job(p), p)
    if not p.exists():
        raise InputError("file not found", file=p)
    from engine.mandrel_io import load_mandrel_file

    return load_mandrel_file(p)


def run(args: argparse.Namespace) -> int:
    from engine.cli import dump_json

    for opt, suffixes in (("step", {".step", ".stp"}), ("stl", {".stl"}), ("dxf", {".dxf"}), ("sketch", {".toml"})):
        out = getattr(args, opt)
        if out and Path(out).suffix.lower() not in suffixes:
            raise InputError(f"--{opt} needs a file ending in {' or '.join(sorted(suffixes))}", file=out)
        if out:
            from engine.fileio import check_output_path

            check_output_path(out, opt.upper())
    if args.smooth is not None:
        if Path(args.file).suffix.lower() not in (".csv", ".txt", ".dat"):
            raise InputError("--smooth applies to measured point tables (.csv/.txt/.dat)", file=args.file)
        from engine.mandrel_io import load_mandrel_file

        mandrel = load_mandrel_file(args.file, smoothing_mm=args.smooth)
    else:
        mandrel = load_any_mandrel(args.file)
    if args.dxf:
        from engine.mandrel_io import export_dxf

        export_dxf(mandrel, args.dxf)
    if args.sketch:
        import tomli_w

        from engine.fileio import atomic_write_text
        from engine.sketch import sketch_from_mandrel

        atomic_write_text(args.sketch, tomli_w.dumps({"mandrel": sketch_from_mandrel(mandrel)}))
    if args.step or args.stl:
        from engine import mandrel_io

        if args.step:
            mandrel_io.export_step(mandrel, args.step)
        if args.stl:
            mandrel_io.export_stl(mandrel, args.stl, tolerance_mm=args.stl_tolerance)
    summary = mandrel.summary()
    if mandrel.meta.get("decimated"):
        summary["decimated"] = mandrel.meta["decimated"]
    if mandrel.meta.get("smoothing"):
        summary["smoothing"] = mandrel.meta["smoothing"]
    if args.json:
        dump_json(summary)
    else:
        print(f"{summary['name']} ({summary['source']})")
        print(f"  z: {summary['z_min']:.3f} .. {summary['z_max']:.3f} mm   r: {summary['r_min']:.3f} .. "
              f"{summary['r_max']:.3f} mm")
        print(f"  pole radii: {summary['pole_radii'][0]:.3f}, {summary['pole_radii'][1]:.3f} mm")
        print(f"  area {summary['area_mm2']:.1f} mm2, volume {summary['volume_mm3']:.1f} mm3")
        if mandrel.meta.get("note"):
            print(f"  note: {mandrel.meta['note']}")
        sm = summary.get("smoothing")
        if sm and sm.get("applied"):
            print(f"  smoothed within {sm['tolerance_mm']:g} mm of the points: max deviation "
                  f"{sm['max_deviation_mm']:.4g} mm at z = {sm['at_z_mm']:.6g} mm, rms {sm['rms_deviation_mm']:.4g} mm")
        elif sm:
            print(f"  smoothing: {sm['note']}")
        zones = summary["concave_zones"] or "none"
        print(f"  concave zones: {zones}")
        for opt in ("step", "stl", "dxf", "sketch"):
            if getattr(args, opt):
                print(f"  wrote {getattr(args, opt)}")
    return 0
