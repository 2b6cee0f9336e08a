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

Everything else lives in its module (``from meshgen.methods.tfi import transfinite``, ``from
meshgen.run.request import MeshRequest, carry_out``, ``from meshgen.quality import cell_metrics``).
``meshgen.tfi`` and ``meshgen.elliptic`` are the functions above; their modules are reached with
``from meshgen.methods.tfi import ...`` / ``from meshgen.methods.elliptic import ...``. The names are
imported lazily, so ``import meshgen`` stays cheap (no torch, no trimesh)."""

import importlib
import importlib.abc
import importlib.util
import sys
import types

__version__ = "0.2.0"

_LAZY = {
    "mesh": "meshgen.run.request",
    "Mesh": "meshgen.run.meshing",
    "load_geometry": "meshgen.geometry.plugins",
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


# Modules of 0.2's flat layout, by their new homes: ``import meshgen.tfi`` (as plugins written for
# 0.2 do), ``from meshgen.request import MeshRequest`` and the others keep working (design notes §13).
_MOVED = {
    "meshgen.anderson": "meshgen.methods.anderson",
    "meshgen.atomic": "meshgen.run.atomic",
    "meshgen.block_extrusion": "meshgen.geometry.extrusion",
    "meshgen.block_grading": "meshgen.geometry.grading",
    "meshgen.blocks": "meshgen.geometry.blocks",
    "meshgen.chunked": "meshgen.run.chunked",
    "meshgen.clustering": "meshgen.methods.clustering",
    "meshgen.correction": "meshgen.methods.correction",
    "meshgen.cube": "meshgen.geometry.cube",
    "meshgen.deviation": "meshgen.quality.deviation",
    "meshgen.domain": "meshgen.geometry.domain",
    "meshgen.elliptic": "meshgen.methods.elliptic",
    "meshgen.elliptic_blocks": "meshgen.methods.elliptic",
    "meshgen.fidelity": "meshgen.quality.fidelity",
    "meshgen.gates": "meshgen.quality.gates",
    "meshgen.grid": "meshgen.geometry.grid",
    "meshgen.inputs": "meshgen.run.inputs",
    "meshgen.layout": "meshgen.geometry.layout",
    "meshgen.layout_family": "meshgen.geometry.layout_family",
    "meshgen.layout_start": "meshgen.geometry.layout_start",
    "meshgen.limits": "meshgen.run.limits",
    "meshgen.meshing": "meshgen.run.meshing",
    "meshgen.meshing_blocks": "meshgen.run.meshing",
    "meshgen.mlp_numpy": "meshgen.neural.mlp_numpy",
    "meshgen.orthogonal": "meshgen.methods.orthogonal",
    "meshgen.patches": "meshgen.geometry.patches",
    "meshgen.plots": "meshgen.cli.plots",
    "meshgen.plugin_calls": "meshgen.geometry.plugin_calls",
    "meshgen.polish": "meshgen.methods.polish",
    "meshgen.publish": "meshgen.run.publish",
    "meshgen.request": "meshgen.run.request",
    "meshgen.resources": "meshgen.run.resources",
    "meshgen.scheduler": "meshgen.run.scheduler",
    "meshgen.signals": "meshgen.run.signals",
    "meshgen.surface": "meshgen.geometry.surface",
    "meshgen.tables": "meshgen.cli.tables",
    "meshgen.tfi": "meshgen.methods.tfi",
    "meshgen.trust": "meshgen.run.trust",
    "meshgen.winslow": "meshgen.methods.winslow",
    "meshgen.winslow_compiled": "meshgen.methods.winslow_compiled",
}
_MOVED_PACKAGES = {
    "meshgen.commands": "meshgen.cli",
    "meshgen.comparison": "meshgen.cli.comparison",
    "meshgen.shapes": "meshgen.geometry.shapes",
}


def _new_name(old: str) -> str | None:
    if old in _MOVED:
        return _MOVED[old]
    for package, new in _MOVED_PACKAGES.items():
        if old == package or old.startswith(package + "."):
            return new + old[len(package) :]
    return None


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports a module of 0.2's layout as its new module (the same object, not a copy)."""

    def find_spec(self, fullname, path=None, target=None):
        new = _new_name(fullname) if fullname.startswith("meshgen.") else None
        return None if new is None else importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        module = importlib.import_module(_new_name(spec.name))
        spec.loader_state = module.__spec__  # the import machinery sets the old name's spec on it next
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state


sys.meta_path.insert(0, _MovedModuleFinder())  # before the path finder, which would load a second copy


class _Package(types.ModuleType):
    """The package, whose ``tfi`` and ``elliptic`` stay the functions: importing the submodules of
    the same names would otherwise bind the modules over them."""

    def __setattr__(self, name, value):
        if name in _FUNCTIONS_NAMED_AS_MODULES and isinstance(value, types.ModuleType):
            return  # the module stays in sys.modules["meshgen.<name>"]
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
