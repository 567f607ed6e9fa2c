"""Fanuc-style G-code: ``%`` framing, O program number, N numbers, decimal points always written."""

from __future__ import annotations

from typing import Any

from engine.post.base import ControllerProfile, Option
from engine.post.gcode import GcodePost


class FanucPost(GcodePost):
    name = "fanuc"
    title = "Fanuc-style (O-number, G93 inverse time or G94, forced decimal points)"
    extension = ".nc"
    force_point = True
    g_linear = "G01"
    g_rapid = "G00"
    letter_pattern = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
    options = (Option("program_number", int, 1, "O number of the program (1..9999)"),)

    def render_lines(self, blocks, machine, profile: ControllerProfile, opts: dict[str, Any]) -> list[str]:
        num = opts["program_number"]
        if not 1 <= num <= 9999:
            from engine.errors import InputError
            raise InputError(f"program_number must be 1..9999, got {num}", field="program_number")
        body = super().render_lines(blocks, machine, profile, opts)
        return ["%", f"O{num:04d}"] + body + ["%"]
