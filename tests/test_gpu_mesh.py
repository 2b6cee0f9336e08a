"""The slab-by-slab neural mesh of ``meshgen.neural.gpu_mesh`` (torch; run here on the CPU device)
against the chunked CPU path's mesh, and its slabs' quality summary against the CPU report."""

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.neural.gpu_mesh import SlabMesher, slabs  # noqa: E402
from meshgen.neural.models import load_model  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402
from meshgen.quality.torch_kernels import report_summaries, summarise_hex_torch  # noqa: E402
from meshgen.run.chunked import neural_array  # noqa: E402

DIMS = (13, 9, 11)
THREE_D = Path(__file__).resolve().parent / "data" / "semicylinder-3d-model.pt"  # the slabs are of a 3D network


@pytest.fixture(scope="module")
def case():
    geometry = load_geometry("semicylinder")
    model = load_model(THREE_D).checkpoint["model"]
    coords = [np.linspace(0.0, 1.0, n + 1) ** 1.2 for n in DIMS]  # graded: the coordinates are used, not assumed
    X, info = neural_array(model, geometry, coords)
    return geometry, model, coords, X.compute(), info


def test_slabs_are_the_cpu_mesh(case):
    geometry, model, coords, X, info = case
    mesher = SlabMesher(model, geometry, coords, device="cpu")
    assert mesher.info["corrected"] and info["corrected"]
    covered = np.zeros(DIMS[0], dtype=int)
    for i0, i1, first, nodes in slabs(mesher, planes=4):
        lo = i0 - first
        expected = X[lo : lo + nodes.shape[0]]
        # float32 network: torch's and numba's products round differently, the rest is float64
        assert np.abs(nodes.numpy() - expected).max() < 1e-6 * geometry.characteristic_length
        covered[i0:i1] += 1
        assert first == (1 if i0 > 0 else 0)
        assert nodes.shape[0] == min(i1 + 1, DIMS[0]) - lo + 1
    assert (covered == 1).all()  # each cell plane owned by one slab
    boundary = [X[0], X[-1], X[:, 0], X[:, -1], X[:, :, 0], X[:, :, -1]]
    whole = torch.cat([n[f : f + i1 - i0 + (1 if i1 == DIMS[0] else 0)] for i0, i1, f, n in slabs(mesher, 5)]).numpy()
    for face, mine in zip(boundary, [whole[0], whole[-1], whole[:, 0], whole[:, -1], whole[:, :, 0], whole[:, :, -1]]):
        assert np.array_equal(face, mine)  # the boundary nodes are the boundary map's values, exactly


def test_slab_summary_is_the_cpu_report(case):
    geometry, model, coords, X, _ = case
    mesher = SlabMesher(model, geometry, coords, device="cpu")
    summary = summarise_hex_torch(((n, f, f + i1 - i0) for i0, i1, f, n in slabs(mesher, 3)), mesher.tolerance)
    figures = report_summaries(summary)
    report = quality_report(X)
    assert summary["cells"] == int(np.prod(DIMS))
    assert summary["inverted"] == report["inverted"]["count"]
    for name in ("min_angle", "scaled_jacobian", "non_orthogonality"):
        assert figures[name]["min"] == pytest.approx(report["metrics"][name]["min"], abs=1e-6)
        assert figures[name]["mean"] == pytest.approx(report["metrics"][name]["mean"], rel=1e-7)


def test_the_chunked_path_takes_the_device_asked_for(tmp_path, run_cli):
    """``--device cuda`` reaches the chunked path (its blocks' forward pass): without a GPU it is
    the one-line refusal, nothing written, not a CPU mesh made in silence."""
    if torch.cuda.is_available():
        pytest.skip("a CUDA device is present: the refusal cannot be seen")
    out = tmp_path / "mesh.cgns"
    result = run_cli("mesh", "--dims", "6", "6", "6", "--chunked", "--device", "cuda", "-o", out)
    assert result.returncode == 2
    assert "no CUDA device" in result.stderr and "Traceback" not in result.stderr
    assert not out.exists()
