"""Checkpoints: plain data, round trip to a mesh, exact resume, and the files load_checkpoint refuses."""

import csv

import numpy as np
import pytest
import torch
from neural_helpers import Recorder, tiny_config

from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.neural.checkpoint import CheckpointError, load_checkpoint
from meshgen.neural.config import from_dict
from meshgen.neural.model import MLP, bubble, mesh_from_checkpoint
from meshgen.neural.train import train


@pytest.fixture(scope="module")
def trained(tmp_path_factory, semidisk):
    folder = tmp_path_factory.mktemp("run")
    result = train(tiny_config(), semidisk, folder, summary=False)
    return folder, result


def test_checkpoint_is_plain_data_and_loads_with_weights_only(trained):
    folder, result = trained
    raw = torch.load(folder / "checkpoint.pt", weights_only=True)  # would raise on any pickled object
    assert raw["stage"] == "done" and raw["step"] == 2 + 10 + 2
    model = raw["model"]
    assert model["dim"] == 2 and model["widths"] == [12, 12] and model["activation"] == "tanh"
    assert isinstance(model["center"], list) and isinstance(model["scale"], float)
    assert raw["geometry"] == {"name": "semidisk", "spec": "semidisk", "dim": 2, "params": {"radius": 1.0}}
    assert from_dict(raw["config"]).adam.steps == 10
    assert set(raw["test_loss"]) == {"pde", "boundary", "total"} and np.isfinite(raw["test_loss"]["total"])
    assert raw["meshgen_version"]


def test_mesh_from_checkpoint_is_the_network_in_physical_units(trained, semidisk):
    folder, _ = trained
    checkpoint = load_checkpoint(folder / "checkpoint.pt")
    coords = parametric_grid((7, 5))
    X = mesh_from_checkpoint(checkpoint, coords, chunk=10)  # several chunks
    assert X.shape == (8, 6, 2) and X.dtype == np.float64
    network = MLP(2, [12, 12])
    network.load_state_dict(checkpoint["model"]["state_dict"])
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    with torch.no_grad():
        expected = network(torch.from_numpy(grid.reshape(-1, 2)).float()).double().numpy()
    expected = np.asarray(checkpoint["model"]["center"]) + checkpoint["model"]["scale"] * expected
    np.testing.assert_allclose(X.reshape(-1, 2), expected, rtol=1e-6, atol=1e-6)
    # a trained soft-boundary map is close to, but not on, the boundary
    assert np.abs(X[0, :] - semidisk.boundary(grid[0, :])).max() < 0.5


def test_exact_boundary_map_meets_the_boundary(tmp_path, semidisk):
    train(tiny_config(preset="exact"), semidisk, tmp_path, summary=False)
    checkpoint = load_checkpoint(tmp_path / "checkpoint.pt")
    assert checkpoint["model"]["exact_boundary"]
    coords = parametric_grid((9, 6))
    X = mesh_from_checkpoint(checkpoint, coords)  # geometry loaded from the checkpoint
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    for index in ((0, slice(None)), (-1, slice(None)), (slice(None), 0), (slice(None), -1)):
        np.testing.assert_allclose(X[index], semidisk.boundary(grid[index]), atol=1e-12)
    # inside: TFI plus scale * bubble * network, and the network has moved away from zero
    network = MLP(2, checkpoint["model"]["widths"])
    network.load_state_dict(checkpoint["model"]["state_dict"])
    with torch.no_grad():
        N = network(torch.from_numpy(grid.reshape(-1, 2)).float()).double().numpy().reshape(X.shape)
    expected = tfi(semidisk, None, coords) + checkpoint["model"]["scale"] * bubble(grid)[..., None] * N
    # meshing evaluates the network with NumPy, this with torch: equal to float32 round-off
    np.testing.assert_allclose(X, expected, atol=1e-6)
    assert np.abs(N).max() > 1e-4


def read_history(path):
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(handle)]


@pytest.mark.parametrize("stop_after", [5, 13])  # inside Adam, inside L-BFGS
def test_an_interrupted_and_resumed_run_gives_the_same_weights(tmp_path, semidisk, stop_after):
    config = tiny_config()
    (tmp_path / "straight").mkdir()
    (tmp_path / "resumed").mkdir()
    straight = train(config, semidisk, tmp_path / "straight", summary=False)
    recorder = Recorder(stop_after=stop_after)
    first = train(config, semidisk, tmp_path / "resumed", reporter=recorder, stop=recorder.should_stop, summary=False)
    assert first.interrupted and first.step == stop_after
    saved = load_checkpoint(first.checkpoint_path)
    assert saved["stage"] != "done" and saved["step"] == stop_after
    second = train(from_dict(saved["config"]), semidisk, tmp_path / "resumed", resume=saved, summary=False)
    assert not second.interrupted and second.step == straight.step
    expected, got = straight.checkpoint, second.checkpoint
    for key, tensor in expected["model"]["state_dict"].items():
        assert torch.equal(tensor, got["model"]["state_dict"][key]), key
    assert torch.equal(expected["reweighting"]["log_a"], got["reweighting"]["log_a"])
    assert read_history(tmp_path / "straight" / "history.csv") == read_history(tmp_path / "resumed" / "history.csv")


def test_missing_truncated_foreign_and_future_checkpoints_are_refused(tmp_path, trained):
    folder, _ = trained
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "nothing.pt")
    data = (folder / "checkpoint.pt").read_bytes()
    (tmp_path / "truncated.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated or not a meshgen checkpoint"):
        load_checkpoint(tmp_path / "truncated.pt")
    (tmp_path / "text.pt").write_text("not a checkpoint\n")
    with pytest.raises(CheckpointError, match="truncated or not a meshgen checkpoint"):
        load_checkpoint(tmp_path / "text.pt")
    torch.save({"weights": torch.zeros(3)}, tmp_path / "foreign.pt")
    with pytest.raises(CheckpointError, match="not a meshgen checkpoint"):
        load_checkpoint(tmp_path / "foreign.pt")
    torch.save({"format": "meshgen-checkpoint", "format_version": 1, "x": np.zeros(2)}, tmp_path / "pickled.pt")
    with pytest.raises(CheckpointError, match="truncated or not a meshgen checkpoint"):
        load_checkpoint(tmp_path / "pickled.pt")  # numpy arrays are not plain data: weights_only refuses
    future = torch.load(folder / "checkpoint.pt", weights_only=True)
    future["format_version"] = 99
    torch.save(future, tmp_path / "future.pt")
    with pytest.raises(CheckpointError, match="newer than this meshgen"):
        load_checkpoint(tmp_path / "future.pt")
