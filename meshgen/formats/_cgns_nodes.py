"""The CGNS/HDF5 node layout that every CGNS file of meshgen uses (design notes §8): creating a
node (its name, label and data-type attributes and its `` data`` dataset), reading them back, and
the root node and the one ``CGNSBase_t`` of a new file. ``meshgen.formats._cgns`` builds zones,
patches and 1-to-1 connectivity from these."""

from __future__ import annotations

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats.metadata import METADATA_KEY, metadata_json

__all__ = [
    "BASE_NAME",
    "CGNS_VERSION",
    "DATA_TYPES",
    "NAME_LENGTH",
    "attribute_text",
    "c_order",
    "check_name",
    "chars",
    "child_with_label",
    "children_with_label",
    "file_base",
    "fortran",
    "new_node",
    "node_data",
    "node_label",
    "node_name",
    "node_text",
    "root_string",
    "set_node_attributes",
    "string_attribute",
]

CGNS_VERSION = 3.4  # the layout below is the one CGNS 3.x and 4.x libraries both read and write
NAME_LENGTH = 32  # longest CGNS node name or label
BASE_NAME = "Base"


# --- writing nodes -------------------------------------------------------------------------


def new_node(parent, name: str, label: str, data: np.ndarray | None = None, shape=None):
    """Create the CGNS node ``name`` under ``parent`` (an h5py group); ``data`` in its HDF5 layout,
    or, with ``shape`` (HDF5 order), an unfilled float64 array to be written in blocks."""
    group = parent.create_group(name, track_order=True)
    if shape is not None:
        data_type = "R8"
    else:
        data_type = "MT" if data is None else DATA_TYPES[np.dtype(data.dtype).str]
    set_node_attributes(group, name, label, data_type)
    if shape is not None:
        group.create_dataset(" data", shape=tuple(shape), dtype="<f8")
    elif data is not None:
        group.create_dataset(" data", data=data)
    return group


# NumPy dtype (explicitly little-endian, as " format" says) -> CGNS data type.
DATA_TYPES = {"|i1": "C1", "<i4": "I4", "<i8": "I8", "<f4": "R4", "<f8": "R8"}


def set_node_attributes(group, name: str, label: str, data_type: str, flags: bool = True) -> None:
    string_attribute(group, "name", name, NAME_LENGTH + 1)
    string_attribute(group, "label", label, NAME_LENGTH + 1)
    string_attribute(group, "type", data_type, 3)
    if flags:
        group.attrs.create("flags", np.array([1], dtype="<i4"))


def string_attribute(group, name: str, value: str, size: int) -> None:
    """Scalar fixed-size C string attribute (H5T_C_S1, null-terminated), as the CGNS library
    writes them; h5py's own fixed strings are null-padded."""
    import h5py

    string_type = h5py.h5t.C_S1.copy()
    string_type.set_size(size)
    string_type.set_strpad(h5py.h5t.STR_NULLTERM)
    attribute = h5py.h5a.create(group.id, name.encode(), string_type, h5py.h5s.create(h5py.h5s.SCALAR))
    attribute.write(np.array(value.encode("ascii"), dtype=f"S{size}"), mtype=string_type)


def root_string(root, name: str, value: str, size: int) -> None:
    """A character dataset of the root node, zero-padded to ``size`` bytes."""
    text = value.encode("ascii")[: size - 1]
    root.create_dataset(name, data=np.frombuffer(text.ljust(size, b"\0"), dtype=np.int8))


def chars(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("ascii"), dtype=np.int8)


def fortran(values: np.ndarray) -> np.ndarray:
    """A C-order (i, j[, k]) array as the HDF5 dataset of a CGNS array: reversed shape, float64 LE."""
    return np.ascontiguousarray(np.asarray(values).T, dtype="<f8")


def check_name(name: str, what: str) -> None:
    if not name or len(name) > NAME_LENGTH or "/" in name or name != name.strip() or not name.isascii():
        raise FormatError(
            f"{what} name '{name}' is not a valid CGNS node name (1 to {NAME_LENGTH} ASCII characters, "
            "no '/', no leading or trailing spaces)"
        )


# --- reading nodes -------------------------------------------------------------------------


def attribute_text(group, name: str) -> str:
    value = group.attrs.get(name, b"")
    return (value.tobytes() if isinstance(value, np.ndarray) else bytes(value)).split(b"\0")[0].decode().strip()


def node_name(group) -> str:
    return attribute_text(group, "name")


def node_label(group) -> str:
    return attribute_text(group, "label")


def node_data(group) -> np.ndarray:
    return group[" data"][()]


def node_text(group) -> str:
    return np.asarray(node_data(group)).view(np.uint8).tobytes().split(b"\0")[0].decode().strip()


def children_with_label(group, label: str) -> list:
    import h5py

    return [
        child
        for key, child in group.items()
        if not key.startswith(" ") and isinstance(child, h5py.Group) and node_label(child) == label
    ]


def child_with_label(group, label: str, path):
    children = children_with_label(group, label)
    if not children:
        raise FormatError(f"{path}: no {label} node under {group.name}")
    return children[0]


def c_order(data: np.ndarray, shape: tuple, path) -> np.ndarray:
    """HDF5 dataset of a CGNS array (reversed shape) -> float64 array of C-order ``shape``."""
    array = np.asarray(data, dtype=float).T
    if array.shape != shape:
        raise FormatError(f"{path}: array of shape {array.shape} where {shape} was expected (rind planes are not read)")
    return array


def file_base(root, dim: int, metadata: dict | None):
    """The root node attributes, the library version and the one CGNSBase_t of a new file (with
    ``metadata`` as a Descriptor_t when given). Returns the base node."""
    import h5py

    set_node_attributes(root, "HDF5 MotherNode", "Root Node of HDF5 File", "MT", flags=False)
    root_string(root, " format", "IEEE_LITTLE_32", len("IEEE_LITTLE_32") + 1)
    root_string(root, " hdf5version", f"HDF5 Version {h5py.version.hdf5_version}", NAME_LENGTH + 1)
    new_node(root, "CGNSLibraryVersion", "CGNSLibraryVersion_t", np.array([CGNS_VERSION], dtype="<f4"))
    base = new_node(root, BASE_NAME, "CGNSBase_t", np.array([dim, dim], dtype="<i4"))
    new_node(base, "DataClass", "DataClass_t", chars("NormalizedByUnknownDimensional"))
    if metadata:
        new_node(base, METADATA_KEY, "Descriptor_t", chars(metadata_json(metadata)))
    return base
