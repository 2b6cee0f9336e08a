"""The functions of meshgen's top level that are not a module's own: ``tfi`` and ``elliptic`` (a
mesh by one method), ``read`` and ``write`` (a Mesh from and to a file) and ``evaluate`` (the
quality report of a mesh, a node array or a file). Every function that makes or reads a mesh
returns a ``meshgen.run.meshing.Mesh``; ``write`` and ``evaluate`` return the quality report (the
schema of ``meshgen evaluate --json``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.formats import read_mesh, write_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.quality import as_node_array, cells_for_quality, evaluate_file, quality_report, recorded_metadata
from meshgen.run.meshing import Mesh
from meshgen.run.request import mesh

__all__ = ["elliptic", "evaluate", "read", "tfi", "write"]


def tfi(geometry, dims, *, params: dict | None = None, cluster=(), boundary_layout: str | None = None) -> Mesh:
    """Transfinite interpolation of ``geometry`` with ``dims`` cells per axis: ``mesh(geometry,
    dims, "tfi", ...)``. ``boundary_layout``: "fixed" (the geometry's own map, the default) or
    "smoothed"."""
    return mesh(geometry, dims, "tfi", params=params, cluster=cluster, boundary_layout=boundary_layout)


def elliptic(geometry, dims, *, params: dict | None = None, cluster=(), progress=None, **options) -> Mesh:
    """The Winslow elliptic mesh of ``geometry`` with ``dims`` cells per axis: ``mesh(geometry, dims,
    "elliptic", ...)``; ``options``: ``tol``, ``max_iter``, ``boundary_layout``, ``orthogonal``."""
    return mesh(geometry, dims, "elliptic", params=params, cluster=cluster, progress=progress, **options)


def read(path) -> Mesh:
    """The mesh meshgen wrote to ``path`` (any format ``meshgen.formats.read_mesh`` reads) as a Mesh:
    its node array, and the geometry (None when it cannot be loaded here), method, cells,
    clustering, method info and meshing time the file or its sidecar records. MeshgenError for a
    file that is not a structured grid of recorded cell counts (``evaluate`` measures any mesh)."""
    data = read_mesh(path)
    metadata = recorded_metadata(path, data)
    points, cells, _ = cells_for_quality(data)
    dims = tuple(int(n) for n in metadata.get("dims") or ())
    X = as_node_array(points, cells, dims) if dims else None
    if X is None:
        raise MeshgenError(f"{path} is no structured grid meshgen recorded (meshgen.evaluate measures any mesh)")
    geometry = None
    if isinstance(metadata.get("geometry"), str):
        try:
            geometry = load_geometry(metadata["geometry"], dict(metadata.get("params") or {}))
        except MeshgenError:
            geometry = None  # a plugin geometry not installed here
    seconds = metadata.get("meshing_seconds")
    return Mesh(
        X,
        geometry,
        str(metadata.get("method", "")),
        dims,
        tuple(metadata.get("cluster") or ()),
        dict(metadata.get("method_info") or {}),
        float(seconds) if isinstance(seconds, (int, float)) else 0.0,
        output=Path(path),
    )


def write(path, mesh: Mesh, *, quality: bool = True) -> dict | None:
    """Write ``mesh`` to ``path`` (format from the extension), atomically: with ``quality`` the
    per-cell metrics as cell data and ``<path>.quality.json`` too, and the quality report returned;
    without, the mesh alone and None. A block set's mesh (``mesh.blocks``) is written as
    ``meshgen.formats.multiblock`` writes it (.cgns a zone per block, OpenFOAM, merged .vtu ...)."""
    if not isinstance(mesh, Mesh):
        raise MeshgenError(f"write takes a meshgen.Mesh, got {type(mesh).__name__}")
    if quality or mesh.blocks is not None:  # a block set: meshgen.formats.multiblock
        return mesh.write(path, quality=quality)
    write_mesh(path, mesh.X, metadata=mesh.metadata())
    return None


def evaluate(subject, geometry=None) -> dict:
    """The quality report (``meshgen evaluate --json``'s schema) of a Mesh, a node array ``X``
    ((n1+1, n2+1[, n3+1], dim)) or a mesh file's path. ``geometry`` (a Geometry; for a file also a
    name): what the boundary deviation is measured against (default: the mesh's own, or what the
    file records; none for a bare node array)."""
    if isinstance(subject, Mesh):
        return subject.report() if geometry is None else quality_report(subject.X, geometry)
    if isinstance(subject, (str, os.PathLike)):
        return evaluate_file(subject, geometry)
    return quality_report(np.asarray(subject, dtype=float), geometry)
