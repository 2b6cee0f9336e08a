"""Mesh writers (and readers), looked up by file extension.

Each format is a small module with ``write(path, X, cell_data, metadata)`` (formats that carry
boundary patches: ``write(path, X, cell_data, metadata, patches)``, ``patches`` a list of
``meshgen.geometry.patches.Patch`` covering every cube face, and ``read_patches(path)``; where names are
restricted, ``check_patch_name(name)``) and, where meshgen can read it back,
``read(path) -> meshio.Mesh``. A folder format (OpenFOAM) also has ``check_output(path)`` and writes
atomically itself. ``X`` is the node array of design notes §2;
``cell_data`` maps names to per-cell arrays in C order of the cells (i, j[, k]); ``metadata`` is a
JSON-serialisable dict (geometry, parameters, method, meshgen version) stored where the format
allows (every format but Plot3D, which has no place for it); ``metadata_of`` reads it back.
A format that a mesh larger than memory can be written in either takes
blocks as they come (CGNS: ``stream``, ``write_node_block``) or has
``write_streamed(path, nodes, metadata, patches)`` reading a scratch node file slab by slab
(``meshgen.formats.streamed``; registered as ``streamed``).
Adding a format is one module and one ``register_format`` line.

Every reader returns points in the C order of the nodes (k fastest, as ``flat_points`` writes
them), padded to three columns, and meshgen's metadata as JSON bytes (uint8) in
``mesh.field_data["meshgen"]``.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError, MeshgenError, excerpt
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry.patches import check_covers
from meshgen.run.atomic import atomic_write, check_output_file
from meshgen.run.inputs import InputError, check_input_file
from meshgen.run.publish import publishing

__all__ = [
    "FORMATS",
    "METADATA_KEY",
    "Format",
    "block_reader",
    "check_output_path",
    "check_patches",
    "extensions",
    "format_for",
    "format_named",
    "format_names",
    "metadata_json",
    "metadata_of",
    "read_cells",
    "read_grid",
    "read_header",
    "read_mesh",
    "read_node_block",
    "read_node_components",
    "read_patches",
    "register_format",
    "streaming_writer",
    "write_mesh",
]


@dataclass(frozen=True)
class Format:
    name: str
    extensions: tuple[str, ...]
    module: str
    description: str
    patches: bool = False  # carries named boundary patches
    dims: tuple[int, ...] = (2, 3)  # mesh dimensions it takes
    folder: bool = False  # writes a folder (an OpenFOAM case), chosen with --format
    streams: bool = False  # written block by block (``stream`` and ``write_node_block``): meshes larger than memory
    # The module whose ``write_streamed`` writes it slab by slab from a node file
    # (``meshgen.formats.streamed``): meshes larger than memory, through a scratch CGNS file.
    streamed: str = ""
    # Its writer takes ``cell_data`` as a callable too, called once the nodes and cells are under
    # way (compressing on other threads): what computes the cell data runs meanwhile.
    deferred_cell_data: bool = False

    @property
    def label(self) -> str:
        """How the user names it: its first extension, or ``--format NAME`` for a folder format."""
        return self.extensions[0] if self.extensions else f"--format {self.name}"


FORMATS: list[Format] = []


def register_format(name: str, extensions, module: str, description: str, **options) -> None:
    FORMATS.append(Format(name, tuple(extensions), module, description, **options))


register_format("vtu", [".vtu"], "meshgen.formats._vtu", "VTK XML unstructured grid (zlib-compressed)", deferred_cell_data=True)
register_format(
    "vts",
    [".vts"],
    "meshgen.formats._vts",
    "VTK XML structured grid (zlib-compressed, no connectivity), patch ids",
    patches=True,
    streamed="meshgen.formats._vts_streamed",
)
register_format(
    "pvts",
    [".pvts"],
    "meshgen.formats._pvts",
    "VTK XML partitioned structured grid: a .vts piece per slab in the folder <name>/, patch ids",
    patches=True,
    streamed="meshgen.formats._pvts",
)
register_format("vtk", [".vtk"], "meshgen.formats._meshio", "legacy VTK unstructured grid (binary)")
register_format("xdmf", [".xdmf"], "meshgen.formats._meshio", "XDMF with inline XML data (one self-contained file)")
register_format(
    "cgns", [".cgns"], "meshgen.formats._cgns", "CGNS/HDF5, one structured zone, a BC_t per patch", patches=True, streams=True
)
register_format(
    "openfoam",
    [],
    "meshgen.formats._openfoam",
    "OpenFOAM case: constant/polyMesh (2D: extruded one cell) and CASE.foam",
    patches=True,
    folder=True,
    streamed="meshgen.formats._foam_streamed",
)
register_format(
    "su2",
    [".su2"],
    "meshgen.formats._su2",
    "SU2 native mesh (ASCII), a MARKER_TAG per patch",
    patches=True,
    streamed="meshgen.formats._su2",
)
register_format(
    "gmsh",
    [".msh"],
    "meshgen.formats._gmsh",
    "Gmsh MSH 4.1 (ASCII), a physical group per patch and one for the cells",
    patches=True,
    streamed="meshgen.formats._gmsh",
)
register_format(
    "plot3d",
    [".xyz"],
    "meshgen.formats._plot3d",
    "Plot3D grid, one block, Fortran unformatted, double precision",
    streamed="meshgen.formats._plot3d",
)
register_format(
    "plot3d-ascii",
    [".fmt"],
    "meshgen.formats._plot3d",
    "Plot3D grid, one block, formatted (ASCII)",
    streamed="meshgen.formats._plot3d",
)


def extensions() -> list[str]:
    return [ext for fmt in FORMATS for ext in fmt.extensions]


def format_names() -> list[str]:
    return [fmt.name for fmt in FORMATS]


def format_named(name: str) -> Format:
    for fmt in FORMATS:
        if fmt.name == name:
            return fmt
    raise FormatError(f"unknown format '{name}'; pick one of {', '.join(format_names())}")


def format_for(path: str | os.PathLike, format_name: str | None = None) -> Format:
    """The format named ``format_name``, else the registered format of ``path``'s extension;
    FormatError listing the valid ones otherwise."""
    if format_name is not None:
        return format_named(format_name)
    suffix = Path(path).suffix.lower()
    for fmt in FORMATS:
        if suffix in fmt.extensions:
            return fmt
    shown = suffix or "(none)"
    folders = ", ".join(f"--format {fmt.name}" for fmt in FORMATS if fmt.folder)
    raise FormatError(
        f"unknown output extension {shown} for {path}; pick one of {', '.join(extensions())} (or {folders} for a case folder)"
    )


def check_output_path(path: str | os.PathLike, format_name: str | None = None, dim: int | None = None) -> Path:
    """Validate an output path before any work is done: known extension (or ``format_name``),
    existing writable folder, not a folder itself (folder formats: their own rules), a format that
    takes ``dim``-dimensional meshes. Returns the path to write (an OpenFOAM case: its folder)."""
    fmt = format_for(path, format_name)
    if dim is not None and dim not in fmt.dims:
        raise FormatError(f"{fmt.name} takes {' or '.join(f'{d}D' for d in fmt.dims)} meshes, not {dim}D")
    module = importlib.import_module(fmt.module)
    if fmt.folder:
        return module.check_output(path)
    path = check_output_file(path, "mesh" + (fmt.extensions or extensions())[0])
    if hasattr(module, "check_target"):  # a format that writes more than the file (.pvts: its pieces' folder)
        module.check_target(path)
    return path


def streaming_writer(path, format_name: str | None = None, node_shape=None):
    """The format of ``path`` (or ``format_name``) when a mesh larger than memory can be written in
    it: block by block (``streams``: CGNS) or slab by slab from a scratch node file
    (``streamed``); FormatError naming the formats that can, otherwise, or when the format cannot
    hold a mesh of ``node_shape`` nodes (the module's ``check_node_shape``), before any work."""
    fmt = format_for(path, format_name)
    if not (fmt.streams or fmt.streamed):
        able = ", ".join(f.label for f in FORMATS if f.streams or f.streamed)
        raise FormatError(
            f"{fmt.name} ({fmt.label}) cannot be written block by block, which a mesh larger than memory needs; formats that can: {able}"
        )
    module = importlib.import_module(fmt.module)
    if node_shape is not None and hasattr(module, "check_node_shape"):
        module.check_node_shape(tuple(int(n) for n in node_shape), path)
    return fmt


def block_reader(path, format_name: str | None = None):
    """The reader module of ``path``'s format (or ``format_name``'s) when it can read a structured
    mesh block by block (``zone_header``, ``read_node_block``: the formats that stream); FormatError
    naming the formats that can, otherwise."""
    fmt = format_for(path, format_name)
    if not fmt.streams:
        able = ", ".join(f.label for f in FORMATS if f.streams)
        raise FormatError(f"{fmt.name} ({fmt.label}) cannot be read block by block; formats that can: {able}")
    return importlib.import_module(fmt.module)


def read_header(path) -> tuple[tuple[int, ...], dict]:
    """(node shape (ni, nj[, nk]), meshgen's metadata dict or {}) of a structured mesh file that
    can be read block by block (CGNS), without reading the nodes."""
    try:
        check_input_file(path, "mesh file")
    except InputError as exc:
        raise FormatError(str(exc)) from None
    return block_reader(path).zone_header(path)


def read_node_block(path, block) -> np.ndarray:
    """The nodes ``block`` (one slice per index axis) of a structured mesh file that can be read
    block by block (CGNS): an array of the block's shape + (dim,), C order, float64."""
    return block_reader(path).read_node_block(path, block)


def read_node_components(path, block, out=None) -> np.ndarray:
    """The nodes ``block`` of a structured mesh file that can be read block by block (CGNS), by
    component in the file's order (``_cgns.read_node_components``): (dim, block shape reversed),
    float64, read into ``out`` when it has that shape."""
    return block_reader(path).read_node_components(path, block, out)


def check_patches(patches, dim: int, path=None, format_name: str | None = None):
    """``patches`` (None: one per face, named after it) checked to cover every face once, and their
    names against the format of ``path`` / ``format_name`` if given. Returns Patch objects."""
    try:
        checked = check_covers(patches, dim)
    except MeshgenError as exc:
        raise FormatError(str(exc)) from None
    if path is not None or format_name is not None:
        fmt = format_for(path or "", format_name)
        module = importlib.import_module(fmt.module)
        for patch in checked:
            if hasattr(module, "check_patch_name"):
                module.check_patch_name(patch.name)
    return checked


def write_mesh(
    path,
    X: np.ndarray,
    cell_data=None,
    metadata: dict | None = None,
    patches=None,
    format: str | None = None,
    **options,
) -> Path:
    """Write node array ``X`` to ``path`` atomically in the format ``format`` names (default: the
    one of the extension). ``cell_data``: name -> per-cell array, or a callable returning that
    mapping, called once: by a format with ``deferred_cell_data`` (``.vtu``) after its nodes and
    cells are under way, so that computing the cell data overlaps writing them; by any other
    before the write. ``patches``: the boundary patches (``meshgen.geometry.patches.Patch`` or
    ``{"name", "type", "faces"}`` records covering every cube face once; None: one per face, named
    after it), written by the formats that carry them. ``options``: format options (OpenFOAM:
    ``binary``). Returns the path written (an OpenFOAM case: its folder)."""
    X = np.asarray(X, dtype=float)
    if X.ndim not in (3, 4) or X.shape[-1] != X.ndim - 1 or min(X.shape[:-1]) < 2:
        raise FormatError(f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {X.shape}")
    fmt = format_for(path, format)
    path = check_output_path(path, format, X.shape[-1])
    patches = check_patches(patches, X.shape[-1], path, fmt.name)
    metadata_json(metadata or {})  # fail before anything is written
    node_shape = X.shape[:-1]
    if callable(cell_data) and fmt.deferred_cell_data:
        compute = cell_data

        def cell_data():
            return {name: _cell_array(name, values, node_shape) for name, values in (compute() or {}).items()}

    else:
        given = cell_data() if callable(cell_data) else cell_data
        cell_data = {name: _cell_array(name, values, node_shape) for name, values in (given or {}).items()}
    writer = importlib.import_module(fmt.module)
    arguments = (X, cell_data, dict(metadata or {})) + ((patches,) if fmt.patches else ())
    if not fmt.folder and options:
        raise FormatError(f"{fmt.name} takes no option {', '.join(options)}")
    # One publication (meshgen.run.publish): the file, or the case's files, take their names together
    # under the output's lock, with the sidecar when the caller publishes one with it.
    with publishing(path, FormatError):
        if fmt.folder:
            writer.write(path, *arguments, **options)
        else:
            with atomic_write(path, FormatError) as temporary:
                writer.write(temporary, *arguments)
    return path


def read_patches(path) -> list:
    """The boundary patches (``meshgen.geometry.patches.Patch``) a mesh file or case records; FormatError
    for a format that carries none."""
    fmt = _reading_format(Path(path))
    if fmt is None or not fmt.patches:
        raise FormatError(f"{path}: this format carries no boundary patches")
    return importlib.import_module(fmt.module).read_patches(Path(path))


def _reading_format(path: Path) -> Format | None:
    """The format to read ``path`` with: by extension, a folder format for a folder or its
    ``.foam`` file, None for meshio."""
    suffix = path.suffix.lower()
    if path.is_dir() or suffix == ".foam":
        return next(fmt for fmt in FORMATS if fmt.folder)
    return next((fmt for fmt in FORMATS if suffix in fmt.extensions), None)


def _cell_array(name, values, node_shape) -> np.ndarray:
    """A per-cell array as float64 of shape (n1*n2[*n3],), C order of the cells; FormatError if its
    size is not the number of cells."""
    values = np.asarray(values, dtype=float)
    cells = int(np.prod([n - 1 for n in node_shape]))
    if values.size != cells:
        raise FormatError(f"cell data '{name}' has {values.size} values for {cells} cells")
    return values.reshape(-1)


def metadata_of(source) -> dict:
    """meshgen's metadata dict of a mesh file (any registered format) or of a ``meshio.Mesh`` that
    ``read_mesh`` returned; {} where there is none (Plot3D, files written by other programs)."""
    if isinstance(source, (str, os.PathLike)):
        source = read_mesh(source)
    raw = getattr(source, "field_data", {}).get(METADATA_KEY)
    if raw is None:
        return {}
    try:
        metadata = json.loads(np.asarray(raw, dtype=np.uint8).tobytes().decode())
    except (ValueError, UnicodeDecodeError):
        return {}
    return metadata if isinstance(metadata, dict) else {}


def read_mesh(path):
    """Read a mesh file (or an OpenFOAM case folder, or its ``.foam`` file) as a ``meshio.Mesh``
    (our own readers where we have one, meshio for the rest)."""
    path = _checked_input(path)
    fmt = _reading_format(path)
    reader = importlib.import_module(fmt.module if fmt is not None else "meshgen.formats._meshio")
    return _reading(path, reader.read)


def read_grid(path, cell_arrays=None, point_arrays=None, on_shape=None):
    """A VTK structured grid file (.vts) read without connectivity, as ``meshgen.formats._vts.Grid``
    (node shape, points in C order, meshgen's field data), with only the cell and point arrays
    named in ``cell_arrays`` and ``point_arrays`` (None: all); None for a file of another format
    (``read_mesh`` reads those). ``on_shape(node_shape)`` is called before any array is inflated.
    Errors as ``read_mesh``'s."""
    path = _checked_input(path)
    fmt = _reading_format(path)
    if fmt is None or fmt.module != "meshgen.formats._vts":
        return None
    reader = importlib.import_module(fmt.module)
    return _reading(path, lambda where: reader.read_grid(where, cell_arrays, point_arrays, on_shape))


def read_cells(path, cell_arrays=None):
    """A .vtu file of hexahedra or of quadrilaterals read by meshgen's decoder as a ``meshio.Mesh``
    with only the cell arrays named in ``cell_arrays`` (None: all) and no point data
    (``meshgen.formats._vtu_read``); None for a file of another format or a .vtu it leaves to
    meshio (``read_mesh`` reads those). Errors as ``read_mesh``'s."""
    path = _checked_input(path)
    fmt = _reading_format(path)
    if fmt is None or fmt.module != "meshgen.formats._vtu":
        return None
    reader = importlib.import_module("meshgen.formats._vtu_read")
    return _reading(path, lambda where: reader.read_cells(where, cell_arrays))


def _checked_input(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FormatError(f"mesh file {path} does not exist")
    try:
        check_input_file(path, "mesh file", folder=True)  # a FIFO or a device is never handed to a reader
    except InputError as exc:
        raise FormatError(str(exc)) from None
    return path


def _reading(path: Path, read):
    """``read(path)``, its errors as FormatError naming the file, its printed output kept off stdout."""
    captured = io.StringIO()
    try:
        # meshio prints its own "Error:" line and calls sys.exit() on a file it cannot parse.
        with contextlib.redirect_stderr(captured), contextlib.redirect_stdout(captured):
            mesh = read(path)
    except SystemExit:
        said = " ".join(captured.getvalue().replace("Error:", "").split())
        raise FormatError(f"could not read {path}: {said or 'not a mesh file meshio can read'}") from None
    except FormatError as exc:
        if str(path) in str(exc):
            raise
        raise FormatError(f"could not read {path}: {exc}") from exc  # the reader's reason, with the file
    except Exception as exc:
        raise FormatError(f"could not read {path}: {type(exc).__name__}: {excerpt(exc, 200)}") from exc
    if captured.getvalue().strip():
        sys.stderr.write(captured.getvalue())  # the reader's warnings, kept off stdout
    return mesh
