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

from engine.errors import InputError
from engine.post.base import ControllerProfile, Option, PostProcessor, list_controllers, load_controller


def _registry() -> dict[str, type[PostProcessor]]:
    reg: dict[str, type[PostProcessor]] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name in ("base",) or info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(mod).values():
            if isinstance(obj, type) and issubclass(obj, PostProcessor) and obj.__module__ == mod.__name__:
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


__all__ = ["ControllerProfile", "Option", "PostProcessor", "get_post", "list_controllers", "list_posts",
           "load_controller"]
