"""Siemens Sinumerik (``.mpf``): ``;`` comments, G71/G70, G93 inverse time, ``NAME=value`` for
multi-letter axis identifiers, M30."""

from __future__ import annotations

from typing import Any

from engine.post.base import ControllerProfile
from engine.post.gcode import GcodePost


class SinumerikPost(GcodePost):
    name = "sinumerik"
    title = "Siemens Sinumerik (.mpf)"
    extension = ".mpf"
    g_linear = "G1"
    g_rapid = "G0"

    def address(self, letter: str, value: str) -> str:
        return f"{letter}{value}" if len(letter) == 1 else f"{letter}={value}"

    def mode_lines(self, profile: ControllerProfile, opts: dict[str, Any]) -> list[str]:
        units = "G71" if profile.units == "mm" else "G70"
        feed = {"inverse_time": "G93", "units_per_min": "G94", "none": ""}[profile.feed_mode]
        return [" ".join(w for w in (units, "G90", feed) if w)]
