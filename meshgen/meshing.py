"""What a mesh request returns: the ``Mesh`` (node array, how it was made, what it measured) and
the one description of a run that every written file records (``run_metadata``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.patches import Patch, as_records
from meshgen.quality import cell_metrics, quality_report, write_mesh_with_quality

__all__ = ["Mesh", "run_metadata"]


@dataclass
class Mesh:
    """A mesh: node array ``X`` (n1+1, n2+1[, n3+1], dim), float64 (None when the mesh was streamed
    block by block into ``output`` and never held in memory), the geometry and method that made
    it, the cell counts and clustering asked for, the method's ``info``, the meshing time in
    seconds (the median of ``timings``, one per repeat), the quality report when one was
    measured, the file written (or None), its boundary patches, and the lines said about the run
    (the model used, a fall-back to another method)."""

    X: np.ndarray | None
    geometry: object  # meshgen.geometry.Geometry
    method: str
    dims: tuple[int, ...]
    cluster: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)
    seconds: float = 0.0
    quality_report: dict | None = None
    output: Path | None = None
    patches: tuple[Patch, ...] = ()
    timings: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def quality(self) -> dict[str, np.ndarray]:
        """The seven per-cell metrics, each (n1*n2[*n3],) in C order of the cells (degrees for
        angles and non-orthogonality): ``meshgen.quality.cell_metrics``."""
        return cell_metrics(self.X)

    def report(self) -> dict:
        """The quality report (``meshgen evaluate --json``'s schema), boundary deviation included:
        the one measured when the mesh was made, else measured now."""
        if self.quality_report is None:
            self.quality_report = quality_report(self.X, self.geometry)
        return self.quality_report

    def metadata(self) -> dict:
        """What the written files record of how the mesh was made."""
        return {
            **run_metadata(self.method, self.geometry, self.dims, self.cluster),
            **({"meshing_seconds": self.seconds} if self.X is not None else {}),
            **({"method_info": self.info} if self.info else {}),
            **({"patches": as_records(self.patches)} if self.patches else {}),
        }

    def write(self, path) -> dict:
        """Write the mesh (format from the extension) with its per-cell metrics as cell data, and
        ``<path>.quality.json``; atomic. Returns the quality report."""
        return write_mesh_with_quality(path, self.X, self.geometry, self.metadata())


def run_metadata(method: str, geometry, dims, cluster=()) -> dict:
    """What every mesh file records of the run that made it: meshgen's version, the method, the
    geometry with its parameters, the cell counts and the clustering asked for."""
    return {
        "meshgen_version": __version__,
        "method": method,
        "geometry": geometry.name,
        "params": geometry.values,
        "dims": list(dims),
        **({"cluster": list(cluster)} if cluster else {}),
    }
