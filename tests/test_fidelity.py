"""Solver fidelity: potentialFoam on meshgen's OpenFOAM cases against exact potential flows."""

from __future__ import annotations

import numpy as np
import pytest

import meshgen
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.polish import NOT_POLISHED_REASON
from meshgen.quality.fidelity import exact_velocity, missing_openfoam, potential_flow_error

needs_potential_foam = pytest.mark.skipif(missing_openfoam() is not None, reason=missing_openfoam() or "")
DIMS = (8, 8, 16)


def test_the_canal_vortex_is_a_potential_flow_tangent_to_the_tube():
    canal = load_geometry("canal")
    rng = np.random.default_rng(0)
    # On the wall (points of the side faces): U . n = 0, n the tube's normal (from the centre line).
    points = rng.random((200, 3))
    points[:, 0] = rng.integers(0, 2, 200)
    wall = canal.boundary(points)
    R = canal.values["bend_radius"]
    rho = np.hypot(wall[:, 0], wall[:, 2])
    centre = np.column_stack([R * wall[:, 0] / rho, np.zeros(200), R * wall[:, 2] / rho])
    U = exact_velocity(canal, wall)
    normal = wall - centre
    assert np.abs(np.einsum("ij,ij->i", U, normal)).max() < 1e-12
    # curl-free and divergence-free (central differences of the closed form)
    x, h = np.array([[2.1, 0.2, 0.7]]), 1e-5
    J = np.stack([(exact_velocity(canal, x + h * e) - exact_velocity(canal, x - h * e))[0] / (2 * h) for e in np.eye(3)], axis=1)
    assert abs(np.trace(J)) < 1e-8 and np.abs(J - J.T).max() < 1e-8
    assert np.linalg.norm(exact_velocity(canal, np.array([[R, 0.0, 0.0]]))) == pytest.approx(1.0)


@needs_potential_foam
def test_elliptic_and_neural_meshes_polished_or_raw_reproduce_uniform_flow(tmp_path):
    elliptic = meshgen.mesh("semicylinder", DIMS, method="elliptic")
    reference = potential_flow_error(elliptic.X, elliptic.geometry, tmp_path / "elliptic")["max"]
    assert reference < 1e-3
    tfi = meshgen.mesh("semicylinder", DIMS, method="tfi")  # an extruded mesh: exact to the solver's tolerance
    assert potential_flow_error(tfi.X, tfi.geometry, tmp_path / "tfi")["max"] < 1e-3
    polished = meshgen.mesh("semicylinder", DIMS, method="neural", polish=True)
    assert polished.info["polish"]["polished"] and polished.info["polish"]["converged"]
    assert potential_flow_error(polished.X, polished.geometry, tmp_path / "neural")["max"] <= 10 * max(reference, 1e-6)
    # The mesh meshgen gives by default: the bundled network's own (not polished). Trained on the
    # smoothed layout's lattice, where the faces solve the discrete equations, it is the extrusion
    # the solver needs to within 10x too.
    raw = meshgen.mesh("semicylinder", DIMS, method="neural")
    assert raw.info["polish"] == {"polished": False, "reason": NOT_POLISHED_REASON}
    assert potential_flow_error(raw.X, raw.geometry, tmp_path / "raw")["max"] <= 10 * max(reference, 1e-6)


@needs_potential_foam
def test_velocity_from_the_fluxes_is_openfoams_reconstruction_and_measures_the_canal(tmp_path):
    from meshgen.quality.fidelity import _read_vectors, reconstructed_velocity

    semicylinder = meshgen.mesh("semicylinder", (5, 4, 6), method="tfi")
    semicylinder.X[2, 2, 3] += [0.02, -0.01, 0.03]  # an interior node moved: the flow is no longer uniform
    potential_flow_error(semicylinder.X, semicylinder.geometry, tmp_path / "s")
    written = _read_vectors(tmp_path / "s" / "0" / "U", 5 * 4 * 6)
    ours = reconstructed_velocity(tmp_path / "s")
    assert np.abs(ours - [0.0, 0.0, 1.0]).max() > 1e-3  # a flow the check can tell apart
    # OpenFOAM v1912's written U agrees with the reconstruction in every x component; its y and z
    # are off in some cells (docs/design-fidelity.md), so only x is compared.
    np.testing.assert_allclose(ours[:, 0], written[:, 0], rtol=0, atol=1e-8)
    canal = meshgen.mesh("canal", (8, 8, 16), method="elliptic")
    result = potential_flow_error(canal.X, canal.geometry, tmp_path / "c")
    assert result["max_from_fluxes"] < 0.1  # the vortex to discretisation error
