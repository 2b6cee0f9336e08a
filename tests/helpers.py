"""Helpers shared by several test files (one copy each)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["files_in", "full_disk_temporaries"]


def files_in(folder: Path, skip=()) -> dict:
    """Every file under ``folder`` with its bytes and every folder with None, by relative path:
    two calls compare equal only if nothing was created, removed or changed. Python's bytecode
    caches, names in ``skip`` and a test's own ``stalled*`` markers are left out."""
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
        for p in sorted(Path(folder).rglob("*"))
        if "__pycache__" not in p.parts and p.name not in skip and not p.name.startswith("stalled")
    }


def full_disk_temporaries(monkeypatch, target_name: str) -> list[Path]:
    """Make this process's next temporaries of an output named ``target_name`` links to /dev/full
    (every write to them fails with the kernel's own ENOSPC). meshgen creates its temporaries with
    O_EXCL under random names, so a link cannot be planted from outside: the test swaps the link in
    right after ``meshgen.run.publish.temporary_path`` made the file. Returns the temporaries so made."""
    from meshgen.run import atomic, publish

    made = []
    real = publish.temporary_path

    def planted(target, folder=False):
        path = real(target, folder)
        if Path(target).name == target_name and not folder:
            path.unlink()
            path.symlink_to("/dev/full")
            made.append(path)
        return path

    monkeypatch.setattr(atomic, "temporary_path", planted)
    return made


def vtk_quality(points, cells, measure):
    """VTK's ``vtkMeshQuality`` (Verdict) ``measure`` (a setter name) per cell of hexahedra (8
    corners) or quadrilaterals (4) given as points and VTK-ordered connectivity; skipped without vtk."""
    import pytest

    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    vtk_points = vtk.vtkPoints()
    vtk_points.SetData(numpy_to_vtk(np.ascontiguousarray(points, dtype=float), deep=True))
    grid = vtk.vtkUnstructuredGrid()
    grid.SetPoints(vtk_points)
    connectivity = vtk.vtkCellArray()
    offsets = np.arange(0, cells.size + 1, cells.shape[1])
    connectivity.SetData(
        numpy_to_vtk(offsets, deep=True, array_type=vtk.VTK_ID_TYPE),
        numpy_to_vtk(cells.ravel().copy(), deep=True, array_type=vtk.VTK_ID_TYPE),
    )
    grid.SetCells(vtk.VTK_HEXAHEDRON if cells.shape[1] == 8 else vtk.VTK_QUAD, connectivity)
    quality = vtk.vtkMeshQuality()
    quality.SetInputData(grid)
    getattr(quality, measure)()
    quality.Update()
    return vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality"))
