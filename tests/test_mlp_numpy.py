"""The NumPy forward pass and the torch-free checkpoint reader against torch itself: the network's
forward (``meshgen.neural.model.MLP``) and ``torch.load``."""

import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import MeshgenError
from meshgen.neural.mlp_numpy import forward_on_grid, read_checkpoint

torch = pytest.importorskip("torch")
BUNDLED = Path(__file__).resolve().parents[1] / "meshgen" / "_models" / "semicylinder" / "checkpoint.pt"


def random_model(dim, widths, seed):
    from meshgen.neural.model import MLP

    torch.manual_seed(seed)
    network = MLP(dim, widths)
    state = {k: v.detach().clone() for k, v in network.state_dict().items()}
    return network, {"dim": dim, "widths": widths, "state_dict": state}


@pytest.mark.parametrize("dim, widths", [(3, [85, 85, 85, 85]), (2, [16, 24])])
@pytest.mark.parametrize("workers", [1, 2])
def test_forward_agrees_with_torch_to_float32_round_off(dim, widths, workers):
    network, model = random_model(dim, widths, seed=dim)
    coords = [np.sort(np.random.default_rng(d).random(n)) for d, n in zip(range(dim), (13, 11, 9)[:dim])]
    # uneven chunks: the grid's 1287 or 143 nodes in chunks of 100
    mine = forward_on_grid(model, coords, chunk=100, workers=workers)
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, dim)
    with torch.no_grad():
        expected = network(torch.from_numpy(grid).float()).double().numpy()
    assert mine.shape == expected.shape and mine.dtype == np.float64
    np.testing.assert_allclose(mine, expected, rtol=0, atol=2e-6 * max(1.0, np.abs(expected).max()))
    # numpy arrays in the state dict work as well as tensors
    plain = dict(model, state_dict={k: v.numpy() for k, v in model["state_dict"].items()})
    np.testing.assert_array_equal(forward_on_grid(plain, coords, chunk=100, workers=workers), mine)


def test_the_checkpoint_reads_as_torch_loads_it(tmp_path):
    from meshgen.neural.gpu_forward import evaluate_on_grid

    expected = torch.load(BUNDLED, map_location="cpu", weights_only=True)
    read = read_checkpoint(BUNDLED)

    def compare(a, b):
        if isinstance(b, torch.Tensor):
            assert isinstance(a, np.ndarray) and a.shape == tuple(b.shape)
            np.testing.assert_array_equal(a, b.numpy())
        elif isinstance(b, dict):
            assert list(a) == list(b)
            for key in b:
                compare(a[key], b[key])
        elif isinstance(b, (list, tuple)):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                compare(x, y)
        else:
            assert a == b

    compare(read, expected)
    coords = [np.linspace(0.0, 1.0, n) for n in (9, 8, 7)]
    np.testing.assert_allclose(
        forward_on_grid(read["model"], coords), evaluate_on_grid(expected["model"], coords), rtol=0, atol=2e-6
    )
    # a transposed (non-contiguous) tensor is read with its strides
    path = tmp_path / "strided.pt"
    weight = torch.arange(12.0).reshape(3, 4)
    torch.save({"t": weight.t(), "slice": weight[1:, 2:]}, path)
    read = read_checkpoint(path)
    np.testing.assert_array_equal(read["t"], weight.t().numpy())
    np.testing.assert_array_equal(read["slice"], weight[1:, 2:].numpy())


def test_foreign_pickles_and_other_files_are_refused(tmp_path):
    path = tmp_path / "evil.pt"
    torch.save({"x": 1}, path)
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    data_name = next(name for name in entries if name.endswith("data.pkl"))
    entries[data_name] = pickle.dumps({"x": print})  # a global that plain data never holds
    with zipfile.ZipFile(path, "w") as archive:
        for name, raw in entries.items():
            archive.writestr(name, raw)
    with pytest.raises(MeshgenError, match="builtins.print is not plain checkpoint data"):
        read_checkpoint(path)
    text = tmp_path / "text.pt"
    text.write_text("not a checkpoint")
    with pytest.raises(MeshgenError, match="could not read checkpoint"):
        read_checkpoint(text)


def test_blas_threads_are_restored_after_concurrent_passes():
    from concurrent.futures import ThreadPoolExecutor

    from meshgen.neural.mlp_numpy import openblas_thread_functions

    functions = openblas_thread_functions()
    if functions is None:
        pytest.skip("NumPy's BLAS is not an OpenBLAS whose thread count can be read")
    get, _ = functions
    before = get()
    _, model = random_model(3, [32, 32], seed=4)
    coords = [np.linspace(0.0, 1.0, 30)] * 3
    with ThreadPoolExecutor(max_workers=3) as pool:
        results = list(pool.map(lambda _: forward_on_grid(model, coords, chunk=512, workers=2), range(6)))
    assert get() == before
    for result in results[1:]:
        np.testing.assert_array_equal(result, results[0])


def test_meshing_with_the_bundled_network_imports_no_torch(tmp_path):
    """``meshgen mesh`` with the bundled model on a CPU: NumPy's forward pass, torch never imported
    (the device check included: no NVIDIA device is visible with CUDA_VISIBLE_DEVICES empty)."""
    import os
    import subprocess
    import sys

    script = (
        "import sys; from meshgen.cli import main; sys.argv = ['meshgen', 'mesh', '--dims', '3', '3', '3', '-o', 'm.vtu', '-q'];"
        "\ntry:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\nprint('torch' in sys.modules)"
    )
    environment = {**os.environ, "PYTHONPATH": str(BUNDLED.parents[3]), "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False"
    assert (tmp_path / "m.vtu").is_file()


def test_auto_device_is_cpu_without_a_visible_gpu(monkeypatch):
    from meshgen.neural.device import inference_device, nvidia_device_visible

    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")
    assert nvidia_device_visible() is False
    if not torch.cuda.is_available():
        assert inference_device("auto") == "cpu"


def test_a_nodes_value_is_fixed_order_float32_arithmetic_whatever_the_grid():
    """The forward pass per node is W h summed k = 0, 1, .. with every product and sum rounded to
    float32 (no FMA, no reordering), then + b and tanh: a NumPy oracle doing exactly that,
    column by column, gives the same bits; and so does any sub-grid, batch or worker count (a BLAS
    product rounds a node by its row in the product, so it would not)."""
    _, model = random_model(3, [20, 17], seed=5)
    coords = [np.linspace(0.0, 1.0, n) ** 1.3 for n in (11, 7, 9)]
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float32)
    hidden = np.float32(2.0) * grid - np.float32(1.0)
    layers = [
        (model["state_dict"][f"layers.{i}.weight"].numpy(), model["state_dict"][f"layers.{i}.bias"].numpy()) for i in range(3)
    ]
    for index, (weight, bias) in enumerate(layers):
        total = np.zeros((len(hidden), weight.shape[0]), dtype=np.float32)
        for k in range(weight.shape[1]):
            total = total + hidden[:, k : k + 1] * weight[:, k]  # float32 product, then float32 sum
        hidden = np.tanh(total + bias) if index < 2 else total + bias
    whole = forward_on_grid(model, coords, workers=2)
    np.testing.assert_array_equal(whole, hidden.astype(np.float64))
    part = [coords[0][3:8], coords[1][[0, 5]], coords[2][1:2]]
    expected = whole.reshape(11, 7, 9, 3)[3:8][:, [0, 5]][:, :, 1:2].reshape(-1, 3)
    np.testing.assert_array_equal(forward_on_grid(model, part, chunk=3, workers=1), expected)
