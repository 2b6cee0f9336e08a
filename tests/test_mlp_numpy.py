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
THREE_D = Path(__file__).resolve().parents[1] / "tests" / "data" / "semicylinder-3d-model.pt"  # a 3D network


def random_model(dim, widths, seed):
    from meshgen.neural.model import MLP

    torch.manual_seed(seed)
    network = MLP(dim, widths)
    state = {k: v.detach().clone() for k, v in network.state_dict().items()}
    return network, {"dim": dim, "widths": widths, "state_dict": state}


@pytest.mark.parametrize("dim, widths", [(3, [85, 85, 85, 85]), (2, [16, 24])])
@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("compiled", [True, False])
def test_forward_agrees_with_torch_to_float32_round_off(dim, widths, workers, compiled):
    network, model = random_model(dim, widths, seed=dim)
    coords = [np.sort(np.random.default_rng(d).random(n)) for d, n in zip(range(dim), (13, 11, 9)[:dim])]
    # uneven chunks: the grid's 1287 or 143 nodes in chunks of 100
    mine = forward_on_grid(model, coords, chunk=100, workers=workers, compiled=compiled)
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, dim)
    with torch.no_grad():
        expected = network(torch.from_numpy(grid).float()).double().numpy()
    assert mine.shape == expected.shape and mine.dtype == np.float64
    np.testing.assert_allclose(mine, expected, rtol=0, atol=2e-6 * max(1.0, np.abs(expected).max()))
    # numpy arrays in the state dict work as well as tensors
    plain = dict(model, state_dict={k: v.numpy() for k, v in model["state_dict"].items()})
    np.testing.assert_array_equal(forward_on_grid(plain, coords, chunk=100, workers=workers, compiled=compiled), mine)


def test_the_checkpoint_reads_as_torch_loads_it(tmp_path):
    from meshgen.neural.gpu_forward import evaluate_on_grid

    expected = torch.load(THREE_D, map_location="cpu", weights_only=True)
    read = read_checkpoint(THREE_D)

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
    """The compiled forward pass per node is W h summed k = 0, 1, .. with every product and sum
    rounded to float32 (no FMA, no reordering), then + b and tanh: a NumPy oracle doing exactly
    that, column by column, gives the same bits; and so does any sub-grid, batch or worker count (a
    BLAS product rounds a node by its row in the product, so it would not: the small-grid BLAS
    path is evaluated whole instead, ``test_chunked``)."""
    compiled = True
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
    whole = forward_on_grid(model, coords, workers=2, compiled=compiled)
    np.testing.assert_array_equal(whole, hidden.astype(np.float64))
    part = [coords[0][3:8], coords[1][[0, 5]], coords[2][1:2]]
    expected = whole.reshape(11, 7, 9, 3)[3:8][:, [0, 5]][:, :, 1:2].reshape(-1, 3)
    np.testing.assert_array_equal(forward_on_grid(model, part, chunk=3, workers=1, compiled=compiled), expected)


def dense_numpy(h: np.ndarray, weight: np.ndarray, bias: np.ndarray, out: np.ndarray, scratch: np.ndarray) -> None:
    """``meshgen.neural.mlp_numpy.dense_kernel``'s layer in NumPy (this test's whole-array oracle), the same float32 operations in the same order (so the
    same bits): ``out`` = 0, then ``out`` + W_k h_k for k = 0, 1, .., then + b, each product and sum
    a separate float32 ufunc (rounded one by one). A Python loop over the inputs k, vectorised over
    outputs and nodes. ``h`` (fan_in, nodes), ``out`` and ``scratch`` (fan_out, nodes) float32."""
    out[...] = 0.0
    for k in range(h.shape[0]):
        np.multiply(weight[:, k : k + 1], h[k], out=scratch)
        np.add(out, scratch, out=out)
    np.add(out, bias[:, None], out=out)


@pytest.mark.parametrize("fan_in", [1, 2, 3, 5, 8, 48])
@pytest.mark.parametrize("fan_out", [1, 3, 7, 8, 13, 48])
def test_the_compiled_layer_and_the_numpy_layer_are_the_same_bits_as_a_scalar_oracle(fan_in, fan_out):
    """``dense_kernel`` (outputs in groups of eight and a remainder, inputs in pairs and a
    remainder, nodes in runs of ``KERNEL_NODES`` and a partial run) and ``dense_numpy`` against
    float32 scalars summed k = 0, 1, .. one node at a time: every shape's remainders, bit for bit.
    Values spread over decades, so that a reordered sum or a fused multiply-add would differ."""
    from meshgen.neural.mlp_numpy import KERNEL_NODES, dense_kernel

    rng = np.random.default_rng(fan_in * 100 + fan_out)
    nodes = 2 * KERNEL_NODES + 37
    h = (rng.standard_normal((fan_in, nodes)) * 10.0 ** rng.integers(-3, 4, (fan_in, nodes))).astype(np.float32)
    weight = (rng.standard_normal((fan_out, fan_in)) * 10.0 ** rng.integers(-3, 4, (fan_out, fan_in))).astype(np.float32)
    bias = rng.standard_normal(fan_out).astype(np.float32)
    compiled, plain = np.full((fan_out, nodes), np.nan, np.float32), np.full((fan_out, nodes), np.nan, np.float32)
    dense_kernel()(h, weight, bias, compiled)
    dense_numpy(h, weight, bias, plain, np.empty_like(plain))
    for r in rng.choice(nodes, 12, replace=False).tolist() + [0, KERNEL_NODES - 1, KERNEL_NODES, nodes - 1]:
        for j in range(fan_out):
            total = np.float32(0.0)
            for k in range(fan_in):
                total = np.float32(total + np.float32(weight[j, k] * h[k, r]))
            assert compiled[j, r] == np.float32(total + bias[j]), (j, r)
    np.testing.assert_array_equal(compiled.view(np.int32), plain.view(np.int32))


def test_a_small_mesh_never_imports_numba_and_is_the_compiled_mesh(tmp_path):
    """``meshgen mesh --dims 20 20 20`` (the bundled network) in a fresh process takes the BLAS
    layers (below ``NUMPY_WORK``: no numba import, about a second); the network's values there
    are the compiled kernel's to float32 round-off (the two sum in different orders, so bits would
    test one BLAS build's rounding)."""
    import os
    import subprocess
    import sys

    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.mlp_numpy import compiled_for
    from meshgen.neural.models import find_model

    script = (
        "import sys; from meshgen.cli import main; sys.argv = ['meshgen', 'mesh', '--dims', '20', '20', '20', '-o', 's.vtu', '-q'];"
        "\ntry:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\nprint('numba' in sys.modules)"
    )
    environment = {**os.environ, "PYTHONPATH": str(BUNDLED.parents[3]), "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False"
    model = find_model(geometry_name="semicylinder").checkpoint["model"]  # a section network: 2D
    coords = parametric_grid((20,) * model["dim"])
    assert not compiled_for(model, 21**3) and compiled_for(model, 101**3)
    blas, kernel = forward_on_grid(model, coords, compiled=False), forward_on_grid(model, coords, compiled=True)
    # float32 round-off of the last layer's sum, whose terms (|W| times tanh values up to 1) are far
    # larger than this network's outputs (an exact-boundary network's N is small where b is)
    state = model["state_dict"]
    last = len(model["widths"])
    terms = np.abs(np.asarray(state[f"layers.{last}.weight"])).sum(axis=1) + np.abs(np.asarray(state[f"layers.{last}.bias"]))
    np.testing.assert_allclose(blas, kernel, rtol=0, atol=1e-5 * terms.max())
