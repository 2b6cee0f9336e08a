"""The elliptic start of a block set's networks (design notes §20, "The elliptic start"): the set's
multi-block elliptic mesh on a fine grid, the target of the networks' first fit and of the pull
that keeps them near it, in place of the TFI.

The elliptic mesh solves the discrete Winslow equations the networks are trained on, so a network
fitted to it starts where the Winslow loss ends: on the pipe the fit alone meshes within a fraction
of a degree of the elliptic mesh, where the Winslow steps from the TFI took ten minutes and more
(the measured figures are in the design notes). The fine grid refines every block's parametric
nodes by one whole factor (``refinement``), so interfaces stay conforming; an extruded set solves
its section, as meshing does.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.geometry.plugins import plugin_module
from meshgen.methods.elliptic import elliptic_blocks

__all__ = ["FIT_CELLS", "FIT_NODES", "elliptic_pools", "elliptic_targets", "refined", "refinement"]

FIT_CELLS = 64  # cells per block axis the fine grid aims at (the pipe's section: 64 x 64 a block)
FIT_NODES = 60_000  # most nodes of the fine grid, all blocks together (a 3D set of 8^3-cell blocks: factor 2)


def refinement(block_set: BlockSet) -> int:
    """The whole factor by which every block axis of ``block_set`` is refined: the one that gives
    the block axes about ``FIT_CELLS`` cells on average, lowered until the fine grid holds at most
    ``FIT_NODES`` nodes, at least 1."""
    cells = [n - 1 for shape in block_set.node_shapes for n in shape]
    factor = max(1, math.ceil(FIT_CELLS / (sum(cells) / len(cells))))
    while factor > 1 and sum(math.prod((n - 1) * factor + 1 for n in shape) for shape in block_set.node_shapes) > FIT_NODES:
        factor -= 1
    return factor


def refined(block_set: BlockSet, factor: int) -> BlockSet:
    """``block_set`` with each block's parametric nodes along every axis refined ``factor`` times
    (``factor - 1`` nodes evenly between neighbours in node index, so a graded axis keeps its
    grading and matching interfaces keep matching node counts)."""

    def finer(t: np.ndarray) -> np.ndarray:
        return np.interp(np.linspace(0.0, len(t) - 1.0, (len(t) - 1) * factor + 1), np.arange(len(t)), t)

    coords = tuple(tuple(finer(np.asarray(t, dtype=float)) for t in axes) for axes in block_set.coords)
    return BlockSet(**{**block_set.__dict__, "coords": coords})


def elliptic_targets(block_set: BlockSet, spec: str | None = None) -> tuple[BlockSet, list[np.ndarray], str]:
    """(the fine block set, its node arrays as ``--method elliptic`` makes them, a one-line account)
    of ``block_set``, the set the networks are trained on (an extruded set's section), refined by
    ``refinement``. ``spec``: the plugin the set came from, whose ``elliptic_options`` (a swept CAD
    cap's ``slide_section``, ``keep_tfi``) apply as they do when meshing."""
    module = plugin_module(spec)[0] if spec else None
    options = dict(getattr(module, "elliptic_options", {}) or {})
    factor = refinement(block_set)
    fine = refined(block_set, factor)
    shape = " + ".join("x".join(str(n - 1) for n in s) for s in dict.fromkeys(fine.node_shapes))
    if options.get("keep_tfi"):
        return fine, tfi_blocks(fine), f"the TFI mesh of {shape} cells a block (the plugin keeps the TFI for elliptic)"
    if block_set.dim == 2 and "slide_section" in options:  # an extruded set's section: the section's options
        options = {"slide": options.pop("slide_section")}
    options.pop("slide_section", None)
    Xs, info = elliptic_blocks(fine, **options)
    return fine, Xs, f"the elliptic mesh of {shape} cells a block ({info.get('sweeps', 0)} cycles)"


def elliptic_pools(fine: BlockSet, Xs, center, scale: float, device, count: int | None = None, seed: int = 0) -> list[dict]:
    """Per block, {"points" (K, d) float32, "targets" (K, d) float32} on ``device``: the fine grid's
    parametric nodes and its elliptic nodes in the networks' normalised units ((X - center) / scale);
    every node, or ``count`` drawn without replacement (a fixed draw of ``seed``). The fit's pools
    (``meshgen.neural.projected_fit``) and the pull's."""
    generator = np.random.default_rng(seed)
    pools = []
    for axes, X in zip(fine.coords, Xs):
        points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, fine.dim)
        targets = (np.asarray(X, dtype=float).reshape(-1, fine.dim) - np.asarray(center)) / scale
        if count is not None and count < len(points):
            keep = np.sort(generator.choice(len(points), size=count, replace=False))
            points, targets = points[keep], targets[keep]
        pools.append(
            {
                "points": torch.from_numpy(points).float().to(device),
                "targets": torch.from_numpy(targets).float().to(device),
            }
        )
    return pools
