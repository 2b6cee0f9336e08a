"""The quality report computed in parts on threads (``meshgen.quality.report.report_in_parallel``,
what ``write_mesh_with_quality`` and so ``meshgen mesh`` use) is the report of the serial path
(``quality_report``)."""

from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality import quality_report, write_mesh_with_quality
from meshgen.quality.report import report_in_parallel
from meshgen.quality.structured import structured_metrics


def jittered(geometry, dims, seed=0):
    X = tfi(geometry, dims)
    X[(slice(1, -1),) * len(dims)] += np.random.default_rng(seed).normal(0.0, 0.01, X[(slice(1, -1),) * len(dims)].shape)
    return X


@pytest.mark.parametrize(("name", "dims"), [("semicylinder", (7, 6, 9)), ("semidisk", (9, 7))])
def test_the_report_in_parts_is_the_serial_report(name, dims):
    geometry = load_geometry(name)
    X = jittered(geometry, dims)
    with ThreadPoolExecutor(max_workers=4) as pool:
        metrics, report = report_in_parallel(X, geometry, pool)
        report = report.result()
    assert report == quality_report(X, geometry)
    assert report["solver_figures"]["non_orthogonality_internal"]["faces"] > 0 and report["boundary_deviation"]["max"] < 1e-12
    expected = structured_metrics(X)[0]
    assert all(np.array_equal(metrics[key], expected[key]) for key in expected)
    with ThreadPoolExecutor(max_workers=4) as pool:  # no geometry: no boundary deviation
        assert report_in_parallel(X, None, pool)[1].result() == quality_report(X)


def test_the_sidecar_of_a_written_mesh_is_the_serial_report(tmp_path):
    geometry = load_geometry("semicylinder")
    X = jittered(geometry, (6, 5, 7), seed=1)
    report = write_mesh_with_quality(tmp_path / "m.vtu", X, geometry, {"method": "tfi"})
    sidecar = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    expected = json.loads(json.dumps(quality_report(X, geometry)))
    assert report.pop("quality_seconds") > 0 and sidecar.pop("quality_seconds") > 0
    assert {k: v for k, v in sidecar.items() if k not in ("mesh", "method")} == expected
    assert sidecar["mesh"] == "m.vtu" and sidecar["method"] == "tfi"
