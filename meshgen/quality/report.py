"""The quality report: per-metric summaries (mean, min, max, p01, p99), inverted cells, the
validity verdict and the boundary deviation, as a JSON-ready dict (``meshgen evaluate --json``)."""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.quality.deviation import boundary_deviation, grid_boundary_nodes
from meshgen.quality.faces import cells_for_quality, unstructured_metrics
from meshgen.quality.faces_openfoam import DEFINITIONS as FACE_DEFINITIONS
from meshgen.quality.faces_openfoam import non_orthogonality
from meshgen.quality.kernels import DEFINITIONS, METRICS, STATS, VALID_FRACTION, VALID_RULE
from meshgen.quality.pool import map_in_threads
from meshgen.quality.smoothness import DEFINITIONS as SMOOTHNESS_DEFINITIONS
from meshgen.quality.smoothness import smoothness_figures
from meshgen.quality.structured import check_node_array, structured_metrics

__all__ = [
    "assemble_report",
    "assess",
    "assess_in_parallel",
    "build_report",
    "metric_summaries",
    "node_array_deviation",
    "quality_report",
    "report_in_parallel",
    "summarize",
]


def summarize(values: np.ndarray, overwrite: bool = False) -> dict:
    """mean, min, max, p01, p99 of ``values`` (floats); all None when there are none.
    ``overwrite``: the percentiles may reorder ``values`` in place (no copy of them), for arrays
    nobody reads afterwards."""
    if values.size == 0:
        return {stat: None for stat in STATS}
    summary = {"mean": float(np.mean(values)), "min": float(np.min(values)), "max": float(np.max(values))}
    p01, p99 = np.percentile(values, [1.0, 99.0], overwrite_input=overwrite)
    return {**summary, "p01": float(p01), "p99": float(p99)}


def assess(X_or_mesh):
    """Per-cell metrics of any accepted input, with what the report needs besides them."""
    # Non-finite coordinates are counted, reported and make their cells degenerate; the arithmetic
    # on them (inf - inf) must not also print NumPy's RuntimeWarnings beside meshgen's messages.
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return _assess_quietly(X_or_mesh)


def _assess_quietly(X_or_mesh):
    if isinstance(X_or_mesh, np.ndarray):
        X = check_node_array(X_or_mesh)
        metrics, degenerate, info = structured_metrics(X)
        info["dim"] = X.shape[-1]
        info["boundary"] = lambda: grid_boundary_nodes(X)
        info["solver_figures"] = lambda: solver_figures(X)
        return metrics, degenerate, info
    skipped = {}
    if isinstance(X_or_mesh, tuple):
        points, cells = X_or_mesh
    else:
        points, cells, skipped = cells_for_quality(X_or_mesh)
    metrics, degenerate, info = unstructured_metrics(points, cells)
    info["skipped"] = skipped
    info["boundary"] = lambda: (np.asarray(points, dtype=float)[info["boundary_nodes"], : info["dim"]], None)
    return metrics, degenerate, info


def solver_figures(X: np.ndarray) -> dict:
    """The figures of a node array that predict a flow solver's error, JSON-ready: expansion ratio
    and grid smoothness (``meshgen.quality.smoothness``, with worst cells), and checkMesh's
    internal-face non-orthogonality with the boundary-face figure beside it
    (``meshgen.quality.faces_openfoam``, with worst faces)."""
    return {**smoothness_figures(X), **non_orthogonality(X)}


def node_array_deviation(X: np.ndarray, geometry) -> dict:
    """The boundary deviation (``meshgen.quality.deviation.boundary_deviation``) of the boundary nodes of
    node array ``X`` from ``geometry``, as the report gives it."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        boundary_points, guesses = grid_boundary_nodes(X)
        return boundary_deviation(boundary_points, geometry, parametric_guess=guesses)


def _quietly(function, *arguments):
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):  # per thread
        return function(*arguments)


def assess_in_parallel(X: np.ndarray, geometry, pool):
    """``assess`` of node array ``X`` with its other parts started first on the threads of ``pool``
    (a ``concurrent.futures`` executor with at least three workers): the smoothness figures, the
    face non-orthogonality and the boundary deviation from ``geometry`` (if not None); the
    per-cell metrics are computed on the calling thread (their first call in a process imports
    numba and loads the compiled kernels, which the face kernels wait for). Returns (metrics,
    degenerate, info) for ``build_report``, whose ``solver_figures`` and ``boundary_deviation``
    wait for the threads."""
    X = check_node_array(X)
    smoothness = pool.submit(_quietly, smoothness_figures, X)
    faces = pool.submit(_quietly, non_orthogonality, X)
    deviation = pool.submit(node_array_deviation, X, geometry) if geometry is not None else None
    metrics, degenerate, info = assess(X)
    info["solver_figures"] = lambda: {**smoothness.result(), **faces.result()}
    if deviation is not None:
        info["boundary_deviation"] = deviation.result
    return metrics, degenerate, info


def report_in_parallel(X: np.ndarray, geometry, pool):
    """The quality report of node array ``X`` (as :func:`quality_report` gives it) in parts on the
    threads of ``pool`` (a ``concurrent.futures`` executor with at least four workers), as
    ``assess_in_parallel`` computes them. Returns (metrics, report): the seven per-cell arrays,
    for a writer to start on, and a future of the report."""
    metrics, degenerate, info = assess_in_parallel(X, geometry, pool)
    return metrics, pool.submit(build_report, metrics, degenerate, info, geometry)


def quality_report(X_or_mesh, geometry=None) -> dict:
    """JSON-ready quality report of a mesh (the ``meshgen evaluate --json`` schema).

    ``X_or_mesh``: a node array ``(n1+1, n2+1[, n3+1], dim)``, a ``(points, cells)`` pair, or a
    ``meshio.Mesh`` (hexahedra, else quads; other cell types counted under ``skipped``).
    ``geometry``: a ``meshgen.geometry.plugins.Geometry``; adds ``boundary_deviation``.

    Keys: ``cells``, ``dim``, ``metrics`` ({name: {mean, min, max, p01, p99}}), ``inverted``
    ({count, fraction, degenerate}), ``valid`` (no inverted cell), ``valid_rule``, ``units`` and,
    when known, ``boundary_deviation``, ``skipped``, ``warnings``; for a node array (and a file
    that is meshgen's structured grid) ``solver_figures`` (:func:`solver_figures`). Summaries
    leave degenerate cells out.
    """
    return build_report(*assess(X_or_mesh), geometry)


def build_report(metrics, degenerate, info, geometry) -> dict:
    """The report (``quality_report``'s) of the per-cell ``metrics`` with their ``degenerate`` mask
    and ``info`` (``assess``'s), measured against ``geometry``."""
    return assemble_report(*metric_summaries(metrics, degenerate), info, geometry)


def metric_summaries(metrics, degenerate, overwrite: bool = False) -> tuple[dict, dict]:
    """(summaries {name: {mean, min, max, p01, p99}}, counts {cells, inverted, degenerate}) of the
    per-cell ``metrics`` and their ``degenerate`` mask: what ``assemble_report`` makes the report of.
    ``overwrite``: the metric arrays may be reordered in place (``summarize``): the caller is done
    with them."""
    inverted = degenerate | ~(metrics["scaled_jacobian"] > 0.0)
    shaped = ~degenerate
    every = bool(shaped.all())  # then the arrays themselves, not copies of them

    def summary(name):
        return summarize(metrics[name], overwrite) if every else summarize(metrics[name][shaped], True)

    # One metric per thread: np.percentile's partition, the most of the report's own time, releases the GIL.
    summaries = dict(zip(METRICS, map_in_threads(summary, METRICS)))
    counts = {
        "cells": int(len(degenerate)),
        "inverted": int(np.count_nonzero(inverted)),
        "degenerate": int(np.count_nonzero(degenerate)),
    }
    return summaries, counts


def assemble_report(summaries: dict, counts: dict, info: dict, geometry) -> dict:
    """The report from the metric ``summaries`` ({name: {mean, min, max, p01, p99}}), ``counts``
    (cells, inverted, degenerate) and ``info`` (dim, nonfinite_nodes, nonmanifold_faces, skipped,
    ``boundary()`` -> (boundary points, parametric guesses), or ``boundary_deviation`` measured
    already or a callable returning it); shared by the whole-mesh and the
    block-wise (``meshgen.quality.chunked``) paths."""
    dim = int(info["dim"])
    n_cells = counts["cells"]
    inverted_count = counts["inverted"]
    report = {
        "cells": n_cells,
        "dim": dim,
        "cell_type": "hexahedron" if dim == 3 else "quad",
        "metrics": summaries,
        "inverted": {
            "count": inverted_count,
            "fraction": inverted_count / n_cells if n_cells else 0.0,
            "degenerate": counts["degenerate"],
        },
        "valid": bool(inverted_count <= VALID_FRACTION * n_cells),
        "valid_rule": VALID_RULE,
        "units": {"angles": "degrees", "non_orthogonality": "degrees"},
        "definitions": dict(DEFINITIONS),
    }
    warnings = []
    if info.get("nonfinite_nodes"):
        warnings.append(f"{info['nonfinite_nodes']} nodes have non-finite coordinates; their cells count as degenerate")
    if report["inverted"]["degenerate"]:
        warnings.append(
            f"{report['inverted']['degenerate']} degenerate cells (zero-length edge or non-finite node) "
            "count as inverted and are left out of the metric summaries"
        )
    if info.get("nonmanifold_faces"):
        warnings.append(f"{info['nonmanifold_faces']} faces are shared by more than two cells; treated as boundary faces")
    if info.get("skipped"):
        report["skipped"] = dict(info["skipped"])
    if "solver_figures" in info:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            report["solver_figures"] = info["solver_figures"]()
        report["definitions"].update(SMOOTHNESS_DEFINITIONS)
        report["definitions"].update(FACE_DEFINITIONS)
    if geometry is not None:
        if geometry.dim != dim:
            raise MeshgenError(
                f"geometry '{geometry.name}' is {geometry.dim}D but the mesh is {dim}D: "
                "boundary deviation needs a geometry of the mesh's dimension"
            )
        if "boundary_deviation" in info:  # measured in parts (block by block), or on another thread (a callable)
            deviation = info["boundary_deviation"]
            deviation = deviation() if callable(deviation) else deviation
        else:
            boundary_points, guesses = info["boundary"]()
            deviation = boundary_deviation(boundary_points, geometry, parametric_guess=guesses)
        report["boundary_deviation"] = deviation
        if deviation.get("nonfinite_nodes"):
            warnings.append(f"{deviation['nonfinite_nodes']} boundary nodes are not finite: boundary deviation is undefined")
    if warnings:
        report["warnings"] = warnings
    return report
