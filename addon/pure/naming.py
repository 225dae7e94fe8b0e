"""The names Blender will give datablocks made in bulk, worked out before they are made (pure Python, no bpy).

Blender keeps each kind of datablock (objects, materials, ...) in a list sorted by name, and puts a new or
renamed one in its place by walking the list from its end (``id_sort_by_name``, comparing as
``BLI_strcasecmp`` does).  Made in the order of their names, each new datablock belongs at the end and the
walk stops at once; made in any other order, each walks past every name above its own, so that 10^4
objects called "sphere" ("sphere.001", ... "sphere.1000" sorts before "sphere.101") cost time in the square
of their number.  So the importer asks here for the names Blender would give (the name wanted, else the
lowest free ``.NNN`` suffix, as Blender picks them), and makes its datablocks sorted by :func:`sort_key`.
A name worked out wrongly costs only time: Blender still makes every name unique itself.
"""
from __future__ import annotations

import re
from typing import Iterable, Optional

_NUMBERED = re.compile(r"^(.*)\.([0-9]+)$")


def split_number(name: str) -> tuple[str, Optional[int]]:
    """``("sphere", 12)`` for "sphere.012"; ``(name, None)`` for a name without a numeric suffix."""
    found = _NUMBERED.match(name)
    if found is None:
        return name, None
    return found.group(1), int(found.group(2))


def unique_names(wanted: Iterable[str], taken: Iterable[str], max_bytes: int = 63) -> list[str]:
    """For each wanted name, in order, the name Blender gives a new datablock asking for it when the names in
    ``taken`` and those given before it are in use: the name itself if free, else its base with the lowest free
    suffix .001, .002, ...  A name longer than ``max_bytes`` (in UTF-8) is given unchanged: Blender shortens it
    its own way."""
    used = set(taken)
    next_free: dict[str, int] = {}  # base -> lowest suffix not yet known to be used
    out = []
    for name in wanted:
        if name in used or len(name.encode("utf-8")) > max_bytes:
            if name in used:
                base, _ = split_number(name)
                number = next_free.get(base, 1)
                while f"{base}.{number:03d}" in used:
                    number += 1
                next_free[base] = number + 1
                name = f"{base}.{number:03d}"
        used.add(name)
        out.append(name)
    return out


def sort_key(name: str) -> bytes:
    """Where Blender sorts ``name`` among datablocks of its kind: ``BLI_strcasecmp`` compares the UTF-8 bytes,
    ASCII letters lower-cased (so "_" falls between "9" and "a", and "é" after "~")."""
    return name.encode("utf-8").lower()
