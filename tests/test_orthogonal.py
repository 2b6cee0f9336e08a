"""Orthogonality at chosen walls (meshgen.methods.orthogonal): the first cell layer leaves the wall along
its normal, checked against the walls' closed-form normals."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.errors import MeshgenError
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.elliptic import elliptic
from meshgen.methods.orthogonal import inner_block, parse_walls
from meshgen.methods.winslow import winslow_residual
from meshgen.quality import quality_report


def _angle_from(normal, edges) -> np.ndarray:
    """Degrees between each edge (..., d) and the line of the unit ``normal`` (..., d)."""
    cosine = np.abs((edges * normal).sum(-1)) / np.linalg.norm(edges, axis=-1)
    return np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))


def test_first_layer_meets_flat_and_curved_walls_at_right_angles(semicylinder):
    """Semicylinder, clustered at the flat wall eta0 (the plane y = 0, normal (0, 1, 0)); the arc
    wall eta1 (the cylinder x^2 + y^2 = 1, normal radial)."""
    dims = (12, 10, 6)
    coords = node_coordinates(dims, ["eta:0:1.2"])
    plain, _ = elliptic(semicylinder, coords=coords)
    X, info = elliptic(semicylinder, coords=coords, orthogonal=("eta0", "eta1"))
    assert info["converged"] and info["orthogonal"] == ["eta0", "eta1"]

    def flat(Y):  # the first layer's edges off y = 0, at nodes inside the face
        return _angle_from(np.array([0.0, 1.0, 0.0]), Y[1:-1, 1, 1:-1] - Y[1:-1, 0, 1:-1])

    def curved(Y):
        wall = Y[1:-1, -1, 1:-1]
        radial = np.concatenate([wall[..., :2], np.zeros(wall.shape[:-1] + (1,))], axis=-1)
        radial /= np.linalg.norm(radial, axis=-1, keepdims=True)
        return _angle_from(radial, Y[1:-1, -2, 1:-1] - wall)

    assert flat(X).max() < 1e-9 and flat(plain).max() > 5.0
    assert curved(X).max() < 1e-3 and curved(plain).max() > 5.0
    # the first layer keeps its distance from the wall (the clustering)
    np.testing.assert_allclose(
        X[1:-1, 1, 1:-1, 1], np.linalg.norm(plain[1:-1, 1, 1:-1] - plain[1:-1, 0, 1:-1], axis=-1), rtol=1e-12
    )
    assert quality_report(X)["inverted"]["count"] == 0
    # beyond the fixed first layers the nodes solve the Winslow equations
    block = inner_block(parse_walls(["eta0", "eta1"], 3), 3)
    residual = winslow_residual(X[block], [np.asarray(t)[b] for t, b in zip(coords, block)])
    assert np.abs(residual).max() < 1e-4 * np.abs(winslow_residual(X, coords)).max()


def test_2d_wall(semidisk):
    X, _ = elliptic(semidisk, (12, 10), orthogonal=("eta0",))
    assert _angle_from(np.array([0.0, 1.0]), X[1:-1, 1] - X[1:-1, 0]).max() < 1e-9


def test_unknown_wall_is_an_error(semidisk):
    with pytest.raises(MeshgenError, match="unknown face 'zeta0'"):
        elliptic(semidisk, (8, 8), orthogonal=("zeta0",))


def test_cli(run_cli):
    result = run_cli("mesh", "-m", "elliptic", "-g", "semidisk", "--dims", "8", "8", "--orthogonal", "eta9", "-o", "x.vtu")
    assert result.returncode == 2 and result.stderr.strip().endswith("(faces of a 2D mesh: xi0, xi1, eta0, eta1)")
    result = run_cli("mesh", "-m", "tfi", "-g", "semidisk", "--dims", "8", "8", "--orthogonal", "eta0", "-o", "x.vtu")
    assert result.returncode == 2 and "--orthogonal does not apply to method 'tfi'" in result.stderr
