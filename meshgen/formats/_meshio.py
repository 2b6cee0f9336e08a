"""VTK (.vtu, .vtk) and XDMF (.xdmf) through meshio: hexahedron / quad cells, per-cell arrays,
and meshgen's metadata as a JSON string stored in field data ``meshgen`` (bytes as uint8)."""

from __future__ import annotations

import json

import numpy as np

from meshgen.grid import cell_connectivity, flat_points

METADATA_KEY = "meshgen"


def _file_format(path) -> str:
    return {".vtu": "vtu", ".vtk": "vtk", ".xdmf": "xdmf"}[path.suffix.lower()]


def write(path, X, cell_data, metadata):
    import meshio

    cell_type = "hexahedron" if X.ndim == 4 else "quad"
    cells = [(cell_type, cell_connectivity(X.shape[:-1]))]
    mesh = meshio.Mesh(
        flat_points(X),
        cells,
        cell_data={name: [np.asarray(values, dtype=float).reshape(-1)] for name, values in cell_data.items()},
    )
    file_format = _file_format(path)
    if metadata:
        mesh.field_data[METADATA_KEY] = np.frombuffer(json.dumps(metadata).encode(), dtype=np.uint8).copy()
    if file_format == "vtu":
        meshio.write(path, mesh, file_format="vtu", compression="zlib")
    elif file_format == "vtk":
        meshio.write(path, mesh, file_format="vtk", binary=True)
    else:
        # Inline XML keeps the mesh one self-contained file, so the atomic rename covers all of it.
        meshio.xdmf.write(path, mesh, data_format="XML")


def read(path):
    import meshio

    mesh = meshio.read(path)
    return mesh


def metadata_of(mesh) -> dict:
    """meshgen's metadata stored in a mesh read back by meshio, or {}."""
    raw = mesh.field_data.get(METADATA_KEY)
    if raw is None:
        return {}
    try:
        return json.loads(np.asarray(raw, dtype=np.uint8).tobytes().decode())
    except (ValueError, UnicodeDecodeError):
        return {}
