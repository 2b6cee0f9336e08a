"""A geometry of one boundary map is a block set of one block: 0.2's one-network checkpoints load
as a set of one, and one inference path (``meshgen.neural.inference.block_nodes``) maps a block of
either layout. The map is checked against an independent float64 forward pass of the raw weights."""

from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import MeshgenError
from meshgen.geometry.layout import trained_layout, with_layout
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.neural.checkpoint_data import CheckpointError
from meshgen.neural.inference import block_count, block_model, block_nodes, check_model, is_block_model
from meshgen.neural.models import build_neural, load_model

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "tests" / "data" / "semicylinder-3d-model.pt"  # 0.2's bundled one-block model (3D network)
PIPE = ROOT / "tests" / "data" / "pipe-section-model.pt"  # a 0.2 block-set checkpoint
COORDS = [np.linspace(0.0, 1.0, 9), np.linspace(0.0, 1.0, 7) ** 1.5, np.linspace(0.0, 1.0, 6)]


def raw_forward(model: dict, coords) -> np.ndarray:
    """N(xi) on the tensor grid of ``coords`` in float64 from the raw weights: u = 2 xi - 1, then
    x W^T + b with tanh between the layers; (n1, n2, n3, d)."""
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    hidden = 2.0 * grid - 1.0
    count = len(model["widths"]) + 1
    for index in range(count):
        weight = np.asarray(model["state_dict"][f"layers.{index}.weight"], dtype=np.float64)
        bias = np.asarray(model["state_dict"][f"layers.{index}.bias"], dtype=np.float64)
        hidden = hidden @ weight.T + bias
        if index < count - 1:
            hidden = np.tanh(hidden)
    return hidden


def bundled_geometry(checkpoint: dict):
    return with_layout(load_geometry("semicylinder"), trained_layout(checkpoint))


def test_a_0_2_checkpoint_loads_as_a_set_of_one_block():
    model = load_model(BUNDLED).checkpoint["model"]
    assert not is_block_model(model) and block_count(model) == 1
    assert block_model(model, 0) is model  # 0.2's one network is block 0 itself
    with pytest.raises(IndexError):
        block_model(model, 1)
    pipe = load_model(PIPE).checkpoint["model"]  # a 0.2 block-set checkpoint
    assert is_block_model(pipe) and block_count(pipe) == len(pipe["blocks"]) == 5
    assert sorted(block_model(pipe, 4)["state_dict"]) == sorted(f"layers.{i}.{p}" for i in range(4) for p in ("weight", "bias"))
    damaged = dict(model, state_dict={k: v for k, v in model["state_dict"].items() if k != "layers.1.bias"})
    with pytest.raises(CheckpointError):
        check_model(damaged)


def test_the_one_block_map_is_the_raw_weights_forward_pass():
    """0.2's bundled exact-boundary model: X = TFI + scale b N. The path computes N in float32
    (NumPy's products, whose rounding depends on the BLAS kernel), the oracle in float64: they
    agree to float32 round-off of N (|N| < 1), scaled by the model's scale."""
    checkpoint = load_model(BUNDLED).checkpoint
    model, geometry = checkpoint["model"], bundled_geometry(checkpoint)
    assert model["exact_boundary"]
    X = block_nodes(model, 0, COORDS, geometry)
    grid = np.stack(np.meshgrid(*COORDS, indexing="ij"), axis=-1)
    bubble = 64.0 * np.prod(grid * (1.0 - grid), axis=-1)
    expected = tfi(geometry, None, COORDS) + float(model["scale"]) * bubble[..., None] * raw_forward(model, COORDS)
    assert X.shape == expected.shape == (9, 7, 6, 3)
    np.testing.assert_allclose(X, expected, rtol=0, atol=2e-6 * float(model["scale"]))
    # the meshing method takes that path: its uncorrected mesh is these nodes, bit for bit
    uncorrected, _ = build_neural(geometry, COORDS, load_model(BUNDLED), correct=False, device="cpu")
    assert uncorrected.tobytes() == X.tobytes()


def test_one_block_in_the_block_set_layout_maps_bit_for_bit_as_in_the_0_2_layout():
    checkpoint = load_model(BUNDLED).checkpoint
    model, geometry = checkpoint["model"], bundled_geometry(checkpoint)
    as_set = dict(
        model,
        blocks=["semicylinder"],
        state_dict={f"networks.0.{k}": v for k, v in model["state_dict"].items()},
    )
    check_model(as_set)
    assert block_count(as_set) == 1
    assert block_nodes(as_set, 0, COORDS, geometry).tobytes() == block_nodes(model, 0, COORDS, geometry).tobytes()


def test_training_refuses_init_for_one_block(tmp_path):
    from meshgen.neural.config import resolve_config
    from meshgen.neural.train import train

    with pytest.raises(MeshgenError, match="one block"):
        train(resolve_config("default"), load_geometry("semicylinder"), tmp_path, init={"path": "x", "checkpoint": {}})
    assert not any(tmp_path.iterdir())
