"""``winder slot``: centre distance for a required slot length (cycloidal slot forming, MATH.md §D).

Example (the paper's Table 2)::

    winder slot --rho 22 --tool-radius -95 --ratio -2 --length 2:20:2 --tol 0.005

Exit codes: 0 every row has an answer; 1 some slot length cannot be reached (reported per row);
2 bad input.
"""

from __future__ import annotations

import argparse
import math
import sys

NAME = "slot"
HELP = "Cycloidal slot forming: centre distance A for slot lengths l (rotating blade tool)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``winder slot``."""
    parser.add_argument("--rho", type=float, required=True, metavar="MM",
                        help="forming radius ρ at which the slot length is given (e.g. tube bore), mm")
    parser.add_argument("--tool-radius", type=float, required=True, metavar="MM",
                        help="signed tool radius R_u, mm: negative = external scheme, positive = internal")
    parser.add_argument("--ratio", type=float, default=0.0, metavar="I",
                        help="kinematic ratio i = ω_part/ω_tool; i·R_u > 0 down-cut, < 0 up-cut (default 0)")
    parser.add_argument("--length", required=True, metavar="FROM:TO:STEP",
                        help="slot lengths l, mm: FROM:TO:STEP, one number, or a comma-separated list")
    parser.add_argument("--tol", type=float, default=0.005, metavar="T",
                        help="admissible relative error [Δ] of the iteration (default 0.005)")
    parser.add_argument("--part-radius", type=float, default=None, metavar="MM",
                        help="nominal part radius R_d for the reduced parameters, mm (default ρ)")
    parser.add_argument("--max-iter", type=int, default=100, metavar="N",
                        help="iteration budget (default 100)")
    parser.add_argument("--a-formula", choices=("exact", "paper"), default="exact",
                        help="closure reported as A: exact triangle closure (default) or the paper's printed one")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    parser.add_argument("--csv", metavar="OUT", default=None, help="also write the table as CSV to OUT")


def run(args: argparse.Namespace) -> int:
    """Compute the table and print it (JSON or text); optionally write CSV."""
    from engine.cli import dump_json
    from engine.slotting import SlotSetup, parse_range, slot_table, write_table_csv

    setup = SlotSetup(
        rho=args.rho,
        tool_radius=args.tool_radius,
        ratio=args.ratio,
        tol=args.tol,
        part_radius=args.part_radius,
        max_iter=args.max_iter,
        a_formula=args.a_formula,
    )
    lengths = parse_range(args.length, "slot length", "length")
    table = slot_table(lengths, setup)
    if args.csv:
        write_table_csv(args.csv, table)
    if args.json:
        dump_json([r.as_dict() for r in table.rows])
    else:
        sys.stdout.write(format_table(table))
    bad = [r for r in table.rows if not r.ok]
    if bad:
        ls = ", ".join(f"{r.l:g}" for r in bad)
        print(f"winder slot: {len(bad)} slot length(s) cannot be reached: l = {ls} mm", file=sys.stderr)
        return 1
    return 0


def format_table(table) -> str:  # noqa: ANN001 - engine.slotting.SlotTable, imported lazily
    """Human-readable table with a header of the set-up and Table 1's reduced parameters."""
    s, red = table.setup, table.reduced
    lines = [
        f"Slot forming: ρ = {s.rho:g} mm, R_u = {s.tool_radius:g} mm ({s.scheme} scheme), i = {s.ratio:g} "
        f"({s.mode}), [Δ] = {s.tol:g}, A by the {s.a_formula} closure",
        f"Reduced (Table 1): i1 = {red.i1:.5g}, Ã = 1 − i1 = {red.A_tilde_nominal:.5g}, i = {red.i:g}, "
        f"I = {'—' if red.I is None else f'{red.I:.5g}'}, ρ̃ = {red.rho_tilde:.5g}",
        "",
        f"{'l, mm':>8} {'A, mm':>10} {'A_paper, mm':>12} {'A_check, mm':>12} {'θ, deg':>9} {'j':>4} "
        f"{'conv':>5} {'method':>9}  note",
    ]

    def num(v: float, w: int, p: int) -> str:
        return f"{v:{w}.{p}f}" if math.isfinite(v) else f"{'—':>{w}}"

    for r in table.rows:
        lines.append(
            f"{r.l:8.3f} {num(r.A, 10, 3)} {num(r.A_paper, 12, 3)} {num(r.A_check, 12, 3)} "
            f"{num(math.degrees(r.theta), 9, 4)} {r.iterations:4d} {'yes' if r.converged else 'no':>5} "
            f"{r.method:>9}  {r.message}"
        )
    return "\n".join(lines) + "\n"


__all__ = ["HELP", "NAME", "add_arguments", "format_table", "run"]
