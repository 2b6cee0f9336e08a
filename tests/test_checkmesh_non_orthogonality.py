"""meshgen's internal-face non-orthogonality against OpenFOAM's checkMesh on the same cases.

Each mesh goes through meshgen's OpenFOAM writer; checkMesh prints "Mesh non-orthogonality Max: M
average: A", which ``meshgen.quality.faces_openfoam.non_orthogonality`` must reproduce within 0.1
degrees (it follows the same face and cell decompositions, so it agrees to round-off).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam

import meshgen
from meshgen.formats import write_mesh
from meshgen.geometry.patches import geometry_patches
from meshgen.quality.faces_openfoam import non_orthogonality

CASES = [
    ("semicylinder", (8, 8, 8), "tfi", {}),
    ("semicylinder", (10, 8, 12), "elliptic", {"boundary_layout": "fixed"}),
    ("flower", (10, 10, 10), "tfi", {}),
    ("canal", (6, 6, 12), "tfi", {}),
    ("semidisk", (10, 12), "tfi", {}),
]


@needs_openfoam
@pytest.mark.parametrize(("geometry", "dims", "method", "options"), CASES)
def test_internal_non_orthogonality_matches_check_mesh(tmp_path, geometry, dims, method, options):
    result = meshgen.mesh(geometry, dims, method=method, **options)
    case = write_mesh(tmp_path / "case", result.X, patches=geometry_patches(result.geometry), format="openfoam")
    log = check_mesh(case)["log"]
    printed = re.search(r"Mesh non-orthogonality Max: (\S+) average: (\S+)", log)
    assert printed, log[-2000:]
    for kernels in ("numpy", "compiled"):  # the NumPy definition, and the kernels large meshes take
        ours = non_orthogonality(result.X, kernels=kernels)["non_orthogonality_internal"]
        assert abs(ours["max"] - float(printed[1])) < 0.1
        assert abs(ours["average"] - float(printed[2])) < 0.1


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_orthogonal_box_has_zero_non_orthogonality_and_a_sheared_one_its_shear_angle(kernels):
    axes = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 2, 5), np.linspace(0, 1, 3), indexing="ij")
    box = np.stack(axes, axis=-1)
    figures = non_orthogonality(box, kernels=kernels)
    assert figures["non_orthogonality_internal"]["max"] < 1e-9
    assert figures["non_orthogonality_boundary"]["max"] < 1e-9
    # x += tan(30 deg) y: the faces normal to y tilt by 30 degrees from the cell-to-cell direction
    sheared = box.copy()
    sheared[..., 0] += np.tan(np.radians(30.0)) * sheared[..., 1]
    internal = non_orthogonality(sheared, kernels=kernels)["non_orthogonality_internal"]
    assert internal["max"] == pytest.approx(30.0, abs=1e-9)
    assert internal["worst_face"]["axis"] in (0, 1)
