"""Writing block-set meshes (a ``BlockSet`` and its node arrays, one per block): ``.cgns`` one
structured zone per block with 1-to-1 connectivity, an OpenFOAM case with the interfaces as
internal faces, one merged unstructured mesh for ``.vtu`` (the single block's writer, metadata
included), for the formats meshio writes (``.vtk``, ``.xdmf``) and for ``.su2`` (a marker per
patch) and ``.msh`` (a physical group per patch), the boundary elements outward (2D: the domain
on their left).
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats import check_output_path, format_for
from meshgen.formats._cgns import MultiZoneError, read_zones, write_zones, zone_count
from meshgen.formats._gmsh import write_elements as write_msh_elements
from meshgen.formats._openfoam import EXTRUDED_PATCH, check_extrusion_patch, write_case
from meshgen.formats._polymesh import extrude_quads, write_poly_mesh
from meshgen.formats._structured import boundary_elements, orientation
from meshgen.formats._su2 import write_elements as write_su2_elements
from meshgen.formats._vtm import check_target as check_vtm_target
from meshgen.formats._vtm import write_blocks_vtm
from meshgen.formats._vtu import write_cells as write_vtu_cells
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry import cube
from meshgen.geometry.block_nodes import face_index, global_numbering, merged_mesh
from meshgen.geometry.blocks import BlockSet, Interface, block_patches, connectivity_records
from meshgen.geometry.cyclic import CYCLIC, matching_order, pair_map
from meshgen.geometry.cyclic import TOLERANCE as CYCLIC_TOLERANCE
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import Patch, as_records
from meshgen.run.atomic import atomic_write, check_output_file

__all__ = [
    "MERGED_FORMATS",
    "SOLVER_FORMATS",
    "MultiZoneError",
    "check_block_output",
    "merged_boundary",
    "patch_faces",
    "periodic_records",
    "read_zones",
    "write_blocks",
    "zone_count",
]

MERGED_FORMATS = ("vtu", "vtk", "xdmf")  # one merged unstructured mesh, written by meshio
SOLVER_FORMATS = ("su2", "gmsh")  # .su2 and .msh: one merged mesh with its patches' boundary elements


def check_block_output(path, format_name: str | None, block_set: BlockSet) -> Path:
    """The path to write, checked before any work (FormatError for a format that takes no block set)."""

    if format_name is None and Path(path).suffix.lower() == ".vtm":  # a .vts per block and the .vtm listing them
        path = check_output_file(path, "mesh.vtm")
        check_vtm_target(path)  # its pieces folder must be its own: never a folder of the user's files
        return path
    fmt = format_for(path, format_name)
    if fmt.name not in ("cgns", "openfoam", *MERGED_FORMATS, *SOLVER_FORMATS):
        raise FormatError(
            f"{fmt.name} does not take multi-block meshes ('{block_set.name}' has {len(block_set.names)} blocks); "
            f"write .cgns (a zone per block), --format openfoam, .vtm (a .vts per block) or "
            f".{', .'.join(MERGED_FORMATS)}, .su2, .msh (one merged mesh)"
        )
    if block_set.cyclic and fmt.name not in ("cgns", "openfoam", *MERGED_FORMATS):
        raise FormatError(
            f"{fmt.name} does not take cyclic patches ('{block_set.name}' pairs {block_set.cyclic[0][0]} with "
            f"{block_set.cyclic[0][1]}): write .cgns, --format openfoam (cyclic patches) or .{', .'.join(MERGED_FORMATS)}"
        )
    rotational = [pair[:2] for pair in block_set.cyclic if len(pair) > 3 and pair[3] is not None]
    if rotational and fmt.name == "cgns":
        raise FormatError(
            f"cgns: the cyclic pair '{rotational[0][0]}' and '{rotational[0][1]}' is rotational: meshgen writes "
            "translational periodic connectivity only: write --format openfoam"
        )
    path = check_output_path(path, fmt.name, block_set.dim)
    if fmt.name in ("cgns", "openfoam", *SOLVER_FORMATS):
        from importlib import import_module

        module = import_module(fmt.module)
        for patches in block_patches(block_set):
            for patch in patches:
                module.check_patch_name(patch.name)
    return path


def patch_faces(block_set: BlockSet) -> list[tuple[str, str, np.ndarray]]:
    """The merged mesh's boundary patches: (name, type, elements) with elements the global node
    numbers of each boundary face, (F, 4) quads in 3D, (E, 2) edges in 2D (any orientation)."""

    numbering, _ = global_numbering(block_set)
    found: dict[str, list] = {}
    kinds = {}
    for (block, face_name), (name, kind) in block_set.patches.items():
        face = cube.face_named(face_name, block_set.dim)
        ids = numbering[block][face.node_index]
        local = cell_connectivity(ids.shape)  # the face's own cells: quads (3D) or segments (2D)
        if block_set.dim == 3:
            elements = ids.reshape(-1)[local]
        else:
            elements = np.stack([ids[:-1], ids[1:]], axis=1)
        found.setdefault(name, []).append(elements)
        kinds[name] = kind
    return [(name, kinds[name], np.concatenate(parts)) for name, parts in found.items()]


def merged_boundary(block_set: BlockSet, Xs) -> tuple[list[Patch], list[np.ndarray]]:
    """The merged mesh's patches (faces named ``block.face``) and, per patch, its boundary
    elements in global node numbers: (F, 4) quads with outward normals (3D), (E, 2) segments with
    the domain on their left (2D)."""

    numbering, _ = global_numbering(block_set)
    faces_of: dict[str, list[str]] = {}
    kinds, parts = {}, {}
    for (block, face_name), (name, kind) in block_set.patches.items():
        positive = orientation(Xs[block]) > 0
        local = boundary_elements(numbering[block].shape, face_name, positive)
        parts.setdefault(name, []).append(numbering[block].reshape(-1)[local])
        faces_of.setdefault(name, []).append(f"{block_set.names[block]}.{face_name}")
        kinds[name] = kind
    patches = [Patch(name, kinds[name], tuple(faces)) for name, faces in faces_of.items()]
    return patches, [np.concatenate(parts[p.name]) for p in patches]


def write_blocks(path, block_set: BlockSet, Xs, metadata: dict | None = None, format_name: str | None = None) -> Path:
    """Write the block meshes ``Xs`` to ``path`` (format from the extension, or ``format_name``),
    atomically. Returns the path written (an OpenFOAM case: its folder)."""

    path = check_block_output(path, format_name, block_set)
    metadata = dict(metadata or {})
    metadata_json(metadata)
    if format_name is None and path.suffix.lower() == ".vtm":
        return write_blocks_vtm(path, list(zip(block_set.names, Xs, block_patches(block_set, interfaces=True))), metadata)
    fmt = format_for(path, format_name)
    if fmt.name == "cgns":
        zones = [
            (name, X, [p for p in patches if p.type != CYCLIC])  # cyclic faces: periodic connectivity, not BCs
            for name, X, patches in zip(block_set.names, Xs, block_patches(block_set))
        ]
        records = connectivity_records(block_set)
        for block, periodic in enumerate(periodic_records(block_set, Xs)):
            records[block] += periodic
        with atomic_write(path, FormatError) as temporary:
            write_zones(temporary, zones, metadata, records)
        return path
    if fmt.name == "openfoam":
        _write_openfoam(path, block_set, Xs, metadata)
        return path
    if fmt.name in SOLVER_FORMATS:
        points, cells, _ = merged_mesh(block_set, Xs)
        patches, elements = merged_boundary(block_set, Xs)
        with atomic_write(path, FormatError) as temporary:
            if fmt.name == "su2":
                write_su2_elements(
                    temporary, points, cells, list(zip([p.name for p in patches], elements)), metadata, as_records(patches)
                )
            else:
                entities = list(enumerate(elements))
                write_msh_elements(temporary, points, cells, [p.name for p in patches], entities, metadata, as_records(patches))
        return path
    import meshio

    points, cells, owner = merged_mesh(block_set, Xs)
    padded = np.hstack([points, np.zeros((len(points), 3 - block_set.dim))]) if block_set.dim == 2 else points
    if fmt.name == "vtu":  # the single block's writer: its compression, and meshgen's metadata as field data
        with atomic_write(path, FormatError) as temporary:
            write_vtu_cells(temporary, padded, cells, block_set.dim, {"block": owner.astype(float)}, metadata)
        return path
    cell_type = "hexahedron" if block_set.dim == 3 else "quad"

    field_data = {METADATA_KEY: np.frombuffer(metadata_json(metadata).encode(), dtype=np.uint8).copy()} if metadata else {}
    mesh = meshio.Mesh(padded, [(cell_type, cells)], cell_data={"block": [owner.astype(float)]}, field_data=field_data)
    with atomic_write(path, FormatError) as temporary:
        meshio.write(temporary, mesh, file_format=fmt.name if fmt.name != "vtk" else "vtk")
    return path


def periodic_records(block_set: BlockSet, Xs) -> list[list[tuple]]:
    """Per block, the CGNS 1-to-1 records of its cyclic faces (``connectivity_records``' with the
    translation to the donor's face appended): each face of a pair's first patch joined to the
    face of its second patch that it matches node by node under the separation, the Transform the
    one whose node map does; FormatError when a face has no such partner (a side split into
    block faces differently from the other's)."""
    dim, shapes = block_set.dim, block_set.node_shapes
    periodic = []
    for pair in block_set.cyclic:
        a, b = pair[:2]
        if len(pair) > 3 and pair[3] is not None:
            raise FormatError(
                f"cgns: the cyclic pair '{a}' and '{b}' is rotational: meshgen writes translational periodic "
                "connectivity only: write --format openfoam"
            )
        separation = pair[2]
        sides = [[key for key, (name, _) in block_set.patches.items() if name == patch] for patch in (a, b)]
        for block, face_name in sides[0]:
            face = cube.face_named(face_name, dim)
            found = None
            for donor, donor_name in sides[1]:
                other = cube.face_named(donor_name, dim)
                for permutation in itertools.permutations(other.tangent_axes):
                    if [shapes[block][t] for t in face.tangent_axes] != [shapes[donor][t] for t in permutation]:
                        continue
                    for signs in itertools.product((1, -1), repeat=dim - 1):
                        transform = [0] * dim
                        for axis, target, sign in zip(face.tangent_axes, permutation, signs):
                            transform[axis] = sign * (target + 1)
                        transform[face.axis] = (1 if face.side != other.side else -1) * (other.axis + 1)
                        interface = Interface(block, face, donor, other, tuple(transform))
                        here, there = face_index(block_set, interface)
                        gap = Xs[donor].reshape(-1, dim)[there] - Xs[block].reshape(-1, dim)[here] - np.asarray(separation)
                        if np.abs(gap).max() <= CYCLIC_TOLERANCE * block_set.length:
                            found = interface
            if found is None:
                raise FormatError(
                    f"cgns: the face {block_set.names[block]}.{face_name} of cyclic patch '{a}' matches no block face of '{b}' "
                    "node by node: write --format openfoam"
                )
            periodic.append(found)
    records = connectivity_records(dataclasses.replace(block_set, interfaces=tuple(periodic)))
    for block, entries in enumerate(records):
        for k, (name, donor, point_range, donor_range, transform) in enumerate(entries):
            start, end = Xs[block][tuple(point_range[0] - 1)], Xs[block_set.names.index(donor)][tuple(donor_range[0] - 1)]
            entries[k] = (f"periodic_{name}"[:32], donor, point_range, donor_range, transform, end - start)
    return records


def _foam_transform(pair, dim: int) -> tuple:
    """(R (3, 3), t (3,), {patch: its boundary entry's lines}) of a cyclic pair in OpenFOAM's
    terms: ``translational`` with each side's ``separationVector`` to the other, or
    ``rotational`` with one ``rotationAxis`` and ``rotationCentre`` on both sides."""
    a, b = pair[:2]
    R2, t2 = pair_map(pair, dim)
    R, t = np.eye(3), np.zeros(3)
    R[:dim, :dim], t[:dim] = R2, t2

    def vector(values):
        return " ".join(f"{v + 0.0:.17g}" for v in values)

    lines = {}
    for name, other, sign in ((a, b, 1.0), (b, a, -1.0)):
        if len(pair) < 4 or pair[3] is None:
            how = f"translational;\n        separationVector ({vector(sign * t)});\n"
        else:
            centre, axis, _ = pair[3]
            how = f"rotational;\n        rotationAxis    ({vector(axis)});\n        rotationCentre  ({vector((*centre, 0.0)[:3])});\n"
        lines[name] = f"        neighbourPatch  {other};\n        transform       {how}"
    return R, t, lines


def _write_openfoam(case, block_set: BlockSet, Xs, metadata: dict) -> None:
    """The OpenFOAM case of the merged mesh (interfaces as internal faces) through the one case
    writer of a single block (``meshgen.formats._openfoam.write_case``): the same system files,
    ``0/U`` and ``0/p`` from the patches' types and roles, re-mesh rules and atomic publication."""
    points, cells, _ = merged_mesh(block_set, Xs)
    faces = patch_faces(block_set)
    cyclic = []
    for pair in block_set.cyclic:  # b's faces in a's order: the i-th of b is the i-th of a mapped
        a, b = pair[:2]
        index = {name: k for k, (name, _, _) in enumerate(faces)}
        first, second = faces[index[a]][2], faces[index[b]][2]
        order = matching_order(points, first, second, pair, block_set.length)
        faces[index[b]] = (b, CYCLIC, second[order])
        cyclic.append((a, b, *_foam_transform(pair, block_set.dim)))
    if block_set.dim == 2:
        check_extrusion_patch([Patch(name, kind, ()) for name, kind, _ in faces], 2)
        points, cells, walls, front_back, _ = extrude_quads(points, cells, [elements for _, _, elements in faces])
        faces = [(name, kind, elements) for (name, kind, _), elements in zip(faces, walls)]
        faces.append((EXTRUDED_PATCH, "empty", front_back))
    patches = [Patch(name, kind, ()) for name, kind, _ in faces if name != EXTRUDED_PATCH]

    def write_folder(folder, _patches):
        write_poly_mesh(folder, points, cells, faces, cyclic)

    write_case(case, (0,) * block_set.dim, metadata, patches, write_folder, block_set=block_set.name)
