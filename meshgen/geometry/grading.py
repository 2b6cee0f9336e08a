"""Wall grading of a block set by first-cell height (``--first-cell``) or growth ratio
(``--cluster PATCH:RATIO``): the cells next to named patches get a physical height H (or grow by
the ratio), the node coordinates along the wall-normal axis growing geometrically away from the
wall (``meshgen.methods.clustering``), and every block that shares that axis
through an interface gets the same coordinates, so the interfaces stay conforming (design notes
§20).

A block axis is *linked* to the neighbour's axis it maps to (CGNS Transform) when it is tangential
to an interface; the linked axes form classes that hold one 1D coordinate array (reversed where
the Transform's sign is negative). The parametric first-cell height of a class is H over the mean
length of the grid lines that leave its wall faces, measured on the TFI mesh: for straight lines
(the pipe's wall layer) the TFI mesh's mean first-cell height is H exactly. The elliptic solver
relaxes the grading somewhat; ``first_cell_heights`` measures what the mesh has.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import ParameterError
from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.methods.clustering import Cluster, clustered_coordinates

__all__ = ["first_cell_heights", "graded_block_set", "parse_first_cell", "parse_wall_clusters"]


def parse_first_cell(specs, block_set: BlockSet) -> dict[str, float]:
    """``("0.001",)`` (every ``wall`` patch) or ``("cylinder=0.0005", ...)`` -> {patch name:
    first-cell height}; ParameterError for a malformed spec, an unknown patch or H <= 0."""
    kinds = {name: kind for name, kind in block_set.patches.values()}
    heights = {}
    for spec in specs:
        name, _, value = str(spec).rpartition("=")
        try:
            height = float(value)
        except ValueError:
            raise ParameterError(
                "first_cell", f"malformed {{name}} {spec!r}: expected H or PATCH=H, e.g. 0.001 or wall=0.001"
            ) from None
        if not (np.isfinite(height) and height > 0):
            raise ParameterError("first_cell", f"{{name}} {spec!r}: the first-cell height must be a positive length")
        if name and name not in kinds:
            raise ParameterError(
                "first_cell", f"{{name}} {spec!r}: '{block_set.name}' has no patch '{name}' (patches: {', '.join(sorted(kinds))})"
            )
        names = [name] if name else [patch for patch, kind in kinds.items() if kind == "wall"]
        if not names:
            raise ParameterError("first_cell", f"{{name}} {spec!r}: '{block_set.name}' has no wall patch: name one (PATCH=H)")
        heights.update(dict.fromkeys(names, height))
    return heights


def parse_wall_clusters(specs, block_set: BlockSet) -> dict[str, float]:
    """``("wall:1.1", ...)`` -> {patch name: growth ratio >= 1}. A block set's axes differ from
    block to block, so its clustering names a patch instead of an axis and a side."""
    kinds = {name: kind for name, kind in block_set.patches.values()}
    ratios = {}
    for spec in specs:
        parts = str(spec).split(":")
        usage = f"{{name}} {spec!r}: the multi-block geometry '{block_set.name}' takes PATCH:RATIO (e.g. wall:1.1; patches: {', '.join(sorted(kinds))})"
        if len(parts) != 2 or parts[0] not in kinds:
            raise ParameterError("cluster", usage)
        try:
            ratio = float(parts[1])
        except ValueError:
            raise ParameterError("cluster", usage) from None
        if not (np.isfinite(ratio) and ratio >= 1.0):
            raise ParameterError("cluster", f"{{name}} {spec!r}: the growth ratio must be a number >= 1")
        ratios[parts[0]] = ratio
    return ratios


def _axis_classes(block_set: BlockSet) -> tuple[dict, dict]:
    """(root, sign): for every (block, axis), the representative of its class and whether its
    coordinates run with (+1) or against (-1) the representative's."""
    parent = {(b, a): ((b, a), 1) for b in range(len(block_set.names)) for a in range(block_set.dim)}

    def find(key):
        root, sign = parent[key]
        if root == key:
            return key, 1
        top, further = find(root)
        parent[key] = (top, sign * further)
        return top, sign * further

    for interface in block_set.interfaces:
        for axis, t in enumerate(interface.transform):
            if axis == interface.face_a.axis:
                continue  # the interface's normal: not shared
            (ra, sa), (rb, sb) = find((interface.a, axis)), find((interface.b, abs(t) - 1))
            if ra != rb:
                parent[rb] = (ra, sa * sb * int(np.sign(t)))
    return {key: find(key)[0] for key in parent}, {key: find(key)[1] for key in parent}


def graded_block_set(block_set: BlockSet, heights: dict[str, float], ratios: dict[str, float] | None = None) -> BlockSet:
    """``block_set`` with the coordinates along each wall-normal axis graded so that the first
    cells on the patches of ``heights`` ({patch: height}) have that height, or, on the patches of
    ``ratios`` ({patch: growth ratio}), grow by that ratio away from the wall; the coordinates of
    every linked axis are the same. ParameterError when a height is not below the cell height the
    uniform grading gives there. Walls at both ends of an axis: both get the smaller height (the
    larger ratio); a height wins over a ratio."""
    ratios = dict(ratios or {})
    if not heights and not ratios:
        return block_set
    root, sign = _axis_classes(block_set)
    Xs = tfi_blocks(block_set) if heights else None
    walls: dict = {}  # class -> {side of the representative: [(height, mean line length)]}
    grown: dict = {}  # class -> {side: ratio}
    for (block, face_name), (name, _) in block_set.patches.items():
        if name not in heights and name not in ratios:
            continue
        face = cube.face_named(face_name, block_set.dim)
        key = (block, face.axis)
        side = face.side if sign[key] > 0 else 1 - face.side
        if name in heights:
            lines = np.sum(np.linalg.norm(np.diff(Xs[block], axis=face.axis), axis=-1), axis=face.axis)
            walls.setdefault(root[key], {}).setdefault(side, []).append((heights[name], float(np.mean(lines))))
        else:
            sides = grown.setdefault(root[key], {})
            sides[side] = max(sides.get(side, 1.0), ratios[name])
    coords = [list(c) for c in block_set.coords]
    for representative in {**grown, **walls}:
        n = len(coords[representative[0]][representative[1]]) - 1
        if representative in walls:
            wanted = {side: np.mean([h / length for h, length in found]) for side, found in walls[representative].items()}
            first = min(wanted.values())
            if first >= 1.0 / n:
                name = block_set.names[representative[0]]
                raise ParameterError(
                    "first_cell",
                    f"{{name}}: a first cell of {first:.3g} of the wall layer is not below the uniform cell (1/{n}) "
                    f"across block '{name}': give a smaller height or fewer cells",
                )
            cluster = Cluster(representative[1], _side(wanted), first_height=first)
        else:
            wanted = grown[representative]
            cluster = Cluster(representative[1], _side(wanted), ratio=max(wanted.values()))
        try:
            nodes = clustered_coordinates(n, cluster)
        except ParameterError as exc:
            raise ParameterError("first_cell", exc.template.replace("{name} ", "{name}: ")) from None
        for key, top in root.items():
            if top == representative:
                coords[key[0]][key[1]] = nodes if sign[key] > 0 else 1.0 - nodes[::-1]
    return BlockSet(**{**block_set.__dict__, "coords": tuple(tuple(c) for c in coords)})


def _side(wanted: dict) -> str:
    return "both" if len(wanted) == 2 else ("min" if 0 in wanted else "max")


def first_cell_heights(block_set: BlockSet, Xs, names) -> dict[str, dict]:
    """The heights of the first cells on the patches ``names`` of the block meshes ``Xs``: per
    patch {mean, min, max} of the distance from each wall node to its neighbour one layer in."""
    found: dict[str, list] = {}
    for (block, face_name), (name, _) in block_set.patches.items():
        if name in names:
            face = cube.face_named(face_name, block_set.dim)
            X = Xs[block]
            wall = np.take(X, -1 if face.side else 0, axis=face.axis)
            inner = np.take(X, -2 if face.side else 1, axis=face.axis)
            found.setdefault(name, []).append(np.linalg.norm(wall - inner, axis=-1).ravel())
    heights = {name: np.concatenate(parts) for name, parts in found.items()}
    return {name: {"mean": float(h.mean()), "min": float(h.min()), "max": float(h.max())} for name, h in heights.items()}
