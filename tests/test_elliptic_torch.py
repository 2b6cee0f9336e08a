"""The elliptic multigrid as torch tensor operations (meshgen.methods.multigrid_torch), run on torch's
CPU device in float64: its pieces against the NumPy solver's (operator, line solves), and its meshes
against the NumPy/numba solver's meshes (build_elliptic, tight tolerance) and the independent
discrete residual (meshgen.methods.winslow.winslow_residual). The CUDA tests skip without a GPU."""

import functools

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from meshgen.geometry.layout import relax_faces, with_layout  # noqa: E402
from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.clustering import node_coordinates  # noqa: E402
from meshgen.methods.elliptic import build_elliptic, extruded_solve  # noqa: E402
from meshgen.methods.multigrid import Level, solve_lines  # noqa: E402
from meshgen.methods.multigrid_torch import TorchLevel, solve_lines_pcr, solve_winslow_torch, torch_operator  # noqa: E402
from meshgen.methods.tfi import tfi  # noqa: E402
from meshgen.methods.winslow import component_array, stencils, winslow_operator, winslow_residual  # noqa: E402

TOL = 1e-12
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device visible to torch on this machine")


def _start(geometry, coords):
    """The start the NumPy solver's general (not extruded) path takes: TFI of the smoothed layout, faces relaxed."""
    X0 = tfi(geometry, None, coords)
    relax_faces(geometry, coords, X0)
    return X0


@pytest.mark.parametrize("dim", [2, 3])
def test_the_operator_is_the_numpy_operator(dim):
    """A randomly perturbed grid on stretched and uniform axes: residual and axial coefficients."""
    rng = np.random.default_rng(1)
    coords = node_coordinates((7, 6, 5)[:dim], ["xi:both:1.3"])
    mesh = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    mesh = mesh + 0.05 * rng.standard_normal(mesh.shape)
    R = component_array(mesh)
    expected, axial = winslow_operator(R, stencils(coords))
    level = TorchLevel(Level(coords), "cpu")
    got, got_axial = torch_operator(torch.as_tensor(R), level)
    np.testing.assert_allclose(got.numpy(), expected, rtol=0, atol=1e-13 * np.abs(expected).max())
    for a, b in zip(got_axial, axial):
        np.testing.assert_allclose(a.numpy(), b, rtol=1e-13)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("length", [2, 5, 8, 13])
def test_cyclic_reduction_is_the_thomas_algorithm(axis, length):
    """Diagonally dominant systems like the relaxation's (|sub| + |sup| < 1), every line length
    around the powers of two."""
    rng = np.random.default_rng(length)
    shape = [4, 3, 5]
    shape[axis] = length
    sub, sup = (rng.uniform(-0.45, 0.45, shape) for _ in range(2))
    rhs = rng.standard_normal([3] + shape)
    expected = solve_lines(sub, sup, rhs, axis)
    got = solve_lines_pcr(*(torch.as_tensor(a) for a in (sub, sup, rhs)), axis).numpy()
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * np.abs(expected).max())


def test_the_semicylinder_is_the_numpy_mesh_extruded_and_in_3d():
    """Extruded path (the section's 2D solve on torch) and the full 3D solve on torch from the TFI
    interior with the NumPy mesh's boundary: both the NumPy mesh to 1e-10 of the length."""
    geometry = with_layout(load_geometry("semicylinder"), "smoothed")
    coords = node_coordinates((12, 10, 8), [])
    length = geometry.characteristic_length
    X, info = build_elliptic(geometry, coords, tol=TOL, max_iter=200)
    assert info["extruded"] and info["converged"]
    X0 = tfi(geometry, None, coords)
    solve = functools.partial(solve_winslow_torch, device="cpu")
    extruded, extruded_info = extruded_solve(X0, coords, TOL, 200, length, solve=solve)
    assert extruded_info["converged"] and extruded_info["device"] == "cpu"
    assert np.abs(extruded - X).max() < 1e-10 * length
    start = X0.copy()
    start[:, :, [0, -1]] = X[:, :, [0, -1]]  # the caps: the section's solution (the 3D problem's boundary data)
    assert np.abs(start - X).max() > 1e-3 * length  # the interior starts far from the answer
    solid, solid_info = solve_winslow_torch(start, coords, tol=TOL, max_iter=200, length=length)
    assert solid_info["converged"] and solid_info["final_residual"] < 1e-10
    assert np.abs(solid - X).max() < 1e-10 * length
    assert np.abs(winslow_residual(solid, coords)).max() < 1e-10 * length


@pytest.mark.parametrize(("name", "clusters"), [("canal", ("eta:0:1.2",)), ("flower", ())])
def test_a_3d_shape_is_the_numpy_mesh(name, clusters):
    """Shapes that are no extrusion: the 3D solve from the NumPy solver's start, on a uniform and
    on a clustered grid; same cycles, same mesh to 1e-10 of the length, residual near zero."""
    geometry = with_layout(load_geometry(name), "smoothed")
    coords = node_coordinates((10, 8, 6), list(clusters))
    length = geometry.characteristic_length
    X, info = build_elliptic(geometry, coords, tol=TOL, max_iter=200)
    assert "extruded" not in info and info["converged"]
    got, got_info = solve_winslow_torch(_start(geometry, coords), coords, tol=TOL, max_iter=200, length=length)
    assert got_info["converged"] and got_info["levels"] == info["levels"]
    assert abs(got_info["iterations"] - info["iterations"]) <= 1
    assert np.abs(got - X).max() < 1e-10 * length
    residual = winslow_residual(got, coords)
    start = winslow_residual(_start(geometry, coords), coords)
    assert np.abs(residual).max() < 1e-9 * np.abs(start).max()


def test_a_2d_shape_is_the_numpy_mesh():
    geometry = with_layout(load_geometry("semidisk"), "smoothed")
    coords = node_coordinates((14, 9), [])
    X, info = build_elliptic(geometry, coords, tol=TOL, max_iter=200)
    got, _ = solve_winslow_torch(_start(geometry, coords), coords, tol=TOL, max_iter=200, length=geometry.characteristic_length)
    assert np.abs(got - X).max() < 1e-10 * geometry.characteristic_length


def test_device_cpu_is_the_numpy_solver():
    """``device="cpu"`` is the NumPy/numba path itself, bit for bit; an unknown device is a ParameterError."""
    from meshgen.errors import ParameterError

    geometry = load_geometry("canal")
    coords = node_coordinates((6, 5, 4), [])
    X, _ = build_elliptic(geometry, coords)
    Y, info = build_elliptic(geometry, coords, device="cpu")
    assert "device" not in info
    np.testing.assert_array_equal(X, Y)
    with pytest.raises(ParameterError, match="device"):
        build_elliptic(geometry, coords, device="tpu")


def test_the_graph_bookkeeping_with_a_stand_in_for_cuda_graphs(monkeypatch):
    """The CUDA-graph path's data flow on the CPU: a stand-in graph that records nothing at capture
    (the statics keep their values) and re-runs the function on the statics at each replay, writing
    into the captured output. Copies in and out, the coarsest level's hook and the eager first cycle
    must give the NumPy solver's mesh."""
    import meshgen.methods.multigrid_torch as module

    counts = {"capture": 0, "replay": 0}

    def capture(function, *static):
        counts["capture"] += 1
        saved = [t.clone() for t in static]
        output = function(*static)
        for tensor, value in zip(static, saved):
            tensor.copy_(value)

        class Graph:
            def replay(self):
                counts["replay"] += 1
                output.copy_(function(*static))

        return Graph(), output

    monkeypatch.setattr(module, "_capture", capture)
    monkeypatch.setattr(module, "_graphs_possible", lambda device: True)
    monkeypatch.setattr(module, "_on_side_stream", lambda function, *args: function(*args))
    monkeypatch.setattr(module, "_clock", lambda device, start: 0.0)
    geometry = with_layout(load_geometry("canal"), "smoothed")
    coords = node_coordinates((10, 8, 6), [])
    length = geometry.characteristic_length
    X, info = build_elliptic(geometry, coords, tol=TOL, max_iter=200)
    got, got_info = module.solve_winslow_torch(_start(geometry, coords), coords, tol=TOL, max_iter=200, length=length)
    assert counts["capture"] == 2 and counts["replay"] >= got_info["iterations"] - 1
    assert got_info["iterations"] == info["iterations"]
    assert np.abs(got - X).max() < 1e-10 * length


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal where no CUDA device is visible")
def test_cli_refuses_cuda_without_a_gpu(run_cli, tmp_path):
    result = run_cli(
        *[
            "mesh",
            "-g",
            "canal",
            "--dims",
            "6",
            "5",
            "4",
            "--method",
            "elliptic",
            "--device",
            "cuda",
            "-o",
            str(tmp_path / "m.vtu"),
        ]
    )
    assert result.returncode == 2 and "cuda" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "m.vtu").exists()


@CUDA
def test_cuda_is_the_numpy_mesh():
    """On the GPU (CUDA graph replay of the finest cycle): the canal's NumPy mesh to 1e-10."""
    geometry = with_layout(load_geometry("canal"), "smoothed")
    coords = node_coordinates((16, 12, 10), [])
    X, _ = build_elliptic(geometry, coords, tol=TOL, max_iter=200)
    got, info = build_elliptic(geometry, coords, tol=TOL, max_iter=200, device="cuda")
    assert info["device"].startswith("cuda") and info["converged"]
    assert np.abs(got - X).max() < 1e-10 * geometry.characteristic_length
