"""meshgen: structured hexahedral and quadrilateral meshes of parametrised geometries.

    import meshgen
    result = meshgen.mesh("semicylinder", (30, 30, 30), method="elliptic")
    result.write("mesh.vtu")  # with the per-cell metrics, and mesh.vtu.quality.json

The top level holds what a user needs:

- ``mesh(geometry, dims, method="auto", ...)``: a mesh as ``meshgen mesh`` makes it (``auto``:
  a trained model of the geometry, else ``elliptic``); ``tfi(geometry, dims)`` and
  ``elliptic(geometry, dims)``: one method each;
- ``read(path)``: a mesh meshgen wrote; ``write(path, mesh)``: write one with its quality;
- ``evaluate(mesh_or_X_or_path)``: the quality report (``meshgen evaluate --json``'s schema);
- ``load_geometry(name_or_path, params)``: a geometry; ``Mesh``; the errors ``MeshgenError``
  (every input error), ``ParameterError`` (names the parameter), ``GeometryError``.

One return convention: ``mesh``, ``tfi``, ``elliptic`` and ``read`` return a ``Mesh`` (node array
``X``, the geometry, method, cell counts, clustering, the method's info, meshing seconds, notes
such as a fall-back); ``write`` and ``evaluate`` return the quality report (a dict).

The node array ``X`` is the one currency between the parts: shape ``(n1+1, n2+1, n3+1, 3)``
(2D: ``(n1+1, n2+1, 2)``), float64, index order (i, j, k) = (xi, eta, zeta).

Everything else lives in its module (``from meshgen.tfi import transfinite``, ``from
meshgen.request import MeshRequest, carry_out``, ``from meshgen.quality import cell_metrics``).
``meshgen.tfi`` and ``meshgen.elliptic`` are the functions above; their modules are reached with
``from meshgen.tfi import ...`` / ``from meshgen.elliptic import ...``. The names are imported
lazily, so ``import meshgen`` stays cheap (no torch, no trimesh).
"""

import importlib
import sys
import types

__version__ = "0.2.0"

_LAZY = {
    "mesh": "meshgen.request",
    "Mesh": "meshgen.meshing",
    "load_geometry": "meshgen.geometry",
    "read": "meshgen.api",
    "write": "meshgen.api",
    "evaluate": "meshgen.api",
    "tfi": "meshgen.api",
    "elliptic": "meshgen.api",
    "MeshgenError": "meshgen.errors",
    "ParameterError": "meshgen.errors",
    "GeometryError": "meshgen.errors",
}
_FUNCTIONS_NAMED_AS_MODULES = ("tfi", "elliptic")

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    module_name = _LAZY.get(name)
    if module_name is None:
        raise AttributeError(f"module 'meshgen' has no attribute {name!r}")
    return getattr(importlib.import_module(module_name), name)


class _Package(types.ModuleType):
    """The package, whose ``tfi`` and ``elliptic`` stay the functions: importing the submodules of
    the same names would otherwise bind the modules over them."""

    def __setattr__(self, name, value):
        if name in _FUNCTIONS_NAMED_AS_MODULES and isinstance(value, types.ModuleType):
            return  # the module stays in sys.modules["meshgen.<name>"]
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
