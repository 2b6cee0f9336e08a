"""CGNS/HDF5 (.cgns): the mesh as ONE structured zone, written with h5py.

The tree (SIDS names and labels; data type and CGNS array shape after the colon)::

    CGNSLibraryVersion      CGNSLibraryVersion_t   R4: [3.4]
    Base                    CGNSBase_t             I4: [CellDimension, PhysicalDimension]
      DataClass             DataClass_t            C1: "NormalizedByUnknownDimensional"
      meshgen               Descriptor_t           C1: meshgen's metadata as JSON
      Zone                  Zone_t                 I4 (IndexDimension, 3): vertex, cell and
                                                   boundary-vertex sizes per direction
        ZoneType            ZoneType_t             C1: "Structured"
        GridCoordinates     GridCoordinates_t
          CoordinateX, Y[, Z]  DataArray_t         R8 (ni, nj[, nk]), i fastest
            DimensionalExponents  DimensionalExponents_t  R4: [0, 1, 0, 0, 0] (a length)
        FlowSolution        FlowSolution_t         (only with cell data)
          GridLocation      GridLocation_t         C1: "CellCenter"
          <name>            DataArray_t            R8 (ni-1, nj-1[, nk-1])
        ZoneBC              ZoneBC_t               (only with patches)
          <patch>[_<face>]  BC_t                   C1: "FamilySpecified" (the type is the Family's)
            PointRange      IndexRange_t           I4 (IndexDimension, 2): first and last vertex (1-based)
            FamilyName      FamilyName_t           C1: the patch name
      <patch>               Family_t               one per patch
        FamilyBC            FamilyBC_t             C1: the patch's BC type
        PatchType           Descriptor_t           C1: meshgen's patch type (wall, patch, symmetry, empty)

A patch covers one or more faces of the structured block; PointRange describes one rectangle, so
there is one BC_t per face, named after the patch (``<patch>_<face>`` when the patch has several
faces), and the BC_ts of one patch share its Family: the family is the patch, as ParaView's and
other CGNS readers group boundaries. Each BC_t is of type FamilySpecified and names its family;
the physical type (BCWall, BCInflow ...) is the family's FamilyBC: VTK's (ParaView's) CGNS reader
loads only BC_ts of type FamilySpecified, BCDirichlet or BCNeumann, and shows each as a block named
after its family. A multi-block mesh (``write_zones``) has one zone per block, the same families,
and a ZoneGridConnectivity of GridConnectivity1to1 records per zone.

A 3D mesh has IndexDimension = CellDimension = PhysicalDimension = 3, a 2D mesh 2 (x and y only).
meshgen's coordinates are in the geometry's own, unstated unit: hence the data class
NormalizedByUnknownDimensional, with the exponents saying that coordinates are lengths. cgnscheck
then has nothing to warn about, except "not a CGNS data-name identifier" for each cell-data array
whose name is not one of SIDS' (quality metrics are not).

CGNS/HDF5 mapping (what the CGNS library's ADFH layer reads and cgnscheck checks): every node is an
HDF5 group with the attributes ``name`` and ``label`` (scalar null-terminated strings of 33 bytes),
``type`` (3 bytes: MT, C1, I4, R4, R8, ...) and ``flags`` (int32 [1]); its data, if any, is the
dataset " data" (leading space) whose HDF5 shape is the CGNS shape reversed, so that its C-order
bytes are the Fortran-order array. The root group is the "HDF5 MotherNode" and also holds the
datasets " format" (float format of the data) and " hdf5version". Groups track link creation
order, since the library lists a node's children in that order.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats._cgns_nodes import (
    BASE_NAME,
    CGNS_VERSION,
    NAME_LENGTH,
    c_order,
    chars,
    check_name,
    child_with_label,
    children_with_label,
    file_base,
    fortran,
    new_node,
    node_data,
    node_label,
    node_name,
    node_text,
)
from meshgen.formats.metadata import METADATA_KEY
from meshgen.geometry import cube
from meshgen.geometry.grid import cell_connectivity, flat_points
from meshgen.geometry.patches import Patch, flow_role
from meshgen.run.inputs import MAX_DEFLATE_RATIO

__all__ = [
    "BASE_NAME",
    "CGNS_VERSION",
    "COORDINATE_NAMES",
    "LENGTH_EXPONENTS",
    "MultiZoneError",
    "NAME_LENGTH",
    "SOLUTION_NAME",
    "ZONE_BC_NAME",
    "ZONE_NAME",
    "bc_type",
    "check_patch_name",
    "read",
    "read_node_block",
    "read_node_components",
    "read_patches",
    "stream",
    "write",
    "write_cell_block",
    "write_node_block",
    "write_zone_bc",
    "zone_header",
]

COORDINATE_NAMES = ("CoordinateX", "CoordinateY", "CoordinateZ")
# Exponents of mass, length, time, temperature and angle.
LENGTH_EXPONENTS = np.array([0.0, 1.0, 0.0, 0.0, 0.0], dtype="<f4")
ZONE_NAME = "Zone"
SOLUTION_NAME = "FlowSolution"
ZONE_BC_NAME = "ZoneBC"


def write(path, X, cell_data, metadata, patches=()):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as one structured zone; ``cell_data``
    arrays (C order of the cells) as a cell-centred FlowSolution; ``metadata`` as a Descriptor;
    ``patches`` (``meshgen.geometry.patches.Patch``) as a ZoneBC with Families."""
    node_shape = X.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    with stream(path, node_shape, X.shape[-1], metadata, cell_names=list(cell_data), patches=patches) as zone:
        whole = tuple(slice(0, n) for n in node_shape)
        write_node_block(zone, X, whole)
        for name, values in cell_data.items():
            write_cell_block(zone, name, np.reshape(values, cell_shape), tuple(slice(0, n) for n in cell_shape))


@contextlib.contextmanager
def stream(path, node_shape, dim, metadata, cell_names=(), patches=()):
    """Open ``path`` with the whole tree of ``write`` (the ZoneBC of ``patches`` included) and its
    coordinate (and cell-data) arrays allocated but not filled; yield the zone's datasets for
    ``write_node_block`` and ``write_cell_block`` (HDF5 hyperslab writes), so a mesh larger than
    memory is written block by block. One layout for both: ``write`` is this with one block."""
    import h5py

    for name in cell_names:
        check_name(name, "cell data")
    node_shape = tuple(int(n) for n in node_shape)
    cell_shape = tuple(n - 1 for n in node_shape)

    # libver (earliest, v108): files the HDF5 1.8 and 1.10 libraries of CGNS builds can open.
    with h5py.File(path, "w", libver=("earliest", "v108"), track_order=True) as root:
        base = file_base(root, dim, metadata)

        # Zone_t data is int[3][IndexDimension] in C terms: rows vertex, cell, boundary-vertex sizes.
        sizes = np.array([node_shape, cell_shape, [0] * dim], dtype="<i4")
        zone = new_node(base, ZONE_NAME, "Zone_t", sizes)
        new_node(zone, "ZoneType", "ZoneType_t", chars("Structured"))
        coordinates = new_node(zone, "GridCoordinates", "GridCoordinates_t")
        datasets = {"coordinates": [], "cells": {}}
        for axis in range(dim):
            coordinate = new_node(coordinates, COORDINATE_NAMES[axis], "DataArray_t", shape=node_shape[::-1])
            new_node(coordinate, "DimensionalExponents", "DimensionalExponents_t", LENGTH_EXPONENTS)
            datasets["coordinates"].append(coordinate[" data"])
        if cell_names:
            solution = new_node(zone, SOLUTION_NAME, "FlowSolution_t")
            new_node(solution, "GridLocation", "GridLocation_t", chars("CellCenter"))
            for name in cell_names:
                datasets["cells"][name] = new_node(solution, name, "DataArray_t", shape=cell_shape[::-1])[" data"]
        if patches:
            write_zone_bc(base, zone, node_shape, patches)
        yield datasets


def bc_type(patch) -> str:
    """The CGNS BCType of a patch: walls and symmetry planes by type; a ``patch`` is BCInflow or
    BCOutflow when its name says inlet/inflow or outlet/outflow, else BCGeneral (so is ``empty``)."""
    if patch.type == "wall":
        return "BCWall"
    if patch.type == "symmetry":
        return "BCSymmetryPlane"
    return {"inflow": "BCInflow", "outflow": "BCOutflow"}.get(flow_role(patch), "BCGeneral")


def write_zone_bc(base, zone, node_shape, patches) -> None:
    """The ZoneBC of ``zone`` (one BC_t with a PointRange per patch face) and a Family_t per patch
    under ``base``. ``node_shape``: the zone's vertex counts (ni, nj[, nk])."""
    dim = len(node_shape)
    zone_bc = new_node(zone, ZONE_BC_NAME, "ZoneBC_t")
    for patch in patches:
        kind = bc_type(patch)
        for face_name in patch.faces:
            face = cube.face_named(face_name, dim)
            first = [1] * dim
            last = list(node_shape)
            first[face.axis] = last[face.axis] = node_shape[face.axis] if face.side else 1
            name = patch.name if len(patch.faces) == 1 else f"{patch.name}_{face_name}"
            bc = new_node(zone_bc, name, "BC_t", chars("FamilySpecified"))
            new_node(bc, "PointRange", "IndexRange_t", np.array([first, last], dtype="<i4"))
            new_node(bc, "FamilyName", "FamilyName_t", chars(patch.name))
        if patch.name not in base:  # one Family per patch, however many zones share it
            family = new_node(base, patch.name, "Family_t")
            new_node(family, "FamilyBC", "FamilyBC_t", chars(kind))
            new_node(family, "PatchType", "Descriptor_t", chars(patch.type))


def check_patch_name(name: str) -> None:
    """Patch names become node names (up to 32 characters; the ``_<face>`` suffix included)."""
    if len(name) + len("_zeta0") > NAME_LENGTH:
        raise FormatError(f"patch name '{name}' is too long for CGNS (at most {NAME_LENGTH - len('_zeta0')} characters)")
    check_name(name, "patch")


def read_patches(path) -> list:
    """The patches of a .cgns file: its first zone's BC_ts grouped by FamilyName (or BC name), each
    PointRange matched to the cube face it covers; the type from the Family's PatchType, else from
    the BC type."""
    import h5py

    types = {"BCWall": "wall", "BCSymmetryPlane": "symmetry"}
    faces_of, type_of = {}, {}
    with h5py.File(path, "r") as root:
        base = child_with_label(root, "CGNSBase_t", path)
        zone = child_with_label(base, "Zone_t", path)
        node_shape = tuple(int(n) for n in node_data(zone)[0])
        dim = len(node_shape)
        families = {node_name(f): f for f in children_with_label(base, "Family_t")}
        for zone_bc in children_with_label(zone, "ZoneBC_t"):
            for bc in children_with_label(zone_bc, "BC_t"):
                family_nodes = children_with_label(bc, "FamilyName_t")
                name = node_text(family_nodes[0]) if family_nodes else node_name(bc)
                first, last = np.asarray(node_data(child_with_label(bc, "IndexRange_t", path)), dtype=int)
                face = _face_of_range(first, last, node_shape, cube.faces(dim))
                if face is None:
                    raise FormatError(f"{path}: BC '{node_name(bc)}' does not cover a whole face of the zone")
                descriptor = families.get(name, {}).get("PatchType") if name in families else None
                kind = node_text(descriptor) if descriptor is not None else types.get(node_text(bc), "patch")
                faces_of.setdefault(name, []).append(face.name)
                type_of[name] = kind
    return [Patch(name, type_of[name], tuple(faces)) for name, faces in faces_of.items()]


def _face_of_range(first, last, node_shape, faces):
    for face in faces:
        expected_first = [1] * len(node_shape)
        expected_last = list(node_shape)
        expected_first[face.axis] = expected_last[face.axis] = node_shape[face.axis] if face.side else 1
        if list(first) == expected_first and list(last) == expected_last:
            return face
    return None


def write_node_block(zone: dict, X_block: np.ndarray, block) -> None:
    """Write the nodes ``block`` (one slice per index axis i, j[, k]) of the zone that ``stream``
    opened from ``X_block`` (block shape + (dim,)): one hyperslab per coordinate."""
    hyperslab = tuple(block[::-1])
    for axis, dataset in enumerate(zone["coordinates"]):
        dataset[hyperslab] = fortran(X_block[..., axis])


def write_cell_block(zone: dict, name: str, values: np.ndarray, block) -> None:
    """Write cell-data array ``name`` on the cells ``block`` (slices per axis) from ``values``."""
    zone["cells"][name][tuple(block[::-1])] = fortran(values)


def read(path):
    """Read the first structured zone of the first base as a ``meshio.Mesh``: hexahedron (quad)
    cells in the C order of the cells, points in the C order of the nodes padded to 3 columns,
    cell-centred (vertex) solution arrays as cell (point) data, meshgen's metadata in field data."""
    import h5py
    import meshio

    if zone_count(path) > 1:
        return read_merged(path)
    with h5py.File(path, "r") as root:
        base, zone, node_shape = _structured_zone(root, path)
        cell_shape = tuple(n - 1 for n in node_shape)
        X = np.stack([c_order(array[()], node_shape, path) for array in _coordinate_arrays(zone, len(node_shape), path)], axis=-1)

        point_data, cell_data = {}, {}
        for solution in children_with_label(zone, "FlowSolution_t"):
            location = node_text(solution["GridLocation"]) if "GridLocation" in solution else "Vertex"
            if location not in ("Vertex", "CellCenter"):
                continue
            target, shape = (cell_data, cell_shape) if location == "CellCenter" else (point_data, node_shape)
            for array in children_with_label(solution, "DataArray_t"):
                target[node_name(array)] = c_order(node_data(array), shape, path).reshape(-1)

        field_data = {}
        if METADATA_KEY in base and node_label(base[METADATA_KEY]) == "Descriptor_t":
            field_data[METADATA_KEY] = np.asarray(node_data(base[METADATA_KEY])).view(np.uint8)

    cell_type = "hexahedron" if len(node_shape) == 3 else "quad"
    return meshio.Mesh(
        flat_points(X),
        [(cell_type, cell_connectivity(node_shape))],
        point_data=point_data,
        cell_data={name: [values] for name, values in cell_data.items()},
        field_data=field_data,
    )


# --- reading in blocks (meshes larger than memory) ----------------------------------------


class MultiZoneError(FormatError):
    """A file of several zones given to a reader of one zone (``_single_zone``)."""


def zone_header(path) -> tuple[tuple[int, ...], dict]:
    """(node shape (ni, nj[, nk]), meshgen's metadata dict or {}) of the file's structured zone,
    without reading the coordinates; MultiZoneError for a file of several zones (the block-by-block
    readers read one)."""
    import h5py

    try:
        root = h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(f"could not read {path}: {exc}") from None
    with root:
        base, _, node_shape = _structured_zone(root, path)
        _single_zone(base, path)
        metadata = {}
        if METADATA_KEY in base and node_label(base[METADATA_KEY]) == "Descriptor_t":
            try:
                metadata = json.loads(np.asarray(node_data(base[METADATA_KEY])).view(np.uint8).tobytes().decode())
            except (ValueError, UnicodeDecodeError):
                metadata = {}
    return node_shape, metadata if isinstance(metadata, dict) else {}


def read_node_block(path, block) -> np.ndarray:
    """The nodes ``block`` (one slice per index axis) of the first zone's coordinates: an array of
    the block's shape + (dim,), C order (i, j[, k]), float64; one hyperslab read per coordinate."""
    import h5py

    with h5py.File(path, "r") as root:
        hyperslab = tuple(block[::-1])
        X = np.empty(tuple(s.stop - s.start for s in block) + (len(block),))
        for axis, array in enumerate(_block_coordinates(root, path, block)):
            X[..., axis] = array[hyperslab].T
    return X


def read_node_components(path, block, out=None) -> np.ndarray:
    """The nodes ``block`` (one slice per index axis) of the first zone's coordinates by component
    in the file's order, read without a transpose: an array (dim, block shape reversed), float64,
    coordinate d of node (i, j[, k]) at [d, (k,) j, i]. One hyperslab read per coordinate, into
    ``out`` when it is a C-contiguous float64 array of that shape (a buffer reused from block to
    block), else into a new array."""
    import h5py

    shape = (len(block),) + tuple(s.stop - s.start for s in block[::-1])
    if out is None or out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        out = np.empty(shape)
    with h5py.File(path, "r") as root:
        hyperslab = tuple(block[::-1])
        for axis, array in enumerate(_block_coordinates(root, path, block)):
            array.read_direct(out[axis], source_sel=hyperslab)
    return out


# The coordinate datasets of a file's first structured zone, by version of the file (path, device,
# inode, size, modification time): finding and verifying them walks the tree and reads each node's
# label, several milliseconds, most of a block's read when a file is read block by block.
_ZONES: dict = {}
_ZONES_KEPT = 8
_ZONES_LOCK = threading.Lock()  # block reads run on several threads


def _block_coordinates(root, path, block) -> list:
    """The coordinate datasets of the first zone of the open file ``root`` (``_structured_zone``
    and ``_coordinate_arrays``, found once per version of the file), with ``block`` checked to lie in
    the zone."""
    status = os.stat(path)
    key = (os.fspath(path), status.st_dev, status.st_ino, status.st_size, status.st_mtime_ns)
    found = _ZONES.get(key)
    if found is None:
        _, zone, node_shape = _structured_zone(root, path)
        found = (node_shape, [array.name for array in _coordinate_arrays(zone, len(node_shape), path)])
        with _ZONES_LOCK:
            while len(_ZONES) >= _ZONES_KEPT:
                _ZONES.pop(next(iter(_ZONES)))
            _ZONES[key] = found
    node_shape, names = found
    if len(block) != len(node_shape) or any(not 0 <= s.start <= s.stop <= n for s, n in zip(block, node_shape)):
        raise FormatError(f"{path}: block {block} is not in the zone's {node_shape} nodes")
    return [root[name] for name in names]


def _structured_zone(root, path):
    """(base, zone, node shape) of the first zone of the first base; FormatError unless structured."""
    base = child_with_label(root, "CGNSBase_t", path)
    zone = child_with_label(base, "Zone_t", path)
    return base, zone, _zone_shape(zone, path)


def _zone_shape(zone, path) -> tuple[int, ...]:
    """The node shape of ``zone``, checked before anything is allocated: a zone typed
    ``Structured`` (an ``Unstructured`` zone's header means something else), whose header the
    file's coordinate arrays bear out (``_checked_node_shape``). Every reader of a zone calls it."""
    zone_type = node_text(zone["ZoneType"]) if "ZoneType" in zone else ""
    if zone_type != "Structured":
        raise FormatError(f"{path}: zone '{node_name(zone)}' is {zone_type or 'untyped'}, meshgen reads structured zones")
    return _checked_node_shape(zone, path)


def _single_zone(base, path) -> None:
    """MultiZoneError when the base holds several zones: a reader of one zone (block by block,
    ``zone_header``) would measure the first block only, a wrong answer given as the whole."""
    count = len(children_with_label(base, "Zone_t"))
    if count > 1:
        raise MultiZoneError(
            f"{path} holds {count} zones (a block set): the block-by-block path (--chunked) reads a single zone; "
            "evaluate it without --chunked (every zone, in memory; --per-block for each zone)"
        )


def _checked_node_shape(zone, path) -> tuple[int, ...]:
    """The zone's node shape, verified against what the file holds before anything is allocated:
    2 or 3 counts of at least 2, coordinate arrays of that shape, and the bytes stored for them
    (``_stored_too_little``, compressed arrays included). A header is data: it may claim more nodes than the file carries."""
    sizes = np.asarray(node_data(zone))
    if sizes.ndim != 2 or sizes.shape[0] < 1 or sizes.shape[1] not in (2, 3) or sizes.dtype.kind not in "iu":
        raise FormatError(f"{path}: zone '{node_name(zone)}' has a malformed size header (shape {sizes.shape})")
    node_shape = tuple(int(n) for n in sizes[0])
    if min(node_shape) < 2:
        raise FormatError(f"{path}: zone '{node_name(zone)}' claims {node_shape} nodes: each count must be at least 2")
    for array in _coordinate_arrays(zone, len(node_shape), path):
        if array.shape != node_shape[::-1]:
            raise FormatError(
                f"{path}: zone '{node_name(zone)}' claims {node_shape} nodes but a coordinate array holds {array.shape[::-1]}"
            )
        claimed = int(np.prod(node_shape, dtype=np.int64)) * array.dtype.itemsize
        problem = _stored_too_little(array, claimed)
        if problem:
            raise FormatError(
                f"{path}: zone '{node_name(zone)}' claims {node_shape} nodes ({claimed / 1e9:.3g} GB of coordinates) "
                f"but {problem}: truncated or not a mesh"
            )
    return node_shape


def _stored_too_little(array, claimed: int) -> str | None:
    """Why the HDF5 dataset ``array`` cannot hold the ``claimed`` bytes it declares, or None: an
    uncompressed one stores fewer bytes; a compressed one stores fewer than ``claimed /
    MAX_DEFLATE_RATIO`` (more than deflate can inflate) or leaves chunks unwritten (HDF5 reads
    them as fill values: a header of 1001^3 nodes over no data at all)."""
    stored = array.id.get_storage_size()
    if array.id.get_create_plist().get_nfilters() == 0:
        if stored < claimed:
            return f"the file stores {stored / 1e9:.3g} GB of them"
        return None
    if stored * MAX_DEFLATE_RATIO < claimed:
        return f"the file stores only {stored} compressed bytes of them (deflate inflates a byte to at most {MAX_DEFLATE_RATIO})"
    if array.chunks:
        expected = int(np.prod([-(-n // c) for n, c in zip(array.shape, array.chunks)], dtype=np.int64))
        written = array.id.get_num_chunks()
        if written < expected:
            return f"the file stores {written} of their {expected} compressed chunks"
    return None


def _coordinate_arrays(zone, dim: int, path) -> list:
    """The HDF5 datasets of CoordinateX, Y[, Z] of ``zone`` (not read); FormatError if one is missing."""
    grid = child_with_label(zone, "GridCoordinates_t", path)
    names = COORDINATE_NAMES[:dim]
    missing = [name for name in names if name not in grid]
    if missing:
        raise FormatError(f"{path}: no {', '.join(missing)} in {grid.name} (only Cartesian coordinates are read)")
    return [grid[name][" data"] for name in names]


# --- several zones (block sets) ---------------------------------------------------------------


def write_zones(path, zones, metadata, connections) -> None:
    """Write one structured zone per block: ``zones`` a list of (zone name, node array X, patches
    of that zone), ``connections`` per zone a list of (record name, donor zone name, PointRange,
    PointRangeDonor, Transform[, translation]), ranges as (2, IndexDimension) 1-based vertex
    indices: each becomes a GridConnectivity1to1 in the zone's ZoneGridConnectivity; one with a
    translation (dim,) (from this zone's face to the donor's) is periodic: its
    GridConnectivityProperty/Periodic holds it (no rotation)."""
    import h5py

    dim = zones[0][1].shape[-1]
    with h5py.File(path, "w", libver=("earliest", "v108"), track_order=True) as root:
        base = file_base(root, dim, metadata)
        for (name, X, patches), records in zip(zones, connections):
            check_name(name, "zone")
            node_shape = X.shape[:-1]
            sizes = np.array([node_shape, [n - 1 for n in node_shape], [0] * dim], dtype="<i4")
            zone = new_node(base, name, "Zone_t", sizes)
            new_node(zone, "ZoneType", "ZoneType_t", chars("Structured"))
            coordinates = new_node(zone, "GridCoordinates", "GridCoordinates_t")
            for axis in range(dim):
                coordinate = new_node(coordinates, COORDINATE_NAMES[axis], "DataArray_t", fortran(X[..., axis]))
                new_node(coordinate, "DimensionalExponents", "DimensionalExponents_t", LENGTH_EXPONENTS)
            if patches:
                write_zone_bc(base, zone, node_shape, patches)
            if records:
                connectivity = new_node(zone, "ZoneGridConnectivity", "ZoneGridConnectivity_t")
                for record, donor, point_range, donor_range, transform, *translation in records:
                    link = new_node(connectivity, record, "GridConnectivity1to1_t", chars(donor))
                    new_node(link, "Transform", '"int[IndexDimension]"', np.asarray(transform, dtype="<i4"))
                    new_node(link, "PointRange", "IndexRange_t", np.asarray(point_range, dtype="<i4"))
                    new_node(link, "PointRangeDonor", "IndexRange_t", np.asarray(donor_range, dtype="<i4"))
                    if translation:
                        periodic = new_node(
                            new_node(link, "GridConnectivityProperty", "GridConnectivityProperty_t"), "Periodic", "Periodic_t"
                        )
                        angle = np.array([0.0, 0.0, 0.0, 0.0, 1.0], dtype="<f4")
                        for key, value, exponents in (
                            ("RotationCenter", 0.0, LENGTH_EXPONENTS),
                            ("RotationAngle", 0.0, angle),
                            ("Translation", translation[0], LENGTH_EXPONENTS),
                        ):
                            data = np.broadcast_to(np.asarray(value, dtype="<f4"), (dim,)).copy()
                            new_node(
                                new_node(periodic, key, "DataArray_t", data),
                                "DimensionalExponents",
                                "DimensionalExponents_t",
                                exponents,
                            )


def read_zones(path) -> list[dict]:
    """Every structured zone of the first base: {"name", "X" (C-order node array), "connections":
    [{"name", "donor", "range", "donor_range", "transform"}] (ranges 1-based, (2, dim))}."""
    import h5py

    zones = []
    with h5py.File(path, "r") as root:
        base = child_with_label(root, "CGNSBase_t", path)
        found = children_with_label(base, "Zone_t")
        shapes = [_zone_shape(zone, path) for zone in found]  # every zone's header, before any is read
        for zone, node_shape in zip(found, shapes):
            X = np.stack([c_order(a[()], node_shape, path) for a in _coordinate_arrays(zone, len(node_shape), path)], axis=-1)
            connections = []
            for connectivity in children_with_label(zone, "ZoneGridConnectivity_t"):
                for link in children_with_label(connectivity, "GridConnectivity1to1_t"):
                    connections.append(
                        {
                            "name": node_name(link),
                            "donor": node_text(link),
                            "range": np.asarray(node_data(link["PointRange"]), dtype=int),
                            "donor_range": np.asarray(node_data(link["PointRangeDonor"]), dtype=int),
                            "transform": tuple(int(t) for t in node_data(link["Transform"])),
                        }
                    )
            zones.append({"name": node_name(zone), "X": X, "connections": connections})
    return zones


def zone_count(path) -> int:
    """How many zones the first base holds."""
    import h5py

    try:
        root = h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(f"could not read {path}: {exc}") from None
    with root:
        return len(children_with_label(child_with_label(root, "CGNSBase_t", path), "Zone_t"))


def read_merged(path):
    """All zones of a multi-zone file as one ``meshio.Mesh``: nodes that coincide exactly (the
    interfaces of a block set) merged, hexahedra (quads) zone after zone, cell data ``block``
    (the zone's number), meshgen's metadata in field data."""
    import h5py
    import meshio

    zones = read_zones(path)
    dim = zones[0]["X"].shape[-1]
    points = np.concatenate([zone["X"].reshape(-1, dim) for zone in zones])
    unique, inverse = np.unique(points, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    cells, owner, offset = [], [], 0
    for number, zone in enumerate(zones):
        local = cell_connectivity(zone["X"].shape[:-1])
        cells.append(inverse[offset + local])
        owner.append(np.full(len(local), float(number)))
        offset += zone["X"][..., 0].size
    field_data = {}
    with h5py.File(path, "r") as root:
        base = child_with_label(root, "CGNSBase_t", path)
        if METADATA_KEY in base and node_label(base[METADATA_KEY]) == "Descriptor_t":
            field_data[METADATA_KEY] = np.asarray(node_data(base[METADATA_KEY])).view(np.uint8)
    padded = np.hstack([unique, np.zeros((len(unique), 3 - dim))]) if dim < 3 else unique
    cell_type = "hexahedron" if dim == 3 else "quad"
    return meshio.Mesh(
        padded, [(cell_type, np.concatenate(cells))], cell_data={"block": [np.concatenate(owner)]}, field_data=field_data
    )
