"""The torch hexahedron metrics (``meshgen.quality.torch_kernels``) against the compiled numba kernel
element by element, against VTK's vtkMeshQuality (Verdict), and their device summary against the CPU
report and the CPU quantile sketch. On torch's CPU device here; the CUDA cases skip without one."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from helpers import vtk_quality  # noqa: E402

from meshgen.geometry.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402
from meshgen.quality import sketch as sketches  # noqa: E402
from meshgen.quality.compiled import structured_hex  # noqa: E402
from meshgen.quality.kernels import METRICS  # noqa: E402
from meshgen.quality.structured import apply_degenerate, degenerate_tolerance, structured_metrics  # noqa: E402
from meshgen.quality.summary import block_summaries  # noqa: E402
from meshgen.quality.torch_kernels import report_summaries, structured_hex_torch, summarise_hex_torch  # noqa: E402

CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
ANGLES = ("min_angle", "max_angle", "non_orthogonality")


def box(dims):
    axes = [np.arange(n + 1) / n for n in dims]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def perturbed(dims, sigma, seed):
    rng = np.random.default_rng(seed)
    X = box(dims)
    return X + rng.normal(scale=sigma / max(dims), size=X.shape)


def sheared_shell(dims):
    """A sheared, twisted quarter of a thick cylindrical shell: curved, non-orthogonal cells."""
    u, v, w = np.moveaxis(box(dims), -1, 0)
    r, theta = 1.0 + u + 0.2 * w, 0.5 * np.pi * v + 0.3 * w * u
    return np.stack([r * np.cos(theta), r * np.sin(theta), w + 0.4 * u + 0.1 * np.sin(2 * np.pi * v)], axis=-1)


def broken(dims, seed):
    """A perturbed grid with inverted cells (a node pushed through its neighbours), a zero-length
    edge and a non-finite node."""
    X = perturbed(dims, 0.1, seed)
    X[2, 2, 2] += 1.5 * (X[3, 3, 3] - X[2, 2, 2])  # folds the cells around it
    X[4, 1, 3] = X[4, 1, 4]  # a zero-length edge
    X[1, 5, 1] = np.nan
    return X


def compiled(X, first, last):
    tolerance, _ = degenerate_tolerance(X.reshape(-1, 3))
    m = int(np.prod(np.subtract(last, first)))
    out, degenerate = np.empty((len(METRICS), m)), np.empty(m, dtype=bool)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        structured_hex(X, first, last, tolerance, out, degenerate)
    return out, degenerate, tolerance


def assert_agree(X, first, last, device="cpu", chunk_cells=1 << 23):
    """The torch metrics of cells first..last equal the compiled kernel's: the degenerate mask and
    inverted flags exactly, the values of the other cells to 1e-12 (absolute; the angles in degrees
    to 1e-12 relative to 180)."""
    out, degenerate, tolerance = compiled(X, first, last)
    rows, mask = structured_hex_torch(torch.from_numpy(X).to(device), tolerance, first, last, chunk_cells=chunk_cells)
    rows, mask = rows.cpu().numpy(), mask.cpu().numpy()
    np.testing.assert_array_equal(mask, degenerate)
    kept = ~degenerate
    for row, name in enumerate(METRICS):
        scale = 180.0 if name in ANGLES else max(1.0, float(np.abs(out[row, kept]).max()))
        np.testing.assert_allclose(rows[row, kept], out[row, kept], rtol=0, atol=1e-12 * scale, err_msg=name)
    ours, theirs = dict(zip(METRICS, rows.copy())), dict(zip(METRICS, out.copy()))
    apply_degenerate(ours, mask)
    apply_degenerate(theirs, degenerate)
    np.testing.assert_array_equal(ours["scaled_jacobian"] > 0, theirs["scaled_jacobian"] > 0)
    return rows, mask


@pytest.mark.parametrize("sigma", [0.05, 0.3])
def test_perturbed_grid_agrees_with_compiled(sigma):
    X = perturbed((9, 8, 7), sigma, seed=3)
    rows, _ = assert_agree(X, (0, 0, 0), (9, 8, 7), chunk_cells=100)  # runs of 1-2 planes
    if sigma > 0.2:  # folded cells and faces are among them
        assert np.any(rows[METRICS.index("scaled_jacobian")] <= 0) and np.any(rows[METRICS.index("max_angle")] > 180)


def test_inverted_and_degenerate_cells_agree_with_compiled():
    X = broken((7, 8, 6), seed=5)
    rows, degenerate = assert_agree(X, (0, 0, 0), (7, 8, 6))
    assert degenerate.sum() >= 4 + 8  # the cells on the zero-length edge and around the NaN node
    assert np.any(rows[METRICS.index("scaled_jacobian"), ~degenerate] <= 0)


def test_sheared_curved_grid_agrees_with_compiled_on_a_sub_block():
    X = sheared_shell((12, 10, 9))
    assert_agree(X, (2, 1, 3), (11, 10, 7), chunk_cells=50)  # cells with and without neighbours in X
    assert_agree(X, (0, 0, 0), (12, 10, 9))


def test_runs_of_planes_do_not_change_a_bit():
    X = perturbed((10, 6, 5), 0.2, seed=9)
    T = torch.from_numpy(X)
    whole, mask = structured_hex_torch(T, 1e-12)
    runs, run_mask = structured_hex_torch(T, 1e-12, chunk_cells=30)
    assert torch.equal(mask, run_mask) and torch.equal(whole.isnan(), runs.isnan())
    assert torch.equal(torch.nan_to_num(whole), torch.nan_to_num(runs))


@pytest.mark.parametrize("X", [perturbed((8, 7, 6), 0.25, seed=11), sheared_shell((8, 7, 6))], ids=["perturbed", "sheared"])
def test_agree_with_vtk_mesh_quality(X):
    rows, _ = structured_hex_torch(torch.from_numpy(X), 1e-12)
    points, cells = flat_points(X), cell_connectivity(X.shape[:-1])
    for name, measure in (
        ("scaled_jacobian", "SetHexQualityMeasureToScaledJacobian"),
        ("equiangle_skewness", "SetHexQualityMeasureToEquiangleSkew"),
    ):
        np.testing.assert_allclose(rows[METRICS.index(name)].numpy(), vtk_quality(points, cells, measure), atol=1e-10)


def slabs(T, bounds):
    """(nodes, first, last) of the slabs of cell planes bounds[s] <= i < bounds[s+1], each with its
    halo (one node plane before, one after its last node)."""
    n1 = T.shape[0] - 1
    for c0, c1 in zip(bounds[:-1], bounds[1:]):
        s0, s1 = max(c0 - 1, 0), min(c1 + 2, n1 + 1)
        yield T[s0:s1], c0 - s0, c1 - s0


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=CUDA)])
def test_device_summary_is_the_cpu_report(device):
    X = broken((24, 17, 13), seed=2)
    tolerance, _ = degenerate_tolerance(X.reshape(-1, 3))
    summary = summarise_hex_torch(slabs(torch.from_numpy(X).to(device), [0, 5, 6, 15, 24]), tolerance, chunk_cells=500)
    report = quality_report(X)
    assert (summary["cells"], summary["inverted"], summary["degenerate"]) == (
        report["cells"],
        report["inverted"]["count"],
        report["inverted"]["degenerate"],
    )
    assert 0 < report["inverted"]["degenerate"] < report["inverted"]["count"]
    figures = report_summaries(summary)
    values, degenerate, _ = structured_metrics(X)
    cpu = block_summaries(values, ~degenerate)  # the CPU's sketch of the same cells
    for name in METRICS:
        ours, theirs = figures[name], report["metrics"][name]
        scale = max(1.0, abs(theirs["min"]), abs(theirs["max"]))
        for stat in ("min", "max"):
            assert ours[stat] == pytest.approx(theirs[stat], rel=0, abs=1e-12 * scale), (name, stat)
        assert ours["mean"] == pytest.approx(theirs["mean"], rel=1e-12), name
        for stat in ("p01", "p99"):  # the sketch's bound against np.percentile
            assert abs(ours[stat] - theirs[stat]) <= sketches.RELATIVE_ACCURACY * scale, (name, stat)
        # the same sketch as the CPU's: a value whose log lies within an ulp of a bucket boundary
        # may fall in the neighbouring bucket (one count moved: a difference of 2)
        a, b = summary["metrics"][name]["sketch"], cpu[name]["sketch"]
        assert a.count == b.count == report["cells"] - report["inverted"]["degenerate"]
        assert a.zeros == b.zeros
        for part in ("positive", "negative"):
            assert _bucket_difference(getattr(a, part), getattr(b, part)) <= 2, (name, part)


def _bucket_difference(x, y) -> int:
    """Sum over keys of |count difference| of two ``sketch.Buckets``."""
    start = min(x.offset, y.offset)
    end = max(x.offset + x.counts.size, y.offset + y.counts.size)
    total = np.zeros(end - start, dtype=np.int64)
    total[x.offset - start : x.offset - start + x.counts.size] += x.counts
    total[y.offset - start : y.offset - start + y.counts.size] -= y.counts
    return int(np.abs(total).sum())


def test_slab_cuts_do_not_change_the_summary():
    X = sheared_shell((20, 9, 8))
    T = torch.from_numpy(X)
    one = summarise_hex_torch(slabs(T, [0, 20]), 1e-12)
    many = summarise_hex_torch(slabs(T, [0, 1, 7, 8, 13, 20]), 1e-12, chunk_cells=100)
    for key in ("cells", "inverted", "degenerate"):
        assert one[key] == many[key]
    for name in METRICS:
        a, b = one["metrics"][name], many["metrics"][name]
        assert (a["min"], a["max"], a["count"]) == (b["min"], b["max"], b["count"])
        assert a["sum"] == pytest.approx(b["sum"], rel=1e-13)
        for part in ("positive", "negative"):
            assert _bucket_difference(getattr(a["sketch"], part), getattr(b["sketch"], part)) == 0


@CUDA
def test_cuda_agrees_with_compiled():
    X = broken((12, 11, 10), seed=4)
    rows, degenerate = assert_agree(X, (0, 0, 0), (12, 11, 10), device="cuda")
    # CUDA's + - * / sqrt are correctly rounded, as the compiled kernel's: the rows without an
    # acos are the same to the bit (torch's CPU sqrt is not: there they differ by ulps)
    out, _, _ = compiled(X, (0, 0, 0), (12, 11, 10))
    for name in ("aspect_ratio", "centroid_skewness", "scaled_jacobian"):
        row = METRICS.index(name)
        np.testing.assert_array_equal(rows[row, ~degenerate], out[row, ~degenerate], err_msg=name)


def test_the_gpu_benchmark_row_runs_on_the_cpu_and_matches_the_cpu_report():
    """The benchmark's slab-by-slab analytic mesh and summary (device "cpu", a small size) give the
    CPU report of the same mesh built at once, and its sub-block agrees with the numba kernel."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_quality_gpu

    row = bench_quality_gpu.gpu_quality_row(14, slab_planes=4, device="cpu", agreement_cells_per_side=9)
    report = quality_report(bench_quality_gpu.shell_nodes(14, 0, 15, "cpu").numpy())
    assert (row["cells"], row["inverted"]) == (report["cells"], report["inverted"]["count"]) == (14**3, 0)
    for name in METRICS:
        ours, theirs = row["metrics"][name], report["metrics"][name]
        assert (ours["min"], ours["max"]) == pytest.approx((theirs["min"], theirs["max"]), rel=1e-13), name
        assert ours["mean"] == pytest.approx(theirs["mean"], rel=1e-12), name
    agreement = row["agreement"]
    assert agreement["cells"] == 9**3 and agreement["degenerate_masks_equal"]
    assert max(agreement["max_abs_difference"].values()) < 1e-12
