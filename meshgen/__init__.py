"""meshgen: structured hexahedral and quadrilateral meshes of parametrised geometries.

    import meshgen
    result = meshgen.mesh("semicylinder", (30, 30, 30), method="elliptic")
    result.write("mesh.vtu")  # with the per-cell metrics, and mesh.vtu.quality.json

The node array ``X`` is the one currency between the parts: shape ``(n1+1, n2+1, n3+1, 3)``
(2D: ``(n1+1, n2+1, 2)``), float64, index order (i, j, k) = (xi, eta, zeta).

Submodules hold the methods (``from meshgen.tfi import tfi``, ``from meshgen.elliptic import
elliptic``); the names below are imported lazily so that ``import meshgen`` stays cheap (no torch, no trimesh).
"""

__version__ = "0.2.0"

_LAZY = {
    "mesh": "meshgen.meshing",
    "Mesh": "meshgen.meshing",
    "load_geometry": "meshgen.geometry",
    "list_geometries": "meshgen.geometry",
    "Geometry": "meshgen.geometry",
    "transfinite": "meshgen.tfi",
    "parametric_grid": "meshgen.tfi",
    "make_mesh": "meshgen.methods",
    "winslow_residual": "meshgen.winslow",
    "node_coordinates": "meshgen.clustering",
    "write_mesh": "meshgen.formats",
    "read_mesh": "meshgen.formats",
    "cell_metrics": "meshgen.quality",
    "write_mesh_with_quality": "meshgen.quality",
    "quality_report": "meshgen.quality",
    "boundary_deviation": "meshgen.deviation",
    "MeshgenError": "meshgen.errors",
    "ParameterError": "meshgen.errors",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    module_name = _LAZY.get(name)
    if module_name is None:
        raise AttributeError(f"module 'meshgen' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module_name), name)
