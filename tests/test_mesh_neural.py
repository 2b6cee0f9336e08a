"""meshgen mesh from trained models: the bundled model, --checkpoint, the boundary correction, clustering, the
choice of model, and the inputs that must fail without running code or writing anything."""

import copy
import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from neural_helpers import direct_correction, tiny_config

from meshgen.geometry.plugins import load_geometry
from meshgen.methods.clustering import clustered_coordinates, node_coordinates, parse_cluster
from meshgen.methods.correction import add_boundary_correction, boundary_errors, correct_boundary
from meshgen.methods.polish import NOT_POLISHED_REASON, polishes_by_default
from meshgen.methods.tfi import parametric_grid, tfi, transfinite, transfinite_on_grid
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.checkpoint_data import read_plain_checkpoint
from meshgen.neural.config import resolve_config, to_dict
from meshgen.neural.gpu_forward import evaluate_on_grid
from meshgen.neural.model import bubble, network_from_description
from meshgen.neural.models import MODELS_DIR
from meshgen.neural.network_map import mesh_from_model
from meshgen.neural.train import train
from meshgen.quality import quality_report

BUNDLED = MODELS_DIR / "semicylinder" / "checkpoint.pt"
THREE_D = Path(__file__).resolve().parent / "data" / "semicylinder-3d-model.pt"  # 0.2's bundled model: a 3D network


@pytest.fixture(scope="module")
def soft_2d(tmp_path_factory, semidisk):
    """A tiny soft-boundary semidisk model: its boundary nodes are visibly off the boundary."""
    folder = tmp_path_factory.mktemp("soft2d")
    train(tiny_config(), semidisk, folder, summary=False)
    return folder / "checkpoint.pt"


@pytest.fixture(scope="module")
def soft_3d(tmp_path_factory, semicylinder):
    folder = tmp_path_factory.mktemp("soft3d")
    train(tiny_config("points.interior=125"), semicylinder, folder, summary=False)
    return folder / "checkpoint.pt"


def network_at(checkpoint, coords, geometry):
    """The map written the slow, plain way: torch.nn layers on the full (N, d) grid of points."""
    model = checkpoint["model"]
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    network = network_from_description(model)
    with torch.no_grad():
        N = network(torch.from_numpy(grid.reshape(-1, len(coords))).float()).double().numpy().reshape(grid.shape)
    if model["exact_boundary"]:
        from meshgen.geometry.layout import trained_layout, with_layout

        geometry = with_layout(geometry, trained_layout(checkpoint))  # the boundary it was trained on
        return tfi(geometry, None, coords) + model["scale"] * bubble(grid)[..., None] * N
    return np.asarray(model["center"]) + model["scale"] * N


def read_points(path, dims):
    import meshio

    return meshio.read(path).points[:, : len(dims)].reshape(*[n + 1 for n in dims], len(dims))


def one_line_error(result):
    return result.returncode == 2 and result.stderr.startswith("Error: ") and result.stderr.strip().count("\n") == 0


# ---------------------------------------------------------------------------------------------
# the bundled model


def test_bundled_model_meshes_30_cubed_with_no_inverted_cell(run_cli, tmp_path):
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    result = run_cli("mesh", "--dims", 30, 30, 30, "-o", "m.vtu")
    assert result.returncode == 0, result.stderr
    first = result.stdout.splitlines()[0]
    assert first.startswith("model: ") and str(BUNDLED) in first and "bundled" in first and "exact" in first
    assert f"not polished ({NOT_POLISHED_REASON}; --polish" in result.stdout  # the summary says so
    sidecar = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    assert sidecar["method"] == "neural" and sidecar["geometry"] == "semicylinder"
    model = sidecar["method_info"]["model"]
    assert model["source"] == "bundled" and model["preset"] == "exact"
    assert model["sha256"] == hashlib.sha256(BUNDLED.read_bytes()).hexdigest()
    # Independent check of validity: VTK's (Verdict's) scaled Jacobian of every cell is positive.
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(tmp_path / "m.vtu"))
    reader.Update()
    quality = vtk.vtkMeshQuality()
    quality.SetInputData(reader.GetOutput())
    quality.SetHexQualityMeasureToScaledJacobian()
    quality.Update()
    jacobian = vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality"))
    assert len(jacobian) == 27000 and jacobian.min() > 0
    assert sidecar["inverted"]["count"] == 0 and sidecar["boundary_deviation"]["max_rel"] < 1e-12
    # The bundled network (exact boundary, smoothed layout's lattice) is not polished by default: the
    # figures recorded beside the model for its corrected mesh are those of this mesh.
    assert sidecar["method_info"]["polish"] == {"polished": False, "reason": NOT_POLISHED_REASON}
    record = json.loads((BUNDLED.parent / "model.json").read_text())
    assert record["preset"] == "exact" and record["quality"]["neural_30"]["corrected"]["inverted"] == 0
    assert record["quality"]["neural_30"]["corrected"]["min_angle_mean"] == pytest.approx(
        sidecar["metrics"]["min_angle"]["mean"], rel=1e-6
    )
    assert record["quality"]["neural_30"]["corrected"]["min_angle_mean"] != pytest.approx(
        record["quality"]["neural_30"]["polished"]["min_angle_mean"], rel=1e-6
    )  # the comparison above tells the two apart
    assert (
        record["quality"]["neural_100"]["corrected"]["inverted"] == record["quality"]["neural_100"]["polished"]["inverted"] == 0
    )
    assert BUNDLED.stat().st_size < 1 << 20 and record["sha256"] == model["sha256"]


def test_only_a_lattice_trained_exact_boundary_network_is_left_unpolished_by_default():
    bundled = read_plain_checkpoint(BUNDLED)
    assert bundled["config"]["points"]["lattice"] and bundled["model"]["exact_boundary"]
    assert not polishes_by_default(bundled)
    # Each of the three conditions alone makes the default the polish again.
    changes = [("model", "exact_boundary", False), ("points", "lattice", False), (None, "boundary_layout", "fixed")]
    for section, key, value in changes:
        changed = copy.deepcopy({k: bundled[k] for k in ("model", "config")})
        where = changed["model"] if section == "model" else changed["config"] if section is None else changed["config"][section]
        where[key] = value
        assert polishes_by_default(changed), key
    assert polishes_by_default({"model": bundled["model"]})  # no recorded configuration: polished
    for preset in ("default", "family", "exact"):  # the presets as a run records them
        config = to_dict(resolve_config(preset, None, []))
        expected = preset != "exact"
        assert polishes_by_default({"model": {"exact_boundary": config["model"]["exact_boundary"]}, "config": config}) == expected


def test_bundled_model_loads_with_weights_only_and_is_the_recorded_run(semicylinder):
    checkpoint = load_checkpoint(BUNDLED)
    record = json.loads((BUNDLED.parent / "model.json").read_text())
    assert checkpoint["stage"] == "done" and checkpoint["step"] == record["steps"]
    assert checkpoint["geometry"]["params"] == dict(semicylinder.defaults)
    assert checkpoint["config"]["model"]["exact_boundary"] and record["command"].startswith(
        "meshgen train -g semicylinder --preset exact"
    )


# ---------------------------------------------------------------------------------------------
# the map at the nodes


@pytest.mark.parametrize("chunk, workers", [(7, 3), (1000, 1), (1 << 20, 2)])
def test_chunked_evaluation_is_the_network_at_every_node(soft_3d, chunk, workers):
    checkpoint = load_checkpoint(soft_3d)
    coords = [np.linspace(0, 1, 6), np.array([0.0, 0.3, 1.0]), np.linspace(0, 1, 11) ** 2]
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, 3)
    with torch.no_grad():
        expected = network_from_description(checkpoint["model"])(torch.from_numpy(grid).float()).double().numpy()
    got = evaluate_on_grid(checkpoint["model"], coords, chunk=chunk, workers=workers)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
    assert torch.get_num_threads() >= 1  # restored after the single-threaded workers


@pytest.mark.parametrize("which, dims", [("soft_2d", (9, 5)), ("soft_3d", (4, 6, 5))])
def test_mesh_from_a_checkpoint_is_the_network_at_the_same_points(run_cli, tmp_path, request, which, dims):
    path = request.getfixturevalue(which)
    checkpoint = load_checkpoint(path)
    geometry = load_geometry(checkpoint["geometry"]["spec"], checkpoint["geometry"]["params"])
    result = run_cli("mesh", "--checkpoint", path, "--no-correct", "--dims", *dims, "-o", "m.vtu")
    assert result.returncode == 0, result.stderr
    expected = network_at(checkpoint, parametric_grid(dims), geometry)
    np.testing.assert_allclose(read_points(tmp_path / "m.vtu", dims), expected, rtol=0, atol=1e-6)
    sidecar = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    assert sidecar["method_info"]["model"]["checkpoint"] == str(path)
    assert sidecar["method_info"]["correction"]["corrected"] is False


def test_exact_boundary_map_on_a_clustered_grid(semicylinder):
    checkpoint = load_checkpoint(THREE_D)
    coords = node_coordinates((5, 4, 12), ["zeta:both:1.3", "xi:0:h=0.05"])
    from meshgen.geometry.layout import trained_layout, with_layout

    trained_on = with_layout(semicylinder, trained_layout(checkpoint))  # mesh_from_model takes the geometry as trained
    X = mesh_from_model(checkpoint["model"], coords, trained_on, chunk=64)
    # NumPy's float32 products (meshing) against torch's (network_at): equal to float32 round-off
    # through four 85-wide layers, times the model's scale
    np.testing.assert_allclose(X, network_at(checkpoint, coords, semicylinder), rtol=0, atol=1e-5)


@pytest.mark.parametrize("name, dims", [("semicylinder", (5, 7, 4)), ("semidisk", (9, 6)), ("canal", (3, 4, 6))])
def test_tensor_grid_tfi_equals_the_direct_gordon_hall_form(name, dims):
    geometry = load_geometry(name)
    coords = node_coordinates(dims, ["eta:both:1.4"])
    axes = [c.reshape([-1 if d == a else 1 for d in range(len(coords))]) for a, c in enumerate(coords)]
    direct = transfinite(geometry.boundary, axes)  # the 26-term (2D: 8-term) Boolean sum
    np.testing.assert_allclose(transfinite_on_grid(geometry.boundary, coords), direct, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# the boundary correction X = N + TFI[g - N]


def grid_lookup(values, coords):
    """A boundary callable (K, d) -> (K, d) that returns ``values`` (n1+1, .., d) at the grid
    nodes the points are (their coordinates taken from ``coords``)."""

    def lookup(points):
        index = tuple(np.searchsorted(c, points[:, a]) for a, c in enumerate(coords))
        for a, c in enumerate(coords):
            assert np.array_equal(c[index[a]], points[:, a])  # grid nodes only
        return values[index]

    return lookup


def boundary_mask(shape):
    mask = np.zeros(shape, dtype=bool)
    for axis in range(len(shape)):
        index = [slice(None)] * len(shape)
        for end in (0, -1):
            index[axis] = end
            mask[tuple(index)] = True
    return mask


def test_correction_is_the_tfi_of_the_boundary_error_and_exact_on_the_boundary(run_cli, tmp_path, soft_3d, semicylinder):
    dims = (6, 5, 7)
    corrected = run_cli("mesh", "--checkpoint", soft_3d, "--no-polish", "--dims", *dims, "-o", "s.vtu")
    raw = run_cli("mesh", "--checkpoint", soft_3d, "--no-correct", "--dims", *dims, "-o", "r.vtu")
    old_name = run_cli("mesh", "--checkpoint", soft_3d, "--no-snap", "--dims", *dims, "-o", "o.vtu")
    assert corrected.returncode == raw.returncode == old_name.returncode == 0, corrected.stderr + raw.stderr
    X, X_raw = read_points(tmp_path / "s.vtu", dims), read_points(tmp_path / "r.vtu", dims)
    np.testing.assert_array_equal(read_points(tmp_path / "o.vtu", dims), X_raw)  # --no-snap: the alias of --no-correct
    coords = parametric_grid(dims)
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    on_boundary = boundary_mask(X.shape[:-1])
    from meshgen.geometry.layout import smoothed

    # the default configuration trains on the smoothed boundary layout: the correction goes there
    exact = smoothed(semicylinder).boundary(grid[on_boundary])
    np.testing.assert_allclose(X[on_boundary], exact, rtol=0, atol=1e-14)  # on the boundary to round-off
    # Inside: the raw network plus the correction's direct form of the error at the face nodes.
    error = np.zeros_like(X_raw)
    error[on_boundary] = exact - X_raw[on_boundary]
    np.testing.assert_allclose(X - X_raw, direct_correction(grid_lookup(error, coords), coords), rtol=0, atol=1e-13)
    assert np.abs(error).max() > 1e-3  # a tiny run is visibly off: the check means something
    # The network's boundary error, said the same way with and without the correction.
    distance = np.linalg.norm(error[on_boundary], axis=1)
    for name, result in (("s", corrected), ("r", raw)):
        info = json.loads((tmp_path / f"{name}.vtu.quality.json").read_text())["method_info"]["correction"]
        assert info["error_before"]["max"] == pytest.approx(distance.max(), rel=1e-9)
        assert info["error_before"]["mean"] == pytest.approx(distance.mean(), rel=1e-9)  # each node once
        assert (
            f"network's boundary error (|g(xi) - N(xi)| at the boundary nodes' parametric points): max {distance.max():.3g}"
            in result.stdout
        )


def test_correction_keeps_the_cells_that_snapping_folds(semicylinder):
    """Both outer layers of the cap zeta = 0 pushed 1.5 cells outwards: valid cells. Moving only
    the boundary nodes back (snapping) passes them through the next layer and folds the cells
    between; the correction moves the layers behind them along and folds nothing."""
    dims = (4, 3, 6)
    coords = parametric_grid(dims)
    X = tfi(semicylinder, dims)
    height = X[0, 0, 1, 2] - X[0, 0, 0, 2]
    X[:, :, :2, 2] -= 1.5 * height
    assert quality_report(X)["inverted"]["count"] == 0
    snapped = X.copy()
    snapped[:, :, 0] = tfi(semicylinder, dims)[:, :, 0]
    assert quality_report(snapped)["inverted"]["count"] == 4 * 3
    info = correct_boundary(X, semicylinder, coords, count_inverted=True)
    assert info["error_before"]["max"] == pytest.approx(1.5 * height, rel=1e-12)
    assert info["inverted_before"] == info["inverted_after"] == 0
    report = quality_report(X, semicylinder)
    assert report["inverted"]["count"] == 0 and report["boundary_deviation"]["max"] < 1e-14
    # The error is 1.5 h along z on the cap zeta = 0 and on the side faces' first two node rings,
    # zero elsewhere: the corrected mesh is the moved one plus the correction's direct form of it.
    error = np.zeros(X.shape)
    error[:, :, :2, 2] = 1.5 * height
    expected = tfi(semicylinder, dims) - error + direct_correction(grid_lookup(error, coords), coords)
    np.testing.assert_allclose(X, expected, rtol=0, atol=1e-14)


def test_correction_of_an_error_inside_one_face_fades_as_the_closed_form(semicylinder):
    """A bump on the cap zeta = 0, zero on its edges: the correction's corner part and every other
    face's term vanish, so it is the bump times (1 - zeta)^p at every node (closed form), where
    linear TFI would carry (1 - zeta) of it through the whole volume."""
    from meshgen.methods.correction import CORRECTION_POWER

    dims = (12, 10, 16)
    coords = parametric_grid(dims)
    X = tfi(semicylinder, dims)
    bump = 0.05 * np.outer(np.sin(np.pi * coords[0]), np.sin(np.pi * coords[1]))
    moved = X.copy()
    moved[:, :, 0, 2] += bump
    expected = moved[..., 2] - bump[:, :, None] * (1.0 - coords[2]) ** CORRECTION_POWER  # X on zeta = 0
    correct_boundary(moved, semicylinder, coords)
    np.testing.assert_allclose(moved[..., 2], expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(moved[..., :2], X[..., :2], rtol=0, atol=1e-15)
    assert np.abs(moved - X)[:, :, 8:].max() < 0.05 * 0.5**CORRECTION_POWER + 1e-15  # the inner half kept


def test_correction_block_by_block_from_the_model_equals_the_whole_mesh(soft_3d, semicylinder):
    """What a block-wise mesher does: the boundary errors from the faces alone, then each block's
    nodes from the network plus the correction on that block."""
    from meshgen.neural.network_map import model_boundary_errors

    model = load_checkpoint(soft_3d)["model"]
    coords = node_coordinates((9, 6, 7), ["xi:both:1.2"])
    whole = mesh_from_model(model, coords, semicylinder)
    correct_boundary(whole, semicylinder, coords)
    errors = model_boundary_errors(model, semicylinder, coords)
    blocks = np.empty_like(whole)
    for i in (slice(0, 4), slice(4, 10)):
        for j in (slice(0, 3), slice(3, 7)):
            block = (i, j, slice(0, 8))
            blocks[block] = mesh_from_model(model, [c[b] for c, b in zip(coords, block)], semicylinder)
            add_boundary_correction(blocks[block], errors, coords, block=block)
    # The network's values are the same bits in any block (fixed-order forward pass); the whole
    # mesh's boundary nodes are set to g exactly, the blocks' are N + (g - N): float64 round-off.
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-14)


def test_correction_on_blocks_equals_the_whole_grid(semicylinder):
    """A block-wise caller: face errors once, the correction evaluated block by block."""
    dims = (7, 5, 6)
    coords = node_coordinates(dims, ["zeta:both:1.3"])
    rng = np.random.default_rng(0)
    X = tfi(semicylinder, None, coords) + 0.01 * rng.standard_normal(tuple(len(c) for c in coords) + (3,))
    errors = boundary_errors(X, semicylinder, coords)
    whole = add_boundary_correction(X.copy(), errors, coords)
    blocks = X.copy()
    for i in (slice(0, 3), slice(3, 8)):
        for k in (slice(0, 4), slice(4, 7)):
            block = (i, slice(0, 6), k)
            add_boundary_correction(blocks[block], errors, coords, block=block)
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-15)


@pytest.mark.skipif(torch.cuda.is_available(), reason="a GPU is present: --device cuda is valid here")
def test_device_cuda_without_a_gpu_is_one_line_exit_2(run_cli, tmp_path):
    result = run_cli("mesh", "--device", "cuda", "--dims", 4, 4, 4, "-o", "m.vtu")
    assert one_line_error(result) and "no CUDA device is available" in result.stderr, result.stderr
    assert not (tmp_path / "m.vtu").exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason="a GPU is present: --device cuda is valid here")
def test_train_device_cuda_without_a_gpu_names_the_flag_and_makes_no_run_folder(run_cli, tmp_path):
    """train, mesh and compare share one device check (``inference_device``), worded for the CLI."""
    result = run_cli("train", "-g", "semicylinder", "--device", "cuda", "--out", "run", "-q")
    assert one_line_error(result) and "--device cuda: no CUDA device is available" in result.stderr, result.stderr
    assert not (tmp_path / "run").exists()


def test_device_cpu_and_auto_give_the_same_mesh_on_a_cpu_machine(run_cli, tmp_path):
    dims = (5, 4, 6)
    for device in ("cpu", "auto"):
        assert run_cli("mesh", "--device", device, "--dims", *dims, "-o", f"{device}.vtu").returncode == 0
    if not torch.cuda.is_available():
        np.testing.assert_array_equal(read_points(tmp_path / "cpu.vtu", dims), read_points(tmp_path / "auto.vtu", dims))


def test_default_preset_corrected_is_valid_and_near_elliptic_at_every_resolution(tmp_path, semidisk):
    """The boundary correction on a small case: the default preset (the paper's method: soft boundary,
    reweighting, PCGrad), shortened and on the 2D semidisk, leaves the boundary visibly off; its
    corrected mesh has no inverted cell, the exact boundary, and a mean minimum angle within 0.3
    degrees of the converged elliptic mesh's, at every resolution (the same network)."""
    from meshgen.methods.elliptic import elliptic
    from meshgen.neural.config import resolve_config

    config = resolve_config(
        "default",
        None,
        [
            "pretrain.steps=5",
            "adam.steps=100",
            "lbfgs.steps=20",
            "model.widths=[24,24]",
            "points.interior=1000",
            "points.boundary=1000",
        ],
    )
    model = train(config, semidisk, tmp_path, summary=False).checkpoint["model"]
    for cells in (8, 30, 60):
        coords = parametric_grid((cells, cells))
        X = mesh_from_model(model, coords, semidisk)
        info = correct_boundary(X, semidisk, coords)
        assert info["error_before"]["max_rel"] > 1e-3  # the raw network misses the boundary
        report = quality_report(X, semidisk)
        reference = quality_report(elliptic(semidisk, (cells, cells))[0], semidisk)
        assert report["inverted"]["count"] == 0 and report["boundary_deviation"]["max_rel"] < 1e-12
        angle, elliptic_angle = report["metrics"]["min_angle"]["mean"], reference["metrics"]["min_angle"]["mean"]
        assert abs(angle - elliptic_angle) <= 0.3, (cells, angle, elliptic_angle)


def test_corrected_mesh_of_a_blown_up_map_stays_valid(run_cli, tmp_path, soft_2d):
    """The tiny model's map blown up 1.5 times about the centre: its two outer node layers lie
    outside the semidisk, where snapping the boundary layer back folded the cells between them.
    The correction moves every layer by a share of the error: no cell folds."""
    checkpoint = load_checkpoint(soft_2d)
    last = len(checkpoint["model"]["widths"])
    for key in (f"layers.{last}.weight", f"layers.{last}.bias"):
        checkpoint["model"]["state_dict"][key] *= 1.5
    torch.save(checkpoint, tmp_path / "big.pt")
    result = run_cli("mesh", "--checkpoint", "big.pt", "--dims", 40, 40, "-o", "m.vtu")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    assert report["method_info"]["correction"]["error_before"]["max"] > 0.1
    assert report["inverted"]["count"] == 0 and report["boundary_deviation"]["max"] < 1e-12
    X = read_points(tmp_path / "m.vtu", (40, 40))
    snapped = X.copy()  # what snapping did: the raw network with its boundary layer moved back
    raw = run_cli("mesh", "--checkpoint", "big.pt", "--no-correct", "--dims", 40, 40, "-o", "r.vtu")
    assert raw.returncode == 0
    snapped[1:-1, 1:-1] = read_points(tmp_path / "r.vtu", (40, 40))[1:-1, 1:-1]
    assert quality_report(snapped)["inverted"]["count"] > 0


# ---------------------------------------------------------------------------------------------
# clustering


def test_clustering_gives_the_requested_first_cell(run_cli, tmp_path, semicylinder):
    dims = (4, 4, 20)
    three_d = ["--checkpoint", THREE_D]  # a 3D network, whose clustered nodes network_at computes
    result = run_cli("mesh", *three_d, "--no-polish", "--dims", *dims, "--cluster", "zeta:both:1.15", "-o", "m.vtu")
    assert result.returncode == 0, result.stderr
    X = read_points(tmp_path / "m.vtu", dims)
    coords = node_coordinates(dims, ["zeta:both:1.15"])
    # NumPy's float32 forward pass (meshing) against torch's (network_at): float32 round-off
    np.testing.assert_allclose(X, network_at(load_checkpoint(THREE_D), coords, semicylinder), rtol=0, atol=1e-5)
    # Along the axis z = 2 zeta for the exact Winslow map of a prism; the network keeps it closely,
    # so physical cell heights grow by the ratio asked for.
    heights = np.diff(X[2, 2, :, 2])
    np.testing.assert_allclose(heights[1:10] / heights[:9], 1.15, rtol=0.01)
    np.testing.assert_allclose(heights[-9:] / heights[-10:-1], 1 / 1.15, rtol=0.01)
    # a first-cell height: h = 0.01 of the parametric edge, 0.02 of the length 2
    result = run_cli("mesh", "--dims", *dims, "--cluster", "zeta:0:h=0.01", "-o", "h.vtu")
    assert result.returncode == 0, result.stderr
    X = read_points(tmp_path / "h.vtu", dims)
    assert np.diff(X[2, 2, :, 2])[0] == pytest.approx(0.02, rel=0.01)
    assert clustered_coordinates(20, parse_cluster("zeta:0:h=0.01"))[1] == pytest.approx(0.01, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# which model


@pytest.mark.slow
def test_newest_run_of_the_geometry_is_used_then_the_bundled_model(run_cli, tmp_path, soft_2d, soft_3d):
    runs = tmp_path / "runs"
    for name, source, age in (("semicylinder-old", soft_3d, 200), ("semidisk-new", soft_2d, 100)):
        (runs / name).mkdir(parents=True)
        target = runs / name / "checkpoint.pt"
        target.write_bytes(source.read_bytes())
        os.utime(target, (time.time() - age, time.time() - age))
    # No --geometry means the semicylinder (as --help says), not the newest run of any geometry.
    default = run_cli("mesh", "--dims", 3, 3, 3, "-o", "z.vtu")  # skips the newer semidisk run
    assert default.returncode == 0, default.stderr
    assert default.stdout.startswith("model: runs/semicylinder-old/checkpoint.pt (")
    assert json.loads((tmp_path / "z.vtu.quality.json").read_text())["geometry"] == "semicylinder"
    assert one_line_error(run_cli("mesh", "--dims", 5, 5, "-o", "y.vtu"))  # 2D dims for the 3D default
    newest = run_cli("mesh", "-g", "semidisk", "--dims", 5, 5, "-o", "a.vtu")
    assert newest.returncode == 0, newest.stderr
    assert newest.stdout.startswith("model: runs/semidisk-new/checkpoint.pt (")
    assert json.loads((tmp_path / "a.vtu.quality.json").read_text())["geometry"] == "semidisk"
    chosen = run_cli("mesh", "-g", "semicylinder", "--dims", 3, 3, 3, "-o", "b.vtu")  # skips the semidisk run
    assert chosen.returncode == 0, chosen.stderr
    assert chosen.stdout.startswith("model: runs/semicylinder-old/checkpoint.pt (")
    assert json.loads((tmp_path / "b.vtu.quality.json").read_text())["method_info"]["model"]["source"] == "run"
    # a run trained with other parameters is skipped; no run and no bundled model for radius 2
    # --method neural says so; the default method meshes with elliptic and one line says why.
    other = ("-g", "semicylinder", "--param", "radius=2", "--dims", 3, 3, 3, "-o", "c.vtu")
    neural = run_cli("mesh", "-m", "neural", *other)
    assert one_line_error(neural) and "meshgen train -g semicylinder" in neural.stderr and "--method tfi" in neural.stderr
    assert not (tmp_path / "c.vtu").exists()
    fallback = run_cli("mesh", *other)
    assert fallback.returncode == 0, fallback.stderr
    assert fallback.stdout.startswith(
        "note: no trained model for 'semicylinder': meshing with elliptic (meshgen train -g semicylinder trains one)\n"
    )
    recorded = json.loads((tmp_path / "c.vtu.quality.json").read_text())
    assert recorded["method"] == "elliptic" and recorded["params"]["radius"] == 2.0
    (runs / "semicylinder-old" / "checkpoint.pt").unlink()
    bundled = run_cli("mesh", "-g", "semicylinder", "--dims", 3, 3, 3, "-o", "d.vtu")
    assert bundled.returncode == 0 and f"model: {BUNDLED} (bundled, exact" in bundled.stdout


def test_tfi_and_elliptic_stay_one_option_away(run_cli, tmp_path):
    result = run_cli("mesh", "-m", "tfi", "-g", "canal", "--dims", 3, 3, 3, "-o", "t.vtu")
    assert result.returncode == 0 and "model:" not in result.stdout
    assert json.loads((tmp_path / "t.vtu.quality.json").read_text())["method"] == "tfi"


# ---------------------------------------------------------------------------------------------
# bad input


class Payload:
    """Unpickling this calls open(marker, "w"): creates the marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_a_checkpoint_carrying_code_is_refused_without_running_it(run_cli, tmp_path):
    evil = tmp_path / "evil.pt"
    marker = tmp_path / "pwned"
    torch.save({"format": "meshgen-checkpoint", "model": Payload(marker)}, evil)
    # The payload is real: a plain (unsafe) load runs it.
    proof = tmp_path / "proof"
    torch.save(Payload(proof), tmp_path / "proof.pt")
    torch.load(tmp_path / "proof.pt", weights_only=False)
    assert proof.exists()
    before = sorted(os.listdir(tmp_path))
    result = run_cli("mesh", "--checkpoint", evil, "--dims", 4, 4, 4, "-o", "m.vtu")
    assert one_line_error(result) and "evil.pt" in result.stderr, result.stderr
    assert not marker.exists() and sorted(os.listdir(tmp_path)) == before


def write_foreign(path):
    torch.save({"weights": torch.zeros(3)}, path)


def write_corrupt(path):
    path.write_bytes(BUNDLED.read_bytes()[: BUNDLED.stat().st_size // 2])


def write_wrong_network(path):
    checkpoint = load_checkpoint(BUNDLED)
    checkpoint["model"]["widths"] = [7, 7]
    torch.save(checkpoint, path)


@pytest.mark.parametrize(
    "setup, args, message",
    [
        (None, ["--checkpoint", "missing.pt", "--dims", 4, 4, 4], "missing.pt does not exist"),
        (write_corrupt, ["--checkpoint", "x.pt", "--dims", 4, 4, 4], "truncated or not a meshgen checkpoint"),
        (write_foreign, ["--checkpoint", "x.pt", "--dims", 4, 4, 4], "not a meshgen checkpoint"),
        (write_wrong_network, ["--checkpoint", "x.pt", "--dims", 4, 4, 4], "not a meshgen network"),
        (None, ["--checkpoint", BUNDLED, "--dims", 4, 4], "is 3D: --dims needs 3 numbers, got 2"),
        (None, ["--checkpoint", BUNDLED, "-g", "semidisk", "--dims", 4, 4], "trained on 'semicylinder', not on 'semidisk'"),
        (None, ["--checkpoint", BUNDLED, "--param", "radius=3", "--dims", 4, 4, 4], "trained with radius=1, not radius=3"),
        (None, ["--dims", 4, 4, 4, "--cluster", "zeta:both"], "malformed --cluster"),
        (None, ["--dims", 4, 4, 4, "--cluster", "zeta:both:0.5"], "growth ratio must be a number >= 1"),
        (None, ["-m", "neural", "-g", "canal", "--dims", 4, 4, 4], "no trained model for canal"),
        (None, ["-m", "tfi", "--checkpoint", BUNDLED, "--dims", 4, 4, 4], "--checkpoint applies to the neural method"),
        (None, ["--tol", "1e-3", "--dims", 4, 4, 4], "--tol does not apply to method 'neural'"),
        (None, ["-m", "tfi", "--no-snap", "--dims", 4, 4, 4], "--correct does not apply to method 'tfi'"),
        (None, ["-m", "tfi", "--device", "cpu", "--dims", 4, 4, 4], "--device does not apply to method 'tfi'"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(run_cli, tmp_path, setup, args, message):
    if setup is not None:
        setup(tmp_path / "x.pt")
    before = sorted(os.listdir(tmp_path))
    result = run_cli("mesh", *args, "-o", "m.vtu")
    assert one_line_error(result), result.stderr
    assert message in result.stderr
    assert sorted(os.listdir(tmp_path)) == before


@pytest.mark.parametrize(("geometry", "dims"), [("topcurve", (4, 4, 4)), ("semidisk", (6, 4))])
def test_default_method_without_a_model_meshes_with_elliptic_and_says_so(run_cli, tmp_path, geometry, dims):
    result = run_cli("mesh", "-g", geometry, "--dims", *dims, "-o", "m.vtu")
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[0] == (
        f"note: no trained model for '{geometry}': meshing with elliptic (meshgen train -g {geometry} trains one)"
    )
    assert f"elliptic mesh of {geometry}" in result.stdout
    recorded = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    assert recorded["method"] == "elliptic" and recorded["method_info"]["converged"] and recorded["dims"] == list(dims)
    quiet = run_cli("mesh", "-g", geometry, "--dims", *dims, "-o", "q.vtu", "-q")
    assert quiet.returncode == 0 and quiet.stdout == ""
