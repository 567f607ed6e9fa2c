"""Hobby winders on Marlin or GRBL firmware.

GRBL 1.1 understands inverse-time feed (G93).  Marlin does not: its F is mm/min along the combined
move of all axes it drives, so the profile uses ``feed_mode = "units_per_min"`` with F = Euclidean
norm of all axis motions (rotary axes counted in their own units, as Marlin treats every axis as
linear) per minute.  Comments use ``;``.
"""

from __future__ import annotations

from engine.post.gcode import GcodePost


class MarlinPost(GcodePost):
    name = "marlin"
    title = "Marlin / GRBL hobby firmware (G-code with ; comments)"
    extension = ".gcode"
    letter_pattern = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W", "E", "I", "J", "K")

    def mode_lines(self, profile, opts):  # noqa: D102 - Marlin has no G93/G94
        if profile.feed_mode == "inverse_time":
            return super().mode_lines(profile, opts)
        return ["G21 G90" if profile.units == "mm" else "G20 G90"]
