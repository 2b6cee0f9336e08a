"""A mesh from Python in one call, as ``meshgen mesh`` makes it::

    import meshgen
    result = meshgen.mesh("semicylinder", (30, 30, 30), method="elliptic")
    result.write("mesh.vtu")  # the mesh with its per-cell metrics, and mesh.vtu.quality.json

``result.X`` is the node array, ``result.quality`` the per-cell metrics ({metric: (cells,)}),
``result.report()`` the quality report of ``meshgen evaluate --json``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from meshgen.errors import ParameterError


@dataclass
class Mesh:
    """A mesh made by ``mesh``: node array ``X`` (n1+1, n2+1[, n3+1], dim), the geometry and
    method that made it, the cell counts and clustering asked for, the method's ``info`` and the
    meshing time in seconds."""

    X: np.ndarray
    geometry: object  # meshgen.geometry.Geometry
    method: str
    dims: tuple[int, ...]
    cluster: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def quality(self) -> dict[str, np.ndarray]:
        """The seven per-cell metrics, each (n1*n2[*n3],) in C order of the cells (degrees for
        angles and non-orthogonality): ``meshgen.quality.cell_metrics``."""
        from meshgen.quality import cell_metrics

        return cell_metrics(self.X)

    def report(self) -> dict:
        """The quality report (``meshgen evaluate --json``'s schema), boundary deviation included."""
        from meshgen.quality import quality_report

        return quality_report(self.X, self.geometry)

    def metadata(self) -> dict:
        """What the written files record of how the mesh was made."""
        return {
            **run_metadata(self.method, self.geometry, self.dims, self.cluster),
            "meshing_seconds": self.seconds,
            **({"method_info": self.info} if self.info else {}),
        }

    def write(self, path) -> dict:
        """Write the mesh (format from the extension) with its per-cell metrics as cell data, and
        ``<path>.quality.json``; atomic. Returns the quality report."""
        from meshgen.quality import write_mesh_with_quality

        return write_mesh_with_quality(path, self.X, self.geometry, self.metadata())


def run_metadata(method: str, geometry, dims, cluster=()) -> dict:
    """What every mesh file records of the run that made it: meshgen's version, the method, the
    geometry with its parameters, the cell counts and the clustering asked for."""
    from meshgen import __version__

    return {
        "meshgen_version": __version__,
        "method": method,
        "geometry": geometry.name,
        "params": geometry.values,
        "dims": list(dims),
        **({"cluster": list(cluster)} if cluster else {}),
    }


def mesh(geometry, dims, method: str = "tfi", *, params: dict | None = None, cluster=(), progress=None, **options) -> Mesh:
    """Mesh ``geometry`` (a name, a plugin file's path, or a loaded Geometry) with ``dims`` cells
    per axis (two numbers for a 2D geometry, three for 3D) by ``method`` (``meshgen.methods``:
    tfi, elliptic, neural ...). ``params``: geometry parameters over its defaults (names and paths
    only); ``cluster``: wall clustering specs such as ``"zeta:both:1.1"``; ``progress``: a callback
    for methods that report it; ``options``: the method's own (``tol``, ``max_iter``; ``model`` a
    checkpoint path for ``neural``). Raises MeshgenError (ParameterError naming the parameter) for
    bad input."""
    from meshgen.clustering import node_coordinates
    from meshgen.geometry import load_geometry
    from meshgen.methods import get_method, make_mesh
    from meshgen.tfi import check_axes

    if isinstance(geometry, str):
        geometry = load_geometry(geometry, params)
    elif params:
        from meshgen.geometry import bind, check_boundary

        geometry = bind(geometry, params)
        check_boundary(geometry)
    dims = tuple(int(n) for n in dims)
    if any(n < 1 for n in dims):
        raise ParameterError("dims", f"{{name}} must be positive cell counts, got {' '.join(map(str, dims))}")
    check_axes(geometry, dims)
    cluster = tuple(cluster)
    coords = node_coordinates(dims, cluster)
    if progress is not None and "progress" in get_method(method).options:
        options["progress"] = progress
    start = time.perf_counter()
    X, info = make_mesh(method, geometry, coords, **options)
    return Mesh(X, geometry, method, dims, cluster, info, time.perf_counter() - start)
