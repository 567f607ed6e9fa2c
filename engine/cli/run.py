"""``winder run JOB.toml -o OUT [--post NAME] [--report REPORT.json] [--force]``: the whole pipeline."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from engine.errors import InfeasibleError

NAME = "run"
HELP = "Run the whole pipeline (mandrel -> line -> eye -> axes -> blocks -> NC) and write the NC program."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("job", help="winding job (.toml)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT", help="NC program to write")
    parser.add_argument("--post", metavar="NAME", help="post-processor (default: the job's [post].post)")
    parser.add_argument("--report", metavar="REPORT.json", help="write the run report as JSON")
    parser.add_argument("--force", action="store_true", help="write the NC file even when limits are violated")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no stage times")
    parser.add_argument("-j", "--jobs", type=_positive_int, metavar="N",
                        help="worker processes for a laminate's layers (default: the CPUs available, or "
                             "$WINDER_JOBS; 1 = one after the other in this process); the program is the same "
                             "for any N")


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, not {text!r}")
    return n


def run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    from engine.cli import dump_json
    from engine.fileio import atomic_write_text, check_output_path
    from engine.job import load_job
    from engine.pipeline import process_refusals, run_pipeline, write_program
    from engine.state import CliState

    out = check_output_path(args.output, "NC program")
    if args.report:
        check_output_path(args.report, "report")
    job = load_job(args.job)
    if job.is_single_line:
        result = run_pipeline(job, args.job, post_name=args.post, state=CliState(quiet=args.quiet))
        write = write_program
    else:  # a laminate: every layer, joined into one program
        from engine.laminate import default_workers, run_laminate, write_laminate

        result = run_laminate(job, args.job, post_name=args.post, state=CliState(quiet=args.quiet),
                              workers=args.jobs if args.jobs is not None else default_workers())
        write = write_laminate
    # the report is made only where it is read (a --report file, the summary printed without --quiet):
    # ~0.02 s on the example vessel, after its last layer
    report: dict[str, Any] = result.report() if (args.report or not args.quiet) else {}
    report["output"] = str(out)
    rc = 0
    try:
        if job.is_single_line:
            refusals = process_refusals(result)  # what `trajectory` / `payout` report as failing (exit 1)
        else:
            from engine.laminate import laminate_refusals

            refusals = laminate_refusals(result)
        if refusals and not args.force:
            raise InfeasibleError(f"not written: {'; '.join(refusals)}. Use --force to write it anyway.", file=out)
        write(result, out, force=args.force)
        report["written"] = True
    except InfeasibleError as exc:
        report["written"] = False
        print(f"winder run: {exc}", file=sys.stderr)
        rc = 1
    report["wall_time_s"] = time.perf_counter() - t_start
    if args.report:
        import io

        buf = io.StringIO()
        dump_json(report, buf)
        atomic_write_text(args.report, buf.getvalue())
    if not args.quiet:
        stages = ", ".join(f"{k} {v:.3f}s" for k, v in result.stage_times.items())
        print(f"stages: {stages}", file=sys.stderr)
        if "program_time_s" in report:
            print(
                f"{report['blocks']} blocks, program time {report['program_time_s']:.2f} s "
                f"(preliminary {report['program_time_t17_s']:.2f} s) on {report['machine']}"
                + (f" -> {out}" if report["written"] else ""),
                file=sys.stderr,
            )
        for w in report["warnings"][:10]:
            print(f"warning: {w}", file=sys.stderr)
    return rc
