"""The meshing methods: each maps a geometry and parametric node coordinates to node arrays.

- ``registry``: the methods by name (``tfi``, ``elliptic``, the neural ones) for every caller;
- ``tfi``: transfinite interpolation; ``clustering``: wall-clustered node coordinates;
- ``elliptic``: the one elliptic solver's entry points (a geometry: ``elliptic``; a block set:
  ``elliptic_blocks``), the Winslow equations solved by nonlinear multigrid: ``multigrid`` (one
  grid), ``multigrid_set`` (every block of a set on every level), ``interfaces`` (halo layers,
  junctions), ``sliding`` (nodes on flat patches), the operator (``winslow``), compiled kernels
  (``winslow_compiled``, ``winslow_compiled_2d``), ``anderson`` acceleration, ``orthogonal`` walls;
- ``polish``: Winslow cycles from a network's mesh; ``correction``: the boundary correction of a
  mapped grid. The networks themselves are ``meshgen.neural``.

``from meshgen.methods import make_mesh`` (and the other names of ``registry``) keeps working as
in 0.2; they are imported lazily.
"""

import importlib

_REGISTRY_NAMES = (
    "METHODS",
    "NEURAL",
    "NEURAL_OPTIONS",
    "TRAINED",
    "Method",
    "build_tfi",
    "get_method",
    "make_mesh",
    "register_method",
)

__all__ = list(_REGISTRY_NAMES)


def __getattr__(name):
    if name in _REGISTRY_NAMES:
        return getattr(importlib.import_module("meshgen.methods.registry"), name)
    raise AttributeError(f"module 'meshgen.methods' has no attribute {name!r}")
