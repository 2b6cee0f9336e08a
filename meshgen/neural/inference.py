"""The one inference path of a trained model (design notes §6, §20): a model is a set of networks,
one per block, and a 0.2 checkpoint's single network (no ``blocks`` entry, weights under
``layers.<k>.``) is a set of one (``block_model``, ``block_count``). Every block's map on its
tensor grid comes from :func:`block_nodes` (``meshgen.neural.network_map.mesh_from_model``: the
NumPy forward pass on a CPU, torch on a GPU; soft or exact boundary), for one block
(``meshgen.neural.models.build_neural``) as for a block set (:func:`network_blocks`).

A geometry of one boundary map is then corrected to X + TFI[g - X]
(``meshgen.methods.correction.correct_boundary``, every face pinned to the boundary map). A set of
several blocks takes one conforming correction of all blocks (:func:`neural_blocks`), which first
settles one position per mesh node that lies on a block face: a node on an interface takes the
mean of the images of all blocks that hold it; a node on a curved patch (or on two patches) takes
the geometry's boundary map; a node on one flat patch only (a pipe's inlet) takes the mean
projected onto the patch's plane (it slides in the plane, as in the elliptic mesh). Each block is
then corrected to those face positions, X + C[target - X] with the blending of
``meshgen.methods.correction.add_boundary_correction``, so that the faces are the targets to
round-off; interface nodes are finally made bit-identical (``meshgen.geometry.block_nodes.unify_interfaces``).

A model of an extruded block set (``meshgen.geometry.extrusion``; its ``model["extruded"]`` holds the
extrusion it was trained for) holds the section's 2D networks: the section's mesh is made as above
and extruded, so the mesh is an exact extrusion at every --dims.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.block_nodes import global_numbering, interface_gaps, unify_interfaces
from meshgen.geometry.blocks import BlockSet, check_handedness
from meshgen.geometry.extrusion import extrude, extrusion_of, section_of
from meshgen.methods.correction import add_boundary_correction
from meshgen.methods.tfi import boundary_faces
from meshgen.neural.checkpoint_data import CheckpointError, check_network
from meshgen.neural.network_map import mesh_from_model
from meshgen.neural.wall_map import check_wall_model, is_wall_model, neural_wall_blocks

__all__ = [
    "FLAT_TOLERANCE",
    "block_count",
    "block_model",
    "block_nodes",
    "check_block_model",
    "check_model",
    "check_start_model",
    "face_plane",
    "face_targets",
    "is_block_model",
    "network_blocks",
    "neural_blocks",
]


FLAT_TOLERANCE = 1e-9  # a patch face is flat when its points lie within this (relative) of a plane


def face_plane(points: np.ndarray, length: float):
    """(unit normal, offset) of the plane through ``points`` (N, d) when they all lie within
    ``FLAT_TOLERANCE * length`` of it, else None."""
    centre = points.mean(axis=0)
    _, singular, vt = np.linalg.svd(points - centre, full_matrices=False)
    normal = vt[-1]
    if np.max(np.abs((points - centre) @ normal)) > FLAT_TOLERANCE * length:
        return None
    return normal, float(centre @ normal)


def is_block_model(model: dict) -> bool:
    """Whether a ``checkpoint["model"]`` description holds the networks of a multi-block set (a
    ``blocks`` entry); 0.2's one-network description is a set of one block without it."""
    return isinstance(model, dict) and "blocks" in model


def block_count(model: dict) -> int:
    """The number of networks (blocks) of a ``checkpoint["model"]`` description: 1 for 0.2's one network."""
    return len(model["blocks"]) if is_block_model(model) else 1


def block_model(model: dict, index: int) -> dict:
    """The single-network description of block ``index`` of a model: the network under
    ``networks.<index>.`` of a block-set model; a one-network model (0.2's layout) is its own block 0."""
    if not is_block_model(model):
        if index != 0:
            raise IndexError(f"a one-network model has block 0 only, not {index}")
        return model
    prefix = f"networks.{index}."
    state = {k[len(prefix) :]: v for k, v in model["state_dict"].items() if k.startswith(prefix)}
    return {**{k: v for k, v in model.items() if k not in ("blocks", "state_dict")}, "state_dict": state}


def check_block_model(model: dict) -> None:
    """CheckpointError unless ``model`` is a block model whose every network is a meshgen network and
    whose weights are all used."""
    names = model.get("blocks")
    if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names)):
        raise CheckpointError("the checkpoint's block model names no blocks: the file is damaged")
    used = 0
    for index in range(len(names)):
        sub = block_model(model, index)
        check_network(sub)
        used += len(sub["state_dict"])
    if used != len(model.get("state_dict", {})):
        raise CheckpointError("the checkpoint's block model holds weights of no block: the file is damaged")


def check_model(model: dict) -> None:
    """CheckpointError (one line) unless ``model`` is a meshgen model: a block set's networks
    (:func:`check_block_model`) or one network (``check_network``), before any work is done."""
    if is_wall_model(model):
        check_wall_model(model)
    elif is_block_model(model):
        check_block_model(model)
    else:
        check_network(model)


def block_nodes(model: dict, index: int, coords, geometry=None, device: str = "cpu") -> np.ndarray:
    """The map of block ``index`` of ``model`` on the tensor grid of its 1D parametric ``coords``, in
    physical units: (len(coords[0]), ..., d) float64, not yet corrected onto the boundary.
    ``geometry``: the block's bound Geometry, needed by an exact-boundary network (TFI + b N)."""
    return mesh_from_model(block_model(model, index), list(coords), geometry, device=device)


def _check_fits(model: dict, block_set: BlockSet) -> None:
    if list(model["blocks"]) != list(block_set.names) or int(model["dim"]) != block_set.dim:
        raise CheckpointError(
            f"the model's blocks ({', '.join(model['blocks'])}) are not those of '{block_set.name}' ({', '.join(block_set.names)})"
        )


def _section(model: dict, block_set: BlockSet):
    """(extrusion, section block set) when ``model`` is an extruded set's section model, else None;
    CheckpointError when the model's extrusion is not ``block_set``'s."""
    if "extruded" not in model:
        return None
    extrusion = extrusion_of(block_set)
    if extrusion is None or not extrusion.matches(model["extruded"], block_set.length):
        raise CheckpointError(
            f"the model meshes the section of an extruded block set, and '{block_set.name}' with these parameters is not "
            "that extrusion (design notes §20)"
        )
    return extrusion, section_of(block_set, extrusion)


def network_blocks(model: dict, block_set: BlockSet, device: str = "cpu") -> list[np.ndarray]:
    """Every block's network on its tensor grid (``block_set.coords``), in physical units: node
    arrays as ``meshgen.geometry.blocks`` takes them (not yet conforming, nor on the boundary)."""
    section = _section(model, block_set)
    if section is not None:
        extrusion, plane = section
        return extrude(extrusion, _network_nodes(model, plane, device), block_set.coords[0][2])
    return _network_nodes(model, block_set, device)


def _network_nodes(model: dict, block_set: BlockSet, device: str) -> list[np.ndarray]:
    _check_fits(model, block_set)
    return [block_nodes(model, index, coords, device=device) for index, coords in enumerate(block_set.coords)]


def check_start_model(model: dict, block_set: BlockSet, option: str) -> None:
    """CheckpointError (one line) unless the block model ``model`` that a run starts from
    (``option``: --resume or --init) is of the kind the run trains: the section's 2D networks for an
    extruded ``block_set`` (the same extrusion), else networks of the set's dimension."""
    extrusion = extrusion_of(block_set)
    extruded = model.get("extruded")
    if extrusion is not None and extruded is None:
        raise CheckpointError(
            f"{option}: the checkpoint holds {model['dim']}D networks, and '{block_set.name}' is extruded: meshgen trains "
            "its 2D section (design notes §20); train anew"
        )
    if extrusion is None and extruded is not None:
        raise CheckpointError(
            f"{option}: the checkpoint holds the section model of an extruded block set; '{block_set.name}' is not extruded"
        )
    if extrusion is not None and not extrusion.matches(extruded, block_set.length):
        raise CheckpointError(
            f"{option}: the checkpoint's section model was trained for another extrusion than that of '{block_set.name}'"
        )


def face_targets(block_set: BlockSet, Xs) -> tuple[np.ndarray, list[np.ndarray]]:
    """One position per node of the merged mesh ((count, d)) for the nodes on block faces (the
    module docstring's rules; other nodes hold the blocks' mean, unused), and the global numbering."""
    dim = block_set.dim
    numbering, count = global_numbering(block_set)
    sums, copies = np.zeros((count, dim)), np.zeros(count)
    for X, ids in zip(Xs, numbering):
        np.add.at(sums, ids.reshape(-1), X.reshape(-1, dim))
        np.add.at(copies, ids.reshape(-1), 1.0)
    target = sums / copies[:, None]
    pinned, pinned_value = np.zeros(count, dtype=bool), np.zeros((count, dim))
    normals, offsets = np.full((count, dim), np.nan), np.full(count, np.nan)
    for (block, face_name), _ in sorted(block_set.patches.items()):
        face = cube.face_named(face_name, dim)
        ids = numbering[block][face.node_index].reshape(-1)
        images = block_set.geometries[block].boundary(face.points(block_set.coords[block]))
        plane = face_plane(images, block_set.length)
        if plane is None:
            conflict = np.ones(len(ids), dtype=bool)
        else:
            normal, offset = plane
            known = ~np.isnan(offsets[ids])
            same = np.abs(np.abs(normals[ids] @ normal) - 1.0) < 1e-9
            same &= np.abs(np.abs(offsets[ids]) - abs(offset)) < 1e-9 * block_set.length
            conflict = known & ~same
            normals[ids[~known]], offsets[ids[~known]] = normal, offset
        pinned[ids[conflict]] = True
        pinned_value[ids[conflict]] = images[conflict]
    sliding = ~pinned & ~np.isnan(offsets)
    n = normals[sliding]
    target[sliding] -= (np.einsum("ij,ij->i", target[sliding], n) - offsets[sliding])[:, None] * n
    target[pinned] = pinned_value[pinned]
    return target, numbering


def neural_blocks(block_set: BlockSet, model: dict, correct: bool = True, device: str = "cpu"):
    """The block set's mesh from a block model (``checkpoint["model"]``): (node arrays, info).
    With ``correct`` (the default) the conforming correction of the module docstring: faces on
    their targets to round-off, interface nodes identical; without it, the networks' own nodes
    with the interfaces merely unified (refused when they do not coincide). ``info``: the
    interface gap and boundary error before the correction (relative to the set's length)."""
    if is_wall_model(model):  # a row of blocks round a wall: the plugin's outer blend makes it conforming
        return neural_wall_blocks(block_set, model)
    section = _section(model, block_set)
    if section is not None:
        extrusion, plane = section
        Xs, info = _conforming(plane, model, correct, device)
        Xs = extrude(extrusion, Xs, block_set.coords[0][2])  # right-handed: the section is, and so is (e1, e2, sweep)
        rescale = plane.length / block_set.length  # the section's relative figures as the set's
        for key in ("interface_gap_before", "face_error_before"):
            info[key] *= rescale
        return Xs, {**info, "extruded": True}
    return _conforming(block_set, model, correct, device)


def _conforming(block_set: BlockSet, model: dict, correct: bool, device: str):
    Xs = _network_nodes(model, block_set, device)
    length = block_set.length
    gap = max(interface_gaps(block_set, Xs), default=0.0) / length
    target, numbering = face_targets(block_set, Xs)
    moved = 0.0
    for X, ids, coords in zip(Xs, numbering, block_set.coords):
        errors = [target[ids[index]] - X[index] for index, _ in boundary_faces(list(coords))]
        moved = max(moved, max(float(np.linalg.norm(e, axis=-1).max()) for e in errors))
        if correct:
            add_boundary_correction(X, errors, list(coords))
    if correct:
        unify_interfaces(block_set, Xs)
    else:
        unify_interfaces(block_set, Xs, tolerance=np.inf)
    check_handedness(block_set, Xs)
    info = {
        "corrected": bool(correct),
        "interface_gap_before": gap,
        "face_error_before": moved / length,
        "definition": "largest distance, relative to the characteristic length, between the networks' face nodes and "
        "their conforming positions (interface mean, boundary map, or projection onto a flat patch)",
    }
    return Xs, info
