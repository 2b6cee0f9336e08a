"""Quality and files: reading meshes for evaluation (``evaluate_file``), writing a mesh with its
per-cell metrics and the ``<mesh>.quality.json`` sidecar, JSON output."""

from __future__ import annotations

import contextlib
import json
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError, GeometryError, MeshgenError, excerpt
from meshgen.formats import metadata_of, read_cells, read_grid, read_header, read_mesh, write_mesh
from meshgen.formats.metadata import is_timing
from meshgen.formats.multiblock import MultiZoneError, read_zones, zone_count
from meshgen.geometry.blocks import BlockSet, block_spec, measured_block_set
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import geometry_patches
from meshgen.geometry.plugins import Geometry, load_geometry, load_recorded_geometry
from meshgen.quality.chunked import chunked_report
from meshgen.quality.deviation import block_set_deviation
from meshgen.quality.faces import cells_for_quality
from meshgen.quality.merged import merged_reports
from meshgen.quality.report import (
    assemble_report,
    assess,
    assess_in_parallel,
    build_report,
    node_array_deviation,
    quality_report,
    report_in_parallel,
)
from meshgen.quality.structured import check_node_array, load_compiled_kernels, use_compiled
from meshgen.quality.worker import EvaluationWorker, worker_fits
from meshgen.run.atomic import atomic_path
from meshgen.run.early import release_early_worker
from meshgen.run.inputs import read_input_text
from meshgen.run.publish import publishing
from meshgen.run.resources import needs_chunking
from meshgen.run.trust import UntrustedGeometry, recorded_spec

__all__ = [
    "zone_reports",
    "BLOCK_DATA",
    "EVALUATE_BYTES_PER_NODE",
    "as_node_array",
    "evaluate_file",
    "json_ready",
    "recorded_metadata",
    "sidecar_path",
    "write_json",
    "write_mesh_alone",
    "write_mesh_with_quality",
]


def as_node_array(points, cells, dims, grid_shape=None) -> np.ndarray | None:
    """The node array of an unstructured mesh that is exactly meshgen's structured grid of ``dims``
    cells (same node order and connectivity), else None: such files take the fast path.
    ``cells`` None: the points are the structured grid of ``grid_shape`` nodes (a .vts read as
    its grid), whose connectivity is meshgen's."""
    dims = tuple(int(n) for n in dims)
    node_shape = tuple(n + 1 for n in dims)
    dim = len(dims)
    if cells is None:
        if tuple(grid_shape) != node_shape:
            return None
    elif len(points) != int(np.prod(node_shape)) or cells.shape != (int(np.prod(dims)), 2**dim):
        return None
    elif not np.array_equal(cells, cell_connectivity(node_shape)):
        return None
    if dim == 2 and points.shape[1] == 3:
        if np.any(points[:, 2] != points[0, 2]):
            return None
    return np.ascontiguousarray(points[:, :dim]).reshape(*node_shape, dim)


def sidecar_path(mesh_path) -> Path:
    """``<mesh>.quality.json`` beside a mesh file (the full file name, extension included)."""
    mesh_path = Path(mesh_path)
    return mesh_path.with_name(mesh_path.name + ".quality.json")


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON atomically (non-finite floats as null)."""
    path = Path(path)
    text = json.dumps(json_ready(data), indent=2, allow_nan=False) + "\n"
    try:
        with atomic_path(path) as temporary:
            temporary.write_text(text)
    except OSError as exc:
        raise MeshgenError(f"could not write {path}: {exc.strerror or exc}") from exc
    return path


def json_ready(data):
    """``data`` with NumPy scalars as plain numbers and non-finite floats as None (JSON null), for
    ``json.dumps(..., allow_nan=False)``."""
    if isinstance(data, dict):
        return {k: json_ready(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [json_ready(v) for v in data]
    if isinstance(data, (float, np.floating)):
        return float(data) if np.isfinite(data) else None
    if isinstance(data, np.integer):
        return int(data)
    if isinstance(data, np.bool_):
        return bool(data)
    return data


def write_mesh_with_quality(path, X, geometry=None, metadata: dict | None = None, worker=None, **write_options) -> dict:
    """Write node array ``X`` to ``path`` with the seven per-cell metrics as cell data (formats
    that carry cell data keep them), and the report plus ``metadata`` (geometry, params, method,
    ...) to ``<path>.quality.json``. ``write_options`` go to ``meshgen.formats.write_mesh``
    (``patches``, default the ``geometry``'s; ``format``; ``binary``). The report is computed in
    parts on threads while the writer starts (``meshgen.quality.report.report_in_parallel``), or by
    ``worker`` (a ``meshgen.quality.worker.QualityWorker`` made for this mesh, which the caller
    closes) in its own process; if the worker fails, here. Returns the report (with
    ``quality_seconds``: wall seconds from the start of the quality to its report, overlapping the
    write)."""
    if geometry is not None and "patches" not in write_options:
        write_options["patches"] = geometry_patches(geometry)
    X = check_node_array(X)
    start = time.perf_counter()
    if worker is not None and not worker.submit(X):
        worker = None
    with ThreadPoolExecutor(max_workers=4, thread_name_prefix="meshgen-quality") as pool:
        measured = []

        def metrics_then_report():
            # The per-cell metrics, for the writer to compress (a .vtu compresses the nodes and
            # cells meanwhile), while the rest of the report is computed on other threads.
            metrics = worker.metrics() if worker is not None else None
            if metrics is not None:
                measured.append(pool.submit(lambda: worker.report() or quality_report(X, geometry)))
                return metrics
            metrics, report = report_in_parallel(X, geometry, pool)
            measured.append(report)
            return metrics

        with publishing(path, FormatError):  # the mesh and its sidecar take their names together, or neither does
            written = write_mesh(path, X, cell_data=metrics_then_report, metadata=metadata, **write_options)
            report = measured[0].result()
            report["quality_seconds"] = time.perf_counter() - start  # overlapping the write
            write_json(sidecar_path(written), {"mesh": os.path.basename(written), **(metadata or {}), **report})
    return report


def write_mesh_alone(path, X, metadata: dict | None = None, **write_options) -> Path:
    """Write node array ``X`` to ``path`` without quality arrays or sidecar (``meshgen mesh
    --no-quality``); the sidecar of a previous mesh under that name is removed in the same
    publication, so no sidecar describes a mesh it was not written with. Returns the path written."""
    with publishing(path, FormatError) as publication:
        written = write_mesh(path, X, metadata=metadata, **write_options)
        publication.remove(sidecar_path(written))
    return written


# ---------------------------------------------------------------------------------------------
# mesh files (meshgen evaluate)


def recorded_metadata(path, mesh) -> dict:
    """meshgen's metadata of a mesh file: what the file records (geometry, params, method, dims),
    with the timings of its ``<mesh>.quality.json`` sidecar (mesh files keep none:
    ``meshgen.formats.metadata``), else the sidecar's (marked ``"source": "sidecar"``), else {}."""
    metadata = metadata_of(mesh)
    sidecar = sidecar_path(path)
    recorded = {}
    if sidecar.is_file():
        try:
            recorded = json.loads(read_input_text(sidecar, "sidecar", MAX_SIDECAR_BYTES))
        except (OSError, ValueError, MeshgenError, RecursionError):
            recorded = {}
        recorded = recorded if isinstance(recorded, dict) else {}
    if metadata:
        if recorded.get("mesh") == Path(path).name:
            metadata.update({key: value for key, value in recorded.items() if is_timing(key) and key not in metadata})
        return {**metadata, "source": "file"}
    return {**recorded, "source": "sidecar"} if recorded else {}


MAX_SIDECAR_BYTES = 16 * 2**20  # a sidecar is a report of a few kB: a larger file is not one
BLOCK_DATA = "block"  # the cell data of a merged block-set file: the block of each cell
EVALUATE_BYTES_PER_NODE = 600  # measured order of the in-memory evaluate of a file (mesh, cells, metrics)


def evaluate_file(
    path,
    geometry=None,
    params: dict | None = None,
    mesh=None,
    chunked: bool | None = None,
    client=None,
    progress=None,
    block_nodes: int | None = None,
    per_block: bool = False,
) -> dict:
    """Quality report of a mesh file (any format ``meshgen.formats.read_mesh`` reads), with
    ``file`` and ``structured`` keys added.

    ``geometry``: a name or plugin path, a Geometry, or None for the geometry the file (or its
    sidecar) records; ``params`` override the geometry's parameters. A file that is meshgen's own
    structured grid takes the structured path. ``mesh``: the file as ``read_mesh(path)`` returned
    it, for a caller that needs it too (read once). MeshgenError when nothing can be evaluated.

    ``chunked``: evaluate block by block (``meshgen.quality.chunked``; CGNS files), True, False,
    or None for automatically when the file is CGNS and the in-memory path would need more than
    half of the available memory. ``client``: a ``distributed.Client`` to run the blocks on.
    ``progress(done, phase=...)``: hears the fraction done (0 to 1) as each phase begins (reading,
    metrics, report; block by block on the chunked path), so a long evaluation is never silent.
    ``block_nodes``: nodes per block of the chunked path (default
    ``meshgen.quality.chunked.evaluate_block_nodes()``).

    A mesh made of blocks (a multi-zone .cgns, a merged file with the cell data ``block``, or any
    file evaluated against a block set) is measured merged, interfaces as interior faces
    (``meshgen.quality.merged``), with the block set's boundary deviation
    (``meshgen.quality.deviation.block_set_deviation``); ``per_block``: its blocks' reports too,
    under ``blocks`` (``file`` named ``<path>:<block>``).
    """
    try:
        return _evaluate_file(path, geometry, params, mesh, chunked, client, progress, block_nodes, per_block)
    finally:
        release_early_worker()  # the child ``meshgen evaluate`` forked first, unless a worker adopted it


def _evaluate_file(path, geometry, params, mesh, chunked, client, progress, block_nodes, per_block) -> dict:
    progress = progress or (lambda done, **figures: None)
    path = Path(path)
    if not path.exists():
        raise MeshgenError(f"mesh file {path} does not exist")
    if path.is_file() and path.stat().st_size == 0 and path.suffix.lower() != ".foam":
        raise MeshgenError(f"mesh file {path} is empty")
    if chunked is None and mesh is None and path.suffix.lower() == ".cgns":
        chunked = _chunked_by_default(path, client)
    if chunked:
        return _evaluate_file_in_blocks(path, geometry, params, client, progress, block_nodes)
    preloading = _Preloading()
    try:
        if mesh is None:
            progress(0.0, phase="reading")
            mesh = _read_for_evaluation(path, preloading)
        return _evaluate_mesh(path, mesh, geometry, params, progress, per_block, preloading)
    finally:
        preloading.close()


class _Preloading:
    """What ``_read_for_evaluation`` started for the metrics while the file is read: an
    ``EvaluationWorker`` (a forked process loading numba) or threads loading numba here."""

    def __init__(self):
        self.worker = None
        self.threads = []

    def worker_for(self, node_shape):
        """The ``EvaluationWorker`` of a node array of ``node_shape`` nodes: the one forked while
        the file was read, else one made now (adopting the child ``meshgen evaluate`` forked
        first, if any) where ``worker_fits``; None where none fits or none can be forked."""
        # not while a thread here may be importing numba: no fork with an import under way
        if self.worker is None and not self.threads and worker_fits(node_shape):
            with contextlib.suppress(OSError):
                self.worker = EvaluationWorker(node_shape)
        return self.worker

    def close(self) -> None:
        for thread in self.threads:
            thread.join()
        if self.worker is not None:
            self.worker.close(wait=False)  # done with it: its memory goes back while the table is printed
            self.worker = None


def _read_for_evaluation(path: Path, preloading: _Preloading):
    """The mesh file ``path`` as ``read_mesh`` reads it; a .vts as its grid (``read_grid``: no
    connectivity, only the cell data ``block`` of its cell arrays); a .vtu of hexahedra or of
    quadrilaterals with only that cell data (``read_cells``: meshgen's decoder, not meshio's). When the compiled kernels will
    measure it, numba loads while its arrays inflate: in an ``EvaluationWorker`` (a forked process,
    where ``worker_fits``: design notes §21, "meshgen evaluate: numba in a forked worker"; the child
    ``meshgen evaluate`` forked first, if there is one), else on a thread here (``preloading`` holds
    either)."""

    def load():
        try:
            load_compiled_kernels()
        except Exception:  # noqa: BLE001 - the metrics meet the same error where it is reported
            pass

    def preload(node_shape):
        if worker_fits(node_shape):
            with contextlib.suppress(OSError):  # no fork: the thread
                preloading.worker = EvaluationWorker(node_shape)
                return
        release_early_worker()  # a small mesh: no core is taken from the parent's NumPy threads
        if use_compiled(int(np.prod([n - 1 for n in node_shape]))):
            thread = threading.Thread(target=load, name="meshgen-numba")
            thread.start()
            preloading.threads.append(thread)

    grid = read_grid(path, cell_arrays=(BLOCK_DATA,), point_arrays=(), on_shape=preload)
    if grid is not None:
        return grid
    mesh = read_cells(path, cell_arrays=(BLOCK_DATA,))  # a .vtu of one cell kind: points, cells and blocks only
    return mesh if mesh is not None else read_mesh(path)


def _evaluate_mesh(path: Path, mesh, geometry, params, progress, per_block: bool, preloading: _Preloading) -> dict:
    """``evaluate_file`` of the file ``path`` read as ``mesh`` (a ``meshio.Mesh`` or a .vts grid);
    ``preloading``: what was started for the metrics while it was read (``worker_for`` gives the
    ``EvaluationWorker`` of a structured mesh)."""
    grid_shape = getattr(mesh, "node_shape", None)  # a .vts grid: the cells are the grid's
    if grid_shape is not None:
        points, cells, skipped = mesh.points, None, {}
        n_cells = int(np.prod([n - 1 for n in grid_shape]))
        if n_cells == 0:
            raise MeshgenError(f"{path}: the mesh has no cells")
    else:
        try:
            points, cells, skipped = cells_for_quality(mesh)
        except MeshgenError as exc:
            raise MeshgenError(f"{path}: {exc}") from None
        n_cells = len(cells)
    metadata = recorded_metadata(path, mesh)
    geometry, source, notes = _geometry_for(path, geometry, params, metadata, n_cells)
    blocks = _cell_blocks(mesh, n_cells)
    if isinstance(geometry, BlockSet) or blocks is not None:
        progress(0.3, phase="metrics")
        cells = cells if cells is not None else cell_connectivity(grid_shape)
        reports = _block_set_reports(path, points, cells, blocks, geometry, metadata)
        progress(1.0, phase="done")
        report = _finish_file_report(path, reports[0], source, notes, metadata, False)
        if per_block:
            report["blocks"] = [{"file": f"{path}:{r.pop('block')}", **r} for r in reports[1:]]
        return report
    dims = metadata.get("dims")
    X = None
    if isinstance(dims, list) and len(dims) in (2, 3) and all(isinstance(n, int) and n > 0 for n in dims):
        X = as_node_array(points, cells, dims, grid_shape)
    progress(0.3, phase="metrics")
    if X is not None:
        worker = preloading.worker_for(X.shape[:-1])
        report = _node_array_report(path, X, geometry, source, notes, skipped, progress, worker)
        progress(1.0, phase="done")
        return _finish_file_report(path, report, source, notes, metadata, True)
    cells = cells if cells is not None else cell_connectivity(grid_shape)
    try:
        metrics, degenerate, info = assess((points, cells))
    except MeshgenError as exc:
        raise MeshgenError(f"{path}: {exc}") from None
    _check_not_all_degenerate(path, degenerate)
    info["skipped"] = skipped
    progress(0.8, phase="report")
    geometry = _geometry_of_dim(geometry, info["dim"], source, notes)
    report = build_report(metrics, degenerate, info, geometry)
    progress(1.0, phase="done")
    return _finish_file_report(path, report, source, notes, metadata, False)


def _node_array_report(path, X, geometry, source, notes, skipped, progress, worker=None) -> dict:
    """The report of a file that is meshgen's structured grid, node array ``X``: the per-cell
    metrics here, the solver figures and the boundary deviation on threads meanwhile; or, by
    ``worker`` (an ``EvaluationWorker`` of X's shape), the metrics' summaries and the solver
    figures in its process, the boundary deviation here meanwhile. The same functions on the same
    values, so the same report; a worker that fails changes only where the report is made."""
    geometry = _geometry_of_dim(geometry, X.shape[-1], source, notes)
    measured = geometry if geometry is not None and geometry.dim == X.shape[-1] else None
    if worker is not None and worker.submit(X):
        deviation = node_array_deviation(X, measured) if measured is not None else None
        parts = worker.parts()
        if parts is not None:
            if parts["all_degenerate"]:
                _check_not_all_degenerate(path, np.ones(parts["cells"], dtype=bool))
            info = {"dim": parts["dim"], "nonfinite_nodes": parts["nonfinite_nodes"], "skipped": skipped}
            info["solver_figures"] = lambda: parts["solver_figures"]
            if deviation is not None:
                info["boundary_deviation"] = deviation
            progress(0.8, phase="report")
            return assemble_report(parts["summaries"], parts["counts"], info, geometry)
    with ThreadPoolExecutor(max_workers=3, thread_name_prefix="meshgen-quality") as pool:
        try:
            metrics, degenerate, info = assess_in_parallel(X, measured, pool)
        except MeshgenError as exc:
            raise MeshgenError(f"{path}: {exc}") from None
        _check_not_all_degenerate(path, degenerate)
        info["skipped"] = skipped
        progress(0.8, phase="report")
        return build_report(metrics, degenerate, info, geometry)


def _geometry_of_dim(geometry, dim: int, source: str, notes: list):
    """``geometry``, or None (with a note) when it was recorded, not given, and is not of the
    mesh's dimension ``dim`` (a --geometry of another dimension is ``build_report``'s error)."""
    if geometry is not None and geometry.dim != dim and source != "--geometry":
        notes.append(f"recorded geometry '{geometry.name}' is {geometry.dim}D but the mesh is {dim}D; no boundary deviation")
        return None
    return geometry


def _check_not_all_degenerate(path, degenerate) -> None:
    if degenerate.all():
        raise MeshgenError(
            f"{path}: nothing to evaluate: all {len(degenerate)} cells are degenerate "
            "(zero-length edges or non-finite coordinates)"
        )


def _chunked_by_default(path, client) -> bool:
    """Whether a .cgns file is evaluated block by block when the caller did not say: with a
    ``client``, or when the in-memory path would need more than half of the memory. A multi-zone
    file (a block set) is read in memory: the block-by-block path reads one zone."""
    try:
        node_shape, _ = read_header(path)
    except MultiZoneError:
        if client is not None:
            raise
        return False
    return client is not None or needs_chunking(int(np.prod(node_shape)), EVALUATE_BYTES_PER_NODE)


def _evaluate_file_in_blocks(path, geometry, params, client, progress, block_nodes=None) -> dict:
    """``evaluate_file`` of a CGNS file block by block (``meshgen.quality.chunked``)."""
    if path.suffix.lower() != ".cgns":
        raise MeshgenError(f"{path}: only .cgns files can be evaluated block by block (structured zones read by hyperslabs)")
    node_shape, recorded = read_header(path)
    metadata = {**recorded, "source": "file"} if recorded else recorded_metadata(path, None)
    cells = int(np.prod([n - 1 for n in node_shape]))
    geometry, source, notes = _geometry_for(path, geometry, params, metadata, cells)
    if geometry is not None and geometry.dim != len(node_shape) and source != "--geometry":
        notes.append(
            f"recorded geometry '{geometry.name}' is {geometry.dim}D but the mesh is {len(node_shape)}D; no boundary deviation"
        )
        geometry = None
    try:
        report = chunked_report(
            path,
            geometry,
            client=client,
            progress=lambda done, total, phase: progress(done / total, blocks=f"{done}/{total}"),
            block_nodes=block_nodes,
        )
    except MeshgenError as exc:
        raise MeshgenError(f"{path}: {exc}") from None
    return _finish_file_report(path, report, source, notes, metadata, True)


def _geometry_for(path, geometry, params, metadata, n_cells):
    """(geometry or None, where it came from, notes) for evaluating the file ``path``."""
    if metadata.get("source") == "sidecar" and (metadata.get("cells") != n_cells or metadata.get("mesh") != path.name):
        metadata.clear()  # a sidecar of another mesh that once had this name
    notes = []
    source = "--geometry"
    spec = block_spec(geometry)
    if spec is not None:  # a multi-block geometry: its block set, with the cell counts recorded
        values = {**(geometry.values if isinstance(geometry, Geometry) else {}), **(params or {})}
        return measured_block_set(spec, values, _recorded_block_dims(metadata)), source, notes
    if geometry is None and metadata.get("block_set") and not params:
        source = f"recorded in the {'mesh file' if metadata['source'] == 'file' else 'sidecar ' + sidecar_path(path).name}"
        try:
            spec = recorded_spec(metadata["block_set"], source.removeprefix("recorded in ").replace("the ", "", 1))
            return measured_block_set(spec, _recorded_params(metadata), _recorded_block_dims(metadata)), source, notes
        except UntrustedGeometry:
            notes.append(
                f"recorded block set is the file {excerpt(metadata['block_set'])}, which a mesh file cannot make meshgen read or run: "
                "no boundary deviation (pass -g PATH to use it)"
            )
        except GeometryError as exc:
            notes.append(
                f"recorded block set {excerpt(repr(metadata['block_set']))} is not available ({exc}); no boundary deviation"
            )
        return None, source, notes
    if isinstance(geometry, str):
        geometry = load_geometry(geometry, params)
    elif geometry is not None and params:
        geometry = geometry.with_params(**params)
    elif geometry is None and metadata.get("geometry"):
        source = f"recorded in the {'mesh file' if metadata['source'] == 'file' else 'sidecar ' + sidecar_path(path).name}"
        recorded = metadata["geometry"]
        try:
            values = {**_recorded_params(metadata), **(params or {})}
            geometry = load_recorded_geometry(recorded, values, where=source.removeprefix("recorded in ").replace("the ", "", 1))
        except UntrustedGeometry:
            notes.append(
                f"recorded geometry is the plugin file {excerpt(recorded)}, which a file cannot make meshgen run: "
                "no boundary deviation (pass -g PATH to use it)"
            )
            geometry = None
        except GeometryError as exc:
            notes.append(
                f"recorded geometry {excerpt(repr(recorded))} is not available ({exc}); pass --geometry for boundary deviation"
            )
            geometry = None
    elif params:
        raise MeshgenError(f"--param needs --geometry: {path} records no geometry")
    return geometry, source, notes


def _recorded_params(metadata) -> dict:
    """The recorded parameters of a geometry: a mapping of names to numbers, else GeometryError."""
    params = metadata.get("params", {})
    if not isinstance(params, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) for k, v in params.items()
    ):
        raise GeometryError("its recorded parameters are not a mapping of names to numbers")
    return params


def _finish_file_report(path, report, source, notes, metadata, structured) -> dict:
    if "boundary_deviation" in report:
        report["boundary_deviation"]["source"] = source
    if notes:
        report["warnings"] = report.get("warnings", []) + notes
    for key in ("method", "dims"):
        if key in metadata:
            report.setdefault("recorded", {})[key] = metadata[key]
    return {"file": str(path), "structured": structured, **report}


def zone_reports(path) -> list[dict]:
    """The quality report of each block of a mesh made of blocks (``evaluate_file``'s
    ``per_block``), ``file`` named ``<path>:<block>``; [] for any other file."""
    return evaluate_file(path, chunked=False, per_block=True).get("blocks", [])


def _recorded_block_dims(metadata) -> tuple | None:
    dims = metadata.get("block_dims")
    if isinstance(dims, list) and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in dims):
        return tuple(dims)
    return None


def _cell_blocks(mesh, n_cells: int) -> np.ndarray | None:
    """The block of each cell of a merged block-set file (its cell data ``block``: a multi-zone
    .cgns read merged, a .vtu meshgen wrote), or None (one block, or no such data)."""
    data = getattr(mesh, "cell_data", {}).get(BLOCK_DATA)
    if not data or len(data) != 1 or len(data[0]) != n_cells:
        return None
    blocks = np.asarray(data[0])
    if not np.all(np.isfinite(blocks)) or np.any(blocks < 0) or np.any(blocks != np.round(blocks)):
        return None
    blocks = blocks.astype(np.int64)
    if blocks.max() < 1 or np.any(np.diff(blocks) < 0):  # one block, or cells not block after block
        return None
    return blocks


def _block_set_reports(path, points, cells, blocks, block_set, metadata) -> list[dict]:
    """[whole, each block's] reports of a mesh made of blocks (``meshgen.quality.merged``). Blocks
    are named and shaped by the .cgns zones, else the block set's (when the cell counts fit), else
    numbered (cells located by their number in the block)."""
    zones = read_zones(path) if path.suffix.lower() == ".cgns" and zone_count(path) > 1 else None
    counts = np.bincount(blocks) if blocks is not None else None
    if zones is not None:
        names = tuple(zone["name"] for zone in zones)
        shapes = [tuple(n - 1 for n in zone["X"].shape[:-1]) for zone in zones]
    elif block_set is not None and counts is not None and len(counts) == len(block_set.names):
        names, shapes = block_set.names, [tuple(n - 1 for n in s) for s in block_set.node_shapes]
    elif counts is not None:
        names, shapes = tuple(str(b) for b in range(len(counts))), [(int(n),) for n in counts]
    else:
        names, shapes = (), []
    if counts is not None and [int(np.prod(s)) for s in shapes] != [int(n) for n in counts]:
        names, shapes = tuple(str(b) for b in range(len(counts))), [(int(n),) for n in counts]
    deviation = None
    if block_set is not None:
        Xs = [zone["X"] for zone in zones] if zones is not None else None
        if Xs is not None and names == block_set.names and [X.shape[:-1] for X in Xs] == block_set.node_shapes:
            deviation = block_set_deviation(block_set, Xs)
        else:

            def deviation(boundary_points):
                return block_set_deviation(block_set, points=boundary_points)

    try:
        return merged_reports(points, cells, blocks, names, shapes, block_set, deviation)
    except MeshgenError as exc:
        raise MeshgenError(f"{path}: {exc}") from None
