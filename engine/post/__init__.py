"""Post-processors: NC text for one controller dialect each, found by name.

``get_post(name)`` returns a :class:`~engine.post.base.PostProcessor`; ``list_posts()`` lists the
dialects.  Every module in this package (except ``base``) defines one post-processor class with a
``name``; adding a dialect adds one module.  Controller *profiles* (units, precision, line endings,
preamble/postamble, axis letters, feed mode) are data in ``resources/controllers/*.toml``
(:func:`load_controller`).  Posts return text; the caller writes it with
:func:`engine.fileio.atomic_write_text`.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Sequence
from pathlib import Path

from engine.errors import InfeasibleError, InputError
from engine.fileio import atomic_write_text
from engine.post.base import ControllerProfile, Option, PostProcessor, list_controllers, load_controller


def _registry() -> dict[str, type[PostProcessor]]:
    reg: dict[str, type[PostProcessor]] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name in ("base",) or info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(mod).values():
            if (isinstance(obj, type) and issubclass(obj, PostProcessor) and obj.__module__ == mod.__name__
                    and obj.name):  # a shared base class (e.g. gcode's) has no name and is no dialect
                reg[obj.name] = obj
    return reg


def list_posts() -> list[str]:
    """Names of the available dialects, sorted."""
    return sorted(_registry())


def get_post(name: str) -> PostProcessor:
    """The post-processor for dialect ``name``; :class:`InputError` naming the known ones otherwise."""
    reg = _registry()
    if name not in reg:
        raise InputError(f"unknown post-processor {name!r}; known: {', '.join(sorted(reg))}", field="post")
    return reg[name]()


def write_nc(path: str | Path, text: str, violations: Sequence[object] = (), force: bool = False) -> Path:
    """Write NC text atomically - unless the program has violations and the user did not force it.

    Parameters
    ----------
    path: target file.  text: output of ``PostProcessor.render`` (line endings kept as they are).
    violations: from :func:`engine.blocks.check_program`; each has a ``message``.
    force: write even when there are violations.

    Raises
    ------
    InfeasibleError
        There are violations and ``force`` is false; nothing is written.  The message lists the first
        few (axis, place, amount) and how many there are.
    """
    if violations and not force:
        msgs = [getattr(v, "message", str(v)) for v in violations]
        more = f" (and {len(msgs) - 5} more)" if len(msgs) > 5 else ""
        raise InfeasibleError(f"not written: the program violates {len(msgs)} limit(s){more}: "
                              + "; ".join(msgs[:5]) + ". Use force to write it anyway.", file=path)
    return atomic_write_text(path, text, newline="")


__all__ = ["ControllerProfile", "Option", "PostProcessor", "get_post", "list_controllers", "list_posts",
           "load_controller", "write_nc"]
