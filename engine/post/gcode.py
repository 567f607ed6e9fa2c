"""Shared G-code writer for the RS274-like dialects (LinuxCNC, Fanuc, Sinumerik, GRBL/Marlin)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from engine.blocks import Blocks
from engine.kinematics import MachineTemplate
from engine.post.base import ControllerProfile, PostProcessor, fmt_many, format_columns_by_axis


class GcodePost(PostProcessor):
    """Modal G-code: absolute positions, only the words that change, one block per line."""

    force_point: ClassVar[bool] = False     # Fanuc: "10." (no decimal point = least input increment)
    g_linear: ClassVar[str] = "G1"
    g_rapid: ClassVar[str] = "G0"

    def address(self, letter: str, value: str) -> str:
        return f"{letter}{value}"

    def mode_lines(self, profile: ControllerProfile, opts: dict[str, Any]) -> list[str]:
        units = "G21" if profile.units == "mm" else "G20"
        feed = {"inverse_time": "G93", "units_per_min": "G94", "none": ""}[profile.feed_mode]
        return [" ".join(w for w in (units, "G90", feed) if w)]

    def end_lines(self, profile: ControllerProfile, opts: dict[str, Any]) -> list[str]:
        return []

    def render_lines(self, blocks: Blocks, machine: MachineTemplate, profile: ControllerProfile,
                     opts: dict[str, Any]) -> list[str]:
        letters = self.letters(machine, profile)
        dec = self.decimals(machine, profile)
        cols = format_columns_by_axis(np.asarray(blocks.q), dec, self.force_point)
        feeds = self.feeds(blocks, profile)
        body: list[str] = []
        body += self.header(blocks, machine, profile, opts)
        body += list(profile.preamble)
        body += self.mode_lines(profile, opts)
        if opts["rapid_to_start"]:
            body.append(" ".join([self.g_rapid] + [self.address(L, c[0]) for L, c in zip(letters, cols)]))
        inverse = profile.feed_mode == "inverse_time"
        notes: dict[int, list[str]] = {}
        if opts["comments"]:
            for i, text in getattr(blocks, "sections", ()):
                notes.setdefault(int(i), []).append(self.comment(profile, text))
        n = blocks.n
        # an axis word where the formatted value changes (column by column); the address of a letter is
        # its prefix followed by the value for every dialect here
        words_k = []
        for L, c in zip(letters, cols):
            pre = self.address(L, "")
            if self.address(L, "1.5") == pre + "1.5":
                words_k.append([pre + b if b != a else "" for a, b in zip(c[:-1], c[1:])])
            else:  # pragma: no cover - a dialect whose address is not prefix + value
                words_k.append([self.address(L, b) if b != a else "" for a, b in zip(c[:-1], c[1:])])
        f_str = fmt_many(feeds, profile.decimals_feed, self.force_point)
        first_word = [self.address(letters[0], v) for v in cols[0][1:]] if cols else [""] * n
        # F where it changes (every block in inverse-time mode)
        f_part = [" F" + f if inverse or f != p else "" for f, p in zip(f_str, [None, *f_str[:-1]])]
        g = self.g_linear + " "
        # no axis moves at output precision: keep the block as a dwell-free repeat so the timing stays
        # intact (controllers accept a G1 with only F in inverse-time mode)
        moves = [g + (" ".join([w for w in ws if w]) or fw) + fp
                 for ws, fw, fp in zip(zip(*words_k), first_word, f_part)] if words_k else \
            [g + fw + fp for fw, fp in zip(first_word, f_part)]
        start = 0
        for i in sorted(k for k in notes if 0 <= k < n):
            body += moves[start:i]
            body += notes[i]
            start = i
        body += moves[start:n]
        body += self.end_lines(profile, opts)
        body += list(profile.postamble)
        return self.number(body, profile)

    def number(self, lines: list[str], profile: ControllerProfile) -> list[str]:
        step = profile.line_numbers
        if not step:
            return lines
        out, n = [], 0
        for s in lines:
            if not s or s[0] in "(;%" or s.startswith("O"):
                out.append(s)
                continue
            n += step
            out.append(f"N{n} {s}")
        return out
