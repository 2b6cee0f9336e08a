"""Re-meshing an OpenFOAM case keeps it runnable: meshgen's own starting fields (also after
potentialFoam has solved them) are rewritten for the new mesh, a user's edited field is kept with
one warning line. Checked with the real potentialFoam: its answer in the semicylinder is the
uniform U = (0, 0, speed) with speed the inlet's normal velocity."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from openfoam_helpers import needs_openfoam, read_vector_field, run_tool

import meshgen.formats._foam_fields as foam_fields
from meshgen.errors import MeshgenWarning
from meshgen.formats import write_mesh
from meshgen.geometry.patches import geometry_patches
from meshgen.methods.tfi import tfi

MESH = ("mesh", "-g", "semicylinder", "--method", "tfi", "--format", "openfoam", "-q", "-o", "case", "--dims")


def solve(case) -> np.ndarray:
    result = run_tool("potentialFoam", case)
    assert result.returncode == 0, result.stdout[-2000:]
    return read_vector_field(case / "0" / "U")


@needs_openfoam
def test_remesh_after_potential_foam_runs_again(run_cli, tmp_path):
    case = tmp_path / "case"
    assert run_cli(*MESH, 8, 8, 16).returncode == 0
    first = solve(case)
    assert first.shape == (8 * 8 * 16, 3)  # the solved field of the old mesh is in 0/U
    again = run_cli(*MESH, 10, 10, 20)
    assert again.returncode == 0, again.stderr
    assert "Warning" not in again.stderr  # a solved meshgen field is meshgen's: rewritten, no warning
    second = solve(case)
    assert second.shape == (10 * 10 * 20, 3)
    assert np.abs(second - [0, 0, 1]).max() < 1e-3


@needs_openfoam
def test_user_edited_field_is_kept_with_one_warning(run_cli, tmp_path):
    case = tmp_path / "case"
    assert run_cli(*MESH, 6, 6, 12).returncode == 0
    U = case / "0" / "U"
    U.write_text(U.read_text().replace("refValue uniform -1;", "refValue uniform -2;"))
    p_before = (case / "0" / "p").read_text()
    again = run_cli(*MESH, 8, 8, 16)
    assert again.returncode == 0, again.stderr
    warnings = [line for line in again.stderr.splitlines() if line.startswith("Warning")]
    assert len(warnings) == 1 and "0/U" in warnings[0] and "0/p" not in warnings[0] and "delete it" in warnings[0]
    assert "refValue uniform -2;" in U.read_text()
    assert (case / "0" / "p").read_text() == p_before  # meshgen's p, rewritten as meshgen writes it
    assert np.abs(solve(case) - [0, 0, 2]).max() < 1e-3  # the user's inlet speed, on the new mesh


def test_deleting_a_kept_field_resets_it(run_cli, tmp_path):
    case = tmp_path / "case"
    assert run_cli(*MESH, 4, 4, 8).returncode == 0
    fresh = (case / "0" / "U").read_text()
    (case / "0" / "U").write_text(fresh.replace("type slip;", "type noSlip;"))
    kept = run_cli(*MESH, 5, 5, 10)
    assert "type noSlip;" in (case / "0" / "U").read_text() and "Warning: kept 0/U" in kept.stderr
    (case / "0" / "U").unlink()
    reset = run_cli(*MESH, 5, 5, 10)
    assert reset.returncode == 0 and "Warning" not in reset.stderr
    assert (case / "0" / "U").read_text() == fresh


def solved_like_a_solver(text: str, cells: int) -> str:
    """``text`` (meshgen's 0/U) as a solver writes it back: its own banner, the internal field a
    value per cell, a ``value`` entry on a patch, its own spacing."""
    body = text[text.find("FoamFile") :]
    body = body.replace(
        "internalField   uniform (0 0 0);", f"internalField   nonuniform List<vector>\n{cells}\n(\n" + "(0 0 1)\n" * cells + ");"
    )
    body = body.replace(
        "type zeroGradient;",
        "type            zeroGradient;\n        value           nonuniform List<vector> 4(" + "(0 0 1)" * 4 + ");",
    )
    return "/*---*\\\n| =========  OpenFOAM: The Open Source CFD Toolbox |\n\\*---*/\n" + body


@pytest.mark.parametrize("tail_bytes", [None, 4096])  # a small solved field, and one read from its head and tail
def test_a_solved_field_is_meshgens_and_is_rewritten(tmp_path, semicylinder, monkeypatch, tail_bytes):
    if tail_bytes:
        monkeypatch.setattr(foam_fields, "TAIL_BYTES", tail_bytes)
    case = tmp_path / "case"
    write_mesh(case, tfi(semicylinder, (4, 4, 8)), format="openfoam", patches=geometry_patches(semicylinder))
    fresh = (case / "0" / "U").read_text()
    (case / "0" / "U").write_text(solved_like_a_solver(fresh, 4 * 4 * 8 * 10))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshgenWarning)
        write_mesh(case, tfi(semicylinder, (5, 5, 10)), format="openfoam", patches=geometry_patches(semicylinder))
    assert (case / "0" / "U").read_text() == fresh
    # the same solved field with a patch's set-up changed is a user's: kept, with the warning
    (case / "0" / "U").write_text(solved_like_a_solver(fresh, 4 * 4 * 8 * 10).replace("type slip;", "type noSlip;"))
    with pytest.warns(MeshgenWarning, match=r"kept 0/U of .*delete it"):
        write_mesh(case, tfi(semicylinder, (4, 4, 8)), format="openfoam", patches=geometry_patches(semicylinder))
    assert "type noSlip;" in (case / "0" / "U").read_text()
