"""CSV axis table: one row per block end (block 0 = start), time of each block, feed, axes."""

from __future__ import annotations

from typing import Any

import numpy as np

from engine.blocks import Blocks
from engine.kinematics import MachineTemplate
from engine.post.base import ControllerProfile, Option, PostProcessor, fmt_many, format_columns


class CsvPost(PostProcessor):
    name = "csv"
    title = "CSV axis table"
    extension = ".csv"
    options = (Option("delimiter", str, ",", "column separator", (",", ";", "\t")),)

    def render_lines(self, blocks: Blocks, machine: MachineTemplate, profile: ControllerProfile,
                     opts: dict[str, Any]) -> list[str]:
        d = opts["delimiter"]
        letters = self.letters(machine, profile)
        units = [a.units for a in machine.axes]
        head = ["block", "path_index", "time_s", "t17_s", "start_s"] + [
            f"{L}_{u}" for L, u in zip(letters, units)]
        pos = format_columns(np.asarray(blocks.q), self.decimals(machine, profile))
        t = np.concatenate(([0.0], np.asarray(blocks.time)))
        t17 = np.concatenate(([0.0], np.asarray(blocks.t17)))
        start = np.concatenate(([0.0], np.cumsum(blocks.time)))
        nd = profile.decimals_feed + 2
        out = []
        if opts["comments"]:
            out += [f"# {s}" for s in self._comments(blocks, machine, profile, opts)]
        out.append(d.join(head))
        cols = (fmt_many(t, nd), fmt_many(t17, nd), fmt_many(start, nd))
        index = np.asarray(blocks.index[:blocks.n + 1], dtype=np.int64).tolist()
        for i, (k, a, b, c, p) in enumerate(zip(index, *cols, pos)):
            out.append(d.join([str(i), str(k), a, b, c, *p]))
        return out

    def _comments(self, blocks, machine, profile, opts):
        return [c[1:-1] if c.startswith("(") else c[2:] for c in self.header(blocks, machine, profile, opts)]
