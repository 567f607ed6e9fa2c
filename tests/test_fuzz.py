"""Seeded, bounded mutation fuzz of the command line (issue 19); the cases are in tests/fuzz_cases.py.

A fixed seed and a fixed time budget (90 s of cases): every input must end with exit code 0, 1 or
2, without a traceback or a Python warning line, within its time budget, under its memory budget,
and without a partial output file.  ``benchmarks/fuzz_winder.py`` runs thousands of the same cases.
"""

from __future__ import annotations

import random

import pytest
from fuzz_cases import Runner, make_case, run_fuzz, summarise

CASE_TIME_S = 40.0          # one case (a full small pipeline takes a few seconds)
TOTAL_TIME_S = 90.0         # the whole test stops generating cases after this
MEMORY_BYTES = 2 * 2**30    # peak RSS of the worker during one case (engine budget 1 GB + libraries)


def test_cases_are_reproducible() -> None:
    a = [make_case(i, random.Random(7)) for i in range(3)]
    b = [make_case(i, random.Random(7)) for i in range(3)]
    assert [(c.argv, c.files) for c in a] == [(c.argv, c.files) for c in b]


@pytest.mark.slow
def test_fuzz_command_line(tmp_path) -> None:
    runner = Runner(memory_budget_bytes=MEMORY_BYTES, engine_budget="1G")
    try:
        outs = run_fuzz(400, 20261124, tmp_path, time_budget_s=CASE_TIME_S, total_budget_s=TOTAL_TIME_S,
                        runner=runner)
    finally:
        runner.close()
    counts = summarise(outs)
    bad = [f"{o.case}: {o.problems} argv={o.argv} stderr={o.stderr[-300:]!r}" for o in outs if o.problems]
    assert len(outs) >= 20, counts  # the budget ran real cases
    assert not bad, "\n".join(bad[:10])
    assert counts.get("rc 2", 0) > 0 and counts.get("rc 0", 0) + counts.get("rc 1", 0) > 0, counts
