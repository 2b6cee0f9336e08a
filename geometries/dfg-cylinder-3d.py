"""The 3D channel with a cylinder of the DFG benchmark (Schaefer and Turek, 1996; 3D-1Z): the
``dfg-cylinder`` section (channel 2.2 x 0.41, cylinder D = 0.1 at (0.2, 0.2)) extruded 0.41
along z, the cylinder spanning the channel; the same twelve blocks (meshgen.geometry.blocks), each the 2D
block times [0, 0.41]; the front and back (z = 0 and z = 0.41) are walls.
"""

import numpy as np

from meshgen.geometry.plugins import plugin_module
from meshgen.methods.tfi import transfinite

_section, _ = plugin_module("dfg-cylinder")

name = "dfg-cylinder-3d"
dim = 3
description = "DFG 3D channel 2.2 x 0.41 x 0.41 with a cylinder (D = 0.1 at (0.2, 0.2)) spanning it: 12 blocks"
params = {}
DEPTH = 0.41
dims_meaning = "N M K: as dfg-cylinder's N M (around a quarter of the cylinder, across the O-grid), K cells along z"
blocks = _section.blocks
interfaces = list(_section.interfaces)
block_patches = {
    block: {**faces, "zeta0": ("walls", "wall"), "zeta1": ("walls", "wall")} for block, faces in _section.block_patches.items()
}


def characteristic_length():
    return float(np.sqrt(_section.LENGTH**2 + _section.HEIGHT**2 + DEPTH**2))


def block_coords(dims):
    n, m, k = dims
    section = _section.block_coords((n, m))
    along = np.linspace(0.0, 1.0, k + 1)
    return {block: [*coords, along] for block, coords in section.items()}


def boundary(block, points):
    """(N, 3) points on the unit cube's boundary -> block ``block``'s boundary: the section's block
    map (its Coons patch on the caps) times z = DEPTH * zeta."""
    xy = transfinite(lambda p: _section.boundary(block, p), [points[:, 0], points[:, 1]])
    return np.column_stack([xy, DEPTH * points[:, 2]])
