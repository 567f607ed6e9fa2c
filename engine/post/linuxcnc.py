"""LinuxCNC (RS274NGC, ``.ngc``): inverse-time feed G93, programs end with M2."""

from __future__ import annotations

from engine.post.gcode import GcodePost


class LinuxcncPost(GcodePost):
    name = "linuxcnc"
    title = "LinuxCNC (.ngc, inverse-time feed G93)"
    extension = ".ngc"
    letter_pattern = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
