"""What a mesh request returns: the ``Mesh`` (node array, how it was made, what it measured) and
the one description of a run that every written file records (``run_metadata``). A block set's
mesh (``meshgen.geometry.blocks``) is a Mesh too: ``X`` None, ``blocks`` its node arrays, ``geometry`` the
``BlockSet``."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.errors import FormatError
from meshgen.formats.multiblock import write_blocks
from meshgen.geometry.blocks import merged_mesh
from meshgen.geometry.patches import Patch, as_records
from meshgen.quality import (
    cell_metrics,
    cell_metrics_unstructured,
    quality_report,
    sidecar_path,
    write_json,
    write_mesh_alone,
    write_mesh_with_quality,
)
from meshgen.quality.deviation import block_set_deviation
from meshgen.quality.merged import merged_reports
from meshgen.run.publish import publishing

__all__ = ["Mesh", "run_metadata"]


@dataclass
class Mesh:
    """A mesh: node array ``X`` (n1+1, n2+1[, n3+1], dim), float64 (None when the mesh was streamed
    block by block into ``output`` and never held in memory), the geometry and method that made
    it, the cell counts and clustering asked for, the method's ``info``, the meshing time in
    seconds (the median of ``timings``, one per repeat), the quality report when one was
    measured, the file written (or None), its boundary patches, and the lines said about the run
    (the model used, a fall-back to another method). A block set's mesh: ``X`` None, ``blocks``
    one node array per block (interface nodes identical), ``geometry`` the ``meshgen.geometry.blocks.BlockSet``;
    its quality is that of the merged unstructured mesh."""

    X: np.ndarray | None
    geometry: object  # meshgen.geometry.plugins.Geometry
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
    blocks: list[np.ndarray] | None = None

    @property
    def quality(self) -> dict[str, np.ndarray]:
        """The seven per-cell metrics, each (n1*n2[*n3],) in C order of the cells (degrees for
        angles and non-orthogonality): ``meshgen.quality.cell_metrics``; of a block set, in the
        merged mesh's cell order (block after block)."""
        if self.blocks is not None:
            return cell_metrics_unstructured(*merged_mesh(self.geometry, self.blocks)[:2])
        return cell_metrics(self.X)

    def report(self) -> dict:
        """The quality report (``meshgen evaluate --json``'s schema), boundary deviation included:
        the one measured when the mesh was made, else measured now."""
        if self.quality_report is None:
            self.quality_report = self._measure()
        return self.quality_report

    def metadata(self) -> dict:
        """What the written files record of how the mesh was made. A block set is recorded as such
        (``block_set``, ``block_dims``, the cells of each block), not as one geometry's grid."""
        recorded = {
            **run_metadata(self.method, self.geometry, self.dims, self.cluster),
            **({"meshing_seconds": self.seconds} if self.X is not None or self.blocks is not None else {}),
            **({"method_info": self.info} if self.info else {}),
            **({"patches": as_records(self.patches)} if self.patches else {}),
        }
        if self.blocks is not None:
            recorded["block_set"] = recorded.pop("geometry")
            recorded["block_dims"] = recorded.pop("dims")
            recorded["blocks"] = {
                name: [len(t) - 1 for t in coords] for name, coords in zip(self.geometry.names, self.geometry.coords)
            }
        return recorded

    def write(self, path, format_name: str | None = None, quality: bool = True) -> dict | None:
        """Write the mesh (format from the extension, or ``format_name``) atomically; with
        ``quality`` its per-cell metrics as cell data (structured meshes) and
        ``<path>.quality.json``, the quality report returned; without, the mesh alone (and a
        previous sidecar under that name removed) and None."""
        if self.blocks is None:
            options = {"format": format_name} if format_name else {}
            if quality:
                return write_mesh_with_quality(path, self.X, self.geometry, self.metadata(), **options)
            write_mesh_alone(path, self.X, self.metadata(), **options)
            return None
        report = self._measure() if quality else None
        with publishing(path, FormatError) as publication:  # the mesh and its sidecar take their names together
            written = write_blocks(path, self.geometry, self.blocks, self.metadata(), format_name)
            if report is None:
                publication.remove(sidecar_path(written))
            else:
                write_json(sidecar_path(written), {"mesh": os.path.basename(written), **self.metadata(), **report})
        if report is not None:
            self.quality_report = {"file": str(written), **report}
        return self.quality_report if quality else None

    def _measure(self) -> dict:
        if self.blocks is None:
            return quality_report(self.X, self.geometry)
        # Measured merged, interfaces as interior faces, with the block set's boundary deviation.
        points, cells, owner = merged_mesh(self.geometry, self.blocks)
        shapes = [tuple(n - 1 for n in X.shape[:-1]) for X in self.blocks]
        deviation = block_set_deviation(self.geometry, self.blocks)
        return merged_reports(points, cells, owner, self.geometry.names, shapes, self.geometry, deviation)[0]


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
