"""How many prims a USD file composes to, estimated from its layers before USD composes it.

References and payloads copy whole subtrees, so a file of a few kilobytes can ask for ten million prims
(seven levels of ten references), which USD would spend minutes and gigabytes composing.  Counting is
cheap: each layer is parsed once (USD's layer registry then serves it to the stage), and the number of
prims under each prim spec is worked out once, with an explicit stack (a chain of references of any length
is fine).  The estimate counts a referenced prim's whole subtree and every variant, so it is an upper bound:
a file under it composes to no more prims than that.

What is bounded is what composition adds: a stage may compose to the prim specs its layers hold plus
MAX_USD_PRIMS.  Prims written out one by one cost reading time in proportion to the file's size, as an SDL
file's shapes do; so any stage the writer makes (it uses no references) reads back, however large.
"""
from __future__ import annotations

from typing import Optional

from ..errors import TracerError
from . import common as C

#: Most prims (instances expanded) a stage may compose to beyond those its layers define: ten times the
#: largest scenes we benchmark, and still read in well under a minute.
MAX_USD_PRIMS = 50_000
#: Where a count stops growing (a count past every budget; Python's integers would grow without end).
_SATURATED = 10 ** 12


class _Counter:
    def __init__(self, Sdf, budget: int):
        self.Sdf = Sdf
        self.budget = budget
        self.sizes: dict[tuple[str, object], int] = {}
        self.layers: dict[str, object] = {}

    def layer(self, identifier: str):
        if identifier not in self.layers:
            try:
                self.layers[identifier] = self.Sdf.Layer.FindOrOpen(identifier)
            except Exception:  # noqa: BLE001 — a layer USD cannot open composes to nothing; open_stage says why
                self.layers[identifier] = None
        return self.layers[identifier]

    def _arcs(self, layer, spec) -> list[tuple[str, object]]:
        """(layer, Sdf prim path) of what a prim spec's references and payloads bring in."""
        found = []
        for arcs in (spec.referenceList, spec.payloadList):
            items = list(arcs.explicitItems) + list(arcs.prependedItems) + list(arcs.appendedItems) + \
                list(arcs.addedItems)
            for item in items:
                if item.assetPath:
                    target = self.layer(layer.ComputeAbsolutePath(item.assetPath))
                else:
                    target = layer
                if target is None:
                    continue
                path = item.primPath if not item.primPath.isEmpty else (
                    self.Sdf.Path(f"/{target.defaultPrim}") if target.defaultPrim else None)
                if path is not None:
                    found.append((target.identifier, path))
        return found

    def _parts(self, key: tuple[str, object]) -> list[tuple[str, object]]:
        """What the prim at ``key`` is made of: its children, its variants' prims and its arcs' targets."""
        layer = self.layer(key[0])
        spec = layer.GetPrimAtPath(key[1]) if layer is not None else None
        if spec is None:
            return []
        parts = [(key[0], child.path) for child in spec.nameChildren]
        for variant_set in spec.variantSets:
            for variant in variant_set.variants:
                parts += [(key[0], child.path) for child in variant.primSpec.nameChildren]
        return parts + self._arcs(layer, spec)

    def size(self, root: tuple[str, object]) -> int:
        """Prims the prim at ``root`` composes to (a count past every budget stays at _SATURATED)."""
        sizes, stack, open_keys = self.sizes, [root], set()
        children: dict[tuple[str, object], list] = {}
        while stack:
            key = stack[-1]
            if key in sizes:
                stack.pop()
                continue
            if key not in open_keys:
                open_keys.add(key)
                children[key] = self._parts(key)
                stack += [k for k in children[key] if k not in sizes and k not in open_keys]
                continue
            open_keys.discard(key)
            # A cycle (which USD reports itself) counts once here.
            total = 1 + sum(sizes.get(k, 0) for k in children.pop(key))
            sizes[key] = min(total, _SATURATED)
            stack.pop()
        return sizes[root]


def check_prim_budget(path: str, budget: Optional[int] = None) -> None:
    """TracerError naming the file if its stage would compose to more than ``budget`` prims beyond the prim
    specs its layers hold."""
    budget = MAX_USD_PRIMS if budget is None else budget
    counter = _Counter(C.pxr().Sdf, budget)
    root = counter.layer(path)
    if root is None:
        return  # opening the stage reports it
    layers, total = [root], 0
    for sub in root.subLayerPaths:
        sublayer = counter.layer(root.ComputeAbsolutePath(sub))
        if sublayer is not None:
            layers.append(sublayer)
    for layer in layers:
        for prim in layer.rootPrims:
            total += counter.size((layer.identifier, prim.path))
            held = len(counter.sizes)  # (every prim spec met so far, each counted once)
            if total > budget + held:
                raise TracerError(f"{path}: the stage composes to more than {budget:,} prims beyond the {held:,} "
                                  f"its layers define (references, payloads and instances expanded): too many "
                                  f"to read")
