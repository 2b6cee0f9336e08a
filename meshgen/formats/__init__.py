"""Mesh writers (and readers), looked up by file extension.

Each format is a small module with ``write(path, X, cell_data, metadata)`` and, where meshgen can
read it back, ``read(path) -> meshio.Mesh``. ``X`` is the node array of DESIGN section 2;
``cell_data`` maps names to per-cell arrays in C order of the cells (i, j[, k]); ``metadata`` is a
JSON-serialisable dict (geometry, parameters, method, meshgen version) stored where the format
allows (every format but Plot3D, which has no place for it); ``metadata_of`` reads it back.
Adding a format is one module and one ``register_format`` line.

Every reader returns points in the C order of the nodes (k fastest, as ``flat_points`` writes
them), padded to three columns, and meshgen's metadata as JSON bytes (uint8) in
``mesh.field_data["meshgen"]``.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import sys
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError


@dataclass(frozen=True)
class Format:
    name: str
    extensions: tuple[str, ...]
    module: str
    description: str
    streams: bool = False  # written block by block (``stream`` and ``write_node_block``): meshes larger than memory


FORMATS: list[Format] = []


def register_format(name: str, extensions, module: str, description: str, streams: bool = False) -> None:
    FORMATS.append(Format(name, tuple(extensions), module, description, streams))


register_format("vtu", [".vtu"], "meshgen.formats._vtu", "VTK XML unstructured grid (zlib-compressed)")
register_format("vtk", [".vtk"], "meshgen.formats._meshio", "legacy VTK unstructured grid (binary)")
register_format("xdmf", [".xdmf"], "meshgen.formats._meshio", "XDMF with inline XML data (one self-contained file)")
register_format("cgns", [".cgns"], "meshgen.formats._cgns", "CGNS/HDF5, one structured zone", streams=True)
register_format("plot3d", [".xyz"], "meshgen.formats._plot3d", "Plot3D grid, one block, Fortran unformatted, double precision")
register_format("plot3d-ascii", [".fmt"], "meshgen.formats._plot3d", "Plot3D grid, one block, formatted (ASCII)")

METADATA_KEY = "meshgen"


def extensions() -> list[str]:
    return [ext for fmt in FORMATS for ext in fmt.extensions]


def format_for(path: str | os.PathLike) -> Format:
    """The registered format of ``path``'s extension; FormatError listing the valid ones otherwise."""
    suffix = Path(path).suffix.lower()
    for fmt in FORMATS:
        if suffix in fmt.extensions:
            return fmt
    shown = suffix or "(none)"
    raise FormatError(f"unknown output extension {shown} for {path}; pick one of {', '.join(extensions())}")


def check_output_path(path: str | os.PathLike) -> Path:
    """Validate an output path before any work is done: known extension, existing writable folder,
    not a folder itself. Returns it as a Path."""
    from meshgen.atomic import check_output_file

    format_for(path)
    return check_output_file(path, "mesh" + extensions()[0])


def streaming_writer(path):
    """The writer module of ``path``'s format when it can write a mesh block by block (``stream``,
    ``write_node_block``); FormatError naming the formats that can, otherwise."""
    fmt = format_for(path)
    if not fmt.streams:
        able = ", ".join(ext for f in FORMATS if f.streams for ext in f.extensions)
        raise FormatError(
            f"{fmt.name} ({Path(path).suffix}) cannot be written block by block, which a mesh larger than memory "
            f"needs; formats that can: {able}"
        )
    return importlib.import_module(fmt.module)


def write_mesh(path, X: np.ndarray, cell_data: dict | None = None, metadata: dict | None = None) -> Path:
    """Write node array ``X`` to ``path`` atomically in the format its extension names."""
    from meshgen.atomic import atomic_path

    path = check_output_path(path)
    X = np.asarray(X, dtype=float)
    if X.ndim not in (3, 4) or X.shape[-1] != X.ndim - 1 or min(X.shape[:-1]) < 2:
        raise FormatError(f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {X.shape}")
    cell_data = {name: _cell_array(name, values, X.shape[:-1]) for name, values in (cell_data or {}).items()}
    metadata_json(metadata or {})  # fail before anything is written
    writer = importlib.import_module(format_for(path).module)
    try:
        with atomic_path(path) as temporary:
            writer.write(temporary, X, cell_data, dict(metadata or {}))
    except OSError as exc:
        raise FormatError(f"could not write {path}: {exc.strerror or exc}") from exc
    return path


def _cell_array(name, values, node_shape) -> np.ndarray:
    """A per-cell array as float64 of shape (n1*n2[*n3],), C order of the cells; FormatError if its
    size is not the number of cells."""
    values = np.asarray(values, dtype=float)
    cells = int(np.prod([n - 1 for n in node_shape]))
    if values.size != cells:
        raise FormatError(f"cell data '{name}' has {values.size} values for {cells} cells")
    return values.reshape(-1)


def metadata_json(metadata: dict) -> str:
    """``metadata`` as ASCII JSON (NumPy scalars and arrays become plain numbers and lists)."""

    def plain(value):
        if isinstance(value, (np.generic, np.ndarray)):
            return value.tolist()
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        raise TypeError(f"{type(value).__name__} value {value!r}")

    try:
        return json.dumps(metadata, default=plain)
    except (TypeError, ValueError) as exc:
        raise FormatError(f"metadata is not JSON-serialisable: {exc}") from exc


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
    """Read a mesh file as a ``meshio.Mesh`` (our CGNS and Plot3D readers, meshio for the rest)."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"mesh file {path} does not exist")
    suffix = path.suffix.lower()
    module = next((fmt.module for fmt in FORMATS if suffix in fmt.extensions), "meshgen.formats._meshio")
    reader = importlib.import_module(module)
    captured = io.StringIO()
    try:
        # meshio prints its own "Error:" line and calls sys.exit() on a file it cannot parse.
        with contextlib.redirect_stderr(captured), contextlib.redirect_stdout(captured):
            mesh = reader.read(path)
    except SystemExit:
        said = " ".join(captured.getvalue().replace("Error:", "").split())
        raise FormatError(f"could not read {path}: {said or 'not a mesh file meshio can read'}") from None
    except FormatError as exc:
        if str(path) in str(exc):
            raise
        raise FormatError(f"could not read {path}: {exc}") from exc  # the reader's reason, with the file
    except Exception as exc:
        raise FormatError(f"could not read {path}: {type(exc).__name__}: {exc}") from exc
    if captured.getvalue().strip():
        sys.stderr.write(captured.getvalue())  # the reader's warnings, kept off stdout
    return mesh
