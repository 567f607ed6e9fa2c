"""Shared G-code writer for the RS274-like dialects (LinuxCNC, Fanuc, Sinumerik, GRBL/Marlin)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from engine.blocks import Blocks
from engine.kinematics import MachineTemplate
from engine.post.base import ControllerProfile, PostProcessor, fmt, format_columns


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
        pos = format_columns(np.asarray(blocks.q), dec, self.force_point)
        feeds = self.feeds(blocks, profile)
        body: list[str] = []
        body += self.header(blocks, machine, profile, opts)
        body += list(profile.preamble)
        body += self.mode_lines(profile, opts)
        if opts["rapid_to_start"]:
            body.append(" ".join([self.g_rapid] + [self.address(L, v) for L, v in zip(letters, pos[0])]))
        inverse = profile.feed_mode == "inverse_time"
        notes: dict[int, list[str]] = {}
        if opts["comments"]:
            for i, text in getattr(blocks, "sections", ()):
                notes.setdefault(int(i), []).append(self.comment(profile, text))
        n = blocks.n
        # column-wise: an axis word where the formatted value changes (the same rule as block by block)
        cols = list(zip(*pos)) if pos else []
        words_k = []
        for k, L in enumerate(letters):
            c = cols[k]
            words_k.append([self.address(L, b) if b != a else "" for a, b in zip(c[:-1], c[1:])])
        f_str = [fmt(float(x), profile.decimals_feed, self.force_point) for x in np.asarray(feeds, dtype=float)]
        first_word = [self.address(letters[0], v) for v in cols[0][1:]] if cols else []
        g = self.g_linear
        last_f = None
        for i in range(n):
            if i in notes:
                body += notes[i]
            ax = [w[i] for w in words_k if w[i]]
            if not ax:
                # no axis moves at output precision: keep the block as a dwell-free repeat so the
                # timing stays intact (controllers accept a G1 with only F in inverse-time mode)
                ax = [first_word[i]]
            f = f_str[i]
            if inverse or f != last_f:
                ax.append(f"F{f}")
            last_f = f
            body.append(g + " " + " ".join(ax))
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
