"""Block sets: a geometry made of several structured blocks that meet face to face (design notes
§11, §20). The one module that knows about blocks; methods and writers take a
``BlockSet`` and a list of node arrays (one per block) and ask it for faces, interfaces and the
merged node numbering.

A multi-block plugin is a geometry plugin (``meshgen.geometry.plugins``) that also declares::

    blocks = ("core", "east", ...)                 # block names, in zone order
    dims_meaning = "cells around a quarter ..."    # what --dims counts
    def block_coords(dims, **params): ...          # {block: [1D parametric node coordinates per axis]}
    def boundary(block, points, **params): ...     # the block's map of the unit cube's boundary
    interfaces = [("core", "xi1", "east", "xi0"), ...]   # faces that meet (orientation derived)
    block_patches = {"east": {"xi1": ("wall", "wall")}, ...}   # every other face: a patch
    cyclic = [("left", "right", (2.0, 0.0))]       # optional: cyclic patch pairs, right = left + separation

``interfaces`` and ``block_patches`` may be functions of the parameters (a topology that depends on them).

Each block is a ``Geometry`` (``<name>.<block>``) as meshgen's single-block methods know it. An
interface's orientation is a CGNS Transform (``transform``): ``Index_b = T (Index_a - Begin_a) +
Begin_b``, entry ``i`` of T being ``+-(axis of b + 1)`` for axis ``i`` of a; it is found by
matching the two faces' corners and then checked node by node.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry import cube
from meshgen.geometry.block_nodes import interface_text, unify_interfaces
from meshgen.geometry.cyclic import CYCLIC, check_cyclic
from meshgen.geometry.patches import PATCH_TYPES, Patch, check_patch_name
from meshgen.geometry.plugins import Geometry, available_names, bind, load_geometry, plugin_module
from meshgen.geometry.shapes.loader import is_shape_file
from meshgen.geometry.shapes.sweep_yaml import is_sweep_geometry
from meshgen.methods.tfi import tfi
from meshgen.run.limits import check_block_set_memory

__all__ = [
    "BlockSet",
    "Interface",
    "block_patches",
    "block_spec",
    "check_interfaces",
    "connectivity_records",
    "describe",
    "inverse_transform",
    "is_multiblock",
    "load_block_set",
    "measured_block_set",
    "tfi_blocks",
]


@dataclass(frozen=True)
class Interface:
    """Face ``face_a`` of block ``a`` is face ``face_b`` of block ``b`` (block indices), with the
    CGNS ``transform`` from a's node indices to b's."""

    a: int
    face_a: cube.Face
    b: int
    face_b: cube.Face
    transform: tuple[int, ...]


@dataclass(frozen=True)
class BlockSet:
    """The blocks of a multi-block geometry with its parameters bound and its cell counts chosen.

    ``geometries``: one ``Geometry`` per block; ``coords``: per block, the parametric node
    coordinates per axis; ``patches``: (block index, face name) -> (patch name, type) for every
    face that is not on an interface; ``cyclic``: (patch, neighbour patch, separation (dim,)[,
    rotation]) of its cyclic pairs (``meshgen.geometry.cyclic``); ``surfaces``: (block index, face
    name) -> the closest-point map (N, dim) -> (N, dim) of the surface whose nodes slide on it in the
    elliptic solve (a topology file's ``slide: true`` on a projected patch)."""

    name: str
    dim: int
    description: str
    values: dict
    names: tuple[str, ...]
    geometries: tuple[Geometry, ...]
    coords: tuple
    interfaces: tuple[Interface, ...]
    patches: dict = field(default_factory=dict)
    dims_meaning: str = ""
    length: float = 1.0
    cyclic: tuple = ()
    surfaces: dict = field(default_factory=dict)

    @property
    def node_shapes(self) -> list[tuple[int, ...]]:
        return [tuple(len(t) for t in c) for c in self.coords]

    @property
    def cells(self) -> int:
        return int(sum(np.prod([n - 1 for n in shape]) for shape in self.node_shapes))


def block_spec(geometry) -> str | None:
    """The plugin spec (name or path) of ``geometry`` (a name, a path or a loaded Geometry) when it
    declares blocks, else None."""
    if geometry is None:
        return None
    if isinstance(geometry, Geometry):
        if geometry.name in available_names() and plugin_module(geometry.name)[1] == geometry.source:
            spec = geometry.name
        elif geometry.source and Path(geometry.source).is_file():
            spec = geometry.source
        else:
            return None
    else:
        spec = str(geometry)
    if is_sweep_geometry(spec):  # a CAD solid swept from a cap: a block set
        return spec
    if is_shape_file(spec) or Path(spec).suffix.lower() not in ("", ".py", ".yaml", ".yml", ".dat"):
        return None  # a shape file is one block (a topology file, .yaml too, is a block set)
    return spec if is_multiblock(spec) else None


def measured_block_set(spec: str, params: dict | None = None, dims=None) -> BlockSet:
    """The block set of plugin ``spec`` to measure a mesh against or to show: with the cell counts
    ``dims`` its mesh was made with (its coordinates then seed the boundary deviation), else the
    plugin's ``shown_dims`` or 4 cells per --dims number (maps, patches, interfaces do not depend on them)."""
    dim, module = load_geometry(spec, params, check=False, dims=dims).dim, plugin_module(spec, dims)[0]
    dims = tuple(int(n) for n in dims) if dims is not None and len(dims) == dim else getattr(module, "shown_dims", (4,) * dim)
    return load_block_set(spec, params, dims)


def is_multiblock(spec: str) -> bool:
    """Whether the geometry ``spec`` (name or plugin path) declares blocks (a shape file never does)."""
    if isinstance(spec, str) and is_sweep_geometry(spec):
        return True
    if not isinstance(spec, str) or is_shape_file(spec):
        return False
    module, _ = plugin_module(spec)
    return hasattr(module, "blocks")


def load_block_set(spec: str, params: dict | None = None, dims=None) -> BlockSet:
    """The block set of plugin ``spec`` with ``params`` over its defaults and the cell counts
    ``dims`` (what the plugin's ``dims_meaning`` says), its interfaces derived and checked."""

    module, source = plugin_module(spec, dims)
    base = load_geometry(spec, params, check=False, dims=dims)
    for attribute in ("blocks", "block_coords", "interfaces", "block_patches"):
        if not hasattr(module, attribute):
            raise GeometryError(f"multi-block geometry plugin {source} does not define '{attribute}'")
    names = tuple(module.blocks)
    declared_patches, declared_interfaces = _declared(module, "block_patches", base), _declared(module, "interfaces", base)
    dim = base.dim
    if dims is None or len(dims) != dim:
        got = "none" if dims is None else len(dims)
        raise GeometryError(f"geometry '{base.name}' is {dim}D: --dims needs {dim} numbers ({module.dims_meaning}), got {got}")
    coords = _block_coords(module, base, source, dims)
    geometries = []
    for block in names:
        geometries.append(
            bind(
                Geometry(
                    f"{base.name}.{block}",
                    dim,
                    base.description,
                    base.defaults,
                    base.values,
                    _block_map(module.boundary, block),
                    None,
                    source,
                    {},
                ),
                None,
            )
        )
        if block not in coords or len(coords[block]) != dim:
            raise GeometryError(f"geometry '{base.name}': block_coords() gives no {dim} axes for block '{block}'")
    block_coords = tuple(tuple(np.asarray(t, dtype=float) for t in coords[block]) for block in names)
    if not all(t.ndim == 1 and len(t) >= 2 and np.isfinite(t).all() for axes in block_coords for t in axes):
        raise GeometryError(
            f"geometry '{base.name}'{_with_params(base)}: block_coords() gives an axis that is not finite numbers"
        )
    # Every block's size through the limits a single block's takes, before anything is allocated.
    check_block_set_memory([tuple(len(t) - 1 for t in axes) for axes in block_coords], base.name)
    length = float(base.length_map(**base.values)) if base.length_map is not None else 1.0
    patches = {}
    for block, faces in declared_patches.items():
        if block not in names:
            raise GeometryError(f"geometry '{base.name}': block_patches names an unknown block '{block}'")
        for face_name, (patch, kind) in faces.items():
            _face(face_name, dim, base.name)
            check_patch_name(patch)
            if kind not in (*PATCH_TYPES, CYCLIC):
                raise GeometryError(f"geometry '{base.name}': patch '{patch}' has unknown type '{kind}'")
            patches[names.index(block), face_name] = (patch, kind)
    cyclic = _cyclic(base.name, getattr(module, "cyclic", ()), patches, dim)
    declared = []
    for entry in declared_interfaces:
        block_a, face_a, block_b, face_b = entry[:4]
        for block in (block_a, block_b):
            if block not in names:
                raise GeometryError(f"geometry '{base.name}': interface {entry} names an unknown block '{block}'")
        declared.append(
            (names.index(block_a), _face(face_a, dim, base.name), names.index(block_b), _face(face_b, dim, base.name))
        )
    surfaces = {(names.index(block), face): project for (block, face), project in getattr(module, "face_surfaces", {}).items()}
    block_set = BlockSet(
        base.name, dim, base.description, dict(base.values), names, tuple(geometries), block_coords, (), patches,
        getattr(module, "dims_meaning", ""), length, cyclic, surfaces,
    )  # fmt: skip
    _check_faces(block_set, declared)
    interfaces = tuple(Interface(a, fa, b, fb, _derive_transform(block_set, a, fa, b, fb)) for a, fa, b, fb in declared)
    block_set = BlockSet(**{**block_set.__dict__, "interfaces": interfaces})
    check_interfaces(block_set)
    return block_set


def _cyclic(name: str, declared, patches: dict, dim: int) -> tuple:
    """The plugin's cyclic pairs checked: each names two cyclic patches and a separation of
    ``dim`` numbers; every cyclic patch is in one pair."""
    kinds = {patch: kind for patch, kind in patches.values()}
    pairs, paired = [], []
    for a, b, separation, *rotation in declared:
        separation = np.asarray(separation, dtype=float)
        if kinds.get(a) != CYCLIC or kinds.get(b) != CYCLIC or a == b or separation.shape != (dim,):
            raise GeometryError(f"geometry '{name}': the cyclic pair ({a}, {b}) needs two cyclic patches and a separation")
        pairs.append((a, b, tuple(float(v) for v in separation), *rotation[:1]))
        paired += [a, b]
    lone = sorted({p for p, k in kinds.items() if k == CYCLIC and paired.count(p) != 1})
    if lone:
        raise GeometryError(f"geometry '{name}': the cyclic patch '{lone[0]}' is not in exactly one cyclic pair")
    return tuple(pairs)


def _declared(module, attribute: str, geometry: Geometry):
    """The plugin's ``interfaces`` or ``block_patches``: as declared, or its function's value at the parameters."""
    value = getattr(module, attribute)
    return value(**geometry.values) if callable(value) else value


def _with_params(base) -> str:
    """`` with a=1, b=2`` naming the geometry's parameters as given, or ``""`` when it has none."""
    values = dict(base.values)
    return " with " + ", ".join(f"{k}={v!r}" for k, v in values.items()) if values else ""


def _block_coords(module, base, source, dims) -> dict:
    """The plugin's ``block_coords(dims, **params)``; a failure, or a floating-point warning
    (a division by zero, an overflow: parameters inside their range that break the geometry), is
    one GeometryError naming the parameters."""
    try:
        with np.errstate(all="raise"), warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            return module.block_coords(tuple(int(n) for n in dims), **base.values)
    except MeshgenError:
        raise
    except Exception as exc:
        words = " ".join(str(exc).split())[:200]
        raise GeometryError(
            f"geometry '{base.name}' ({source}){_with_params(base)}: block_coords() raised {type(exc).__name__}: {words}"
            + (" (the parameters break the geometry: try other values)" if base.values else "")
        ) from exc


def _block_map(boundary, block: str):
    def block_boundary(points, **values):
        return boundary(block, points, **values)

    return block_boundary


def _face(name: str, dim: int, geometry: str) -> cube.Face:
    try:
        return cube.face_named(name, dim)
    except KeyError:
        raise GeometryError(f"geometry '{geometry}': unknown face '{name}' of a {dim}D block") from None


def _check_faces(block_set: BlockSet, declared) -> None:
    """A face claimed by two interfaces, a patch on an interface face, a face with neither."""
    owner = {}
    for a, fa, b, fb in declared:
        for block, face in ((a, fa), (b, fb)):
            key = (block, face.name)
            if key in owner:
                raise GeometryError(
                    f"geometry '{block_set.name}': face {face.name} of block '{block_set.names[block]}' is claimed by two "
                    f"interfaces ({owner[key]} and {interface_text(block_set, a, fa, b, fb)})"
                )
            owner[key] = interface_text(block_set, a, fa, b, fb)
            if key in block_set.patches:
                raise GeometryError(
                    f"geometry '{block_set.name}': face {face.name} of block '{block_set.names[block]}' is on the interface "
                    f"{owner[key]} and also named patch '{block_set.patches[key][0]}'"
                )
    for block, name in enumerate(block_set.names):
        for face in cube.faces(block_set.dim):
            if (block, face.name) not in owner and (block, face.name) not in block_set.patches:
                raise GeometryError(
                    f"geometry '{block_set.name}': face {face.name} of block '{name}' is neither a patch nor on an interface"
                )


def _corner_points(face: cube.Face) -> np.ndarray:
    """The face's corners as parametric points, in C order of its tangential axes."""
    columns = [np.array(c, dtype=float) for c in itertools.product((0.0, 1.0), repeat=face.dim - 1)]
    points = np.zeros((len(columns), face.dim))
    for row, values in enumerate(columns):
        points[row, list(face.tangent_axes)] = values
        points[row, face.axis] = face.side
    return points


def _derive_transform(block_set: BlockSet, a, fa: cube.Face, b, fb: cube.Face) -> tuple[int, ...]:
    """The Transform whose tangential part maps face a's corners closest onto face b's."""
    corners_a = block_set.geometries[a].boundary(_corner_points(fa))
    best, best_gap = None, np.inf
    for permutation in itertools.permutations(fb.tangent_axes):
        for signs in itertools.product((1, -1), repeat=len(permutation)):
            transform = [0] * block_set.dim
            for axis, target, sign in zip(fa.tangent_axes, permutation, signs):
                transform[axis] = sign * (target + 1)
            transform[fa.axis] = (1 if fa.side != fb.side else -1) * (fb.axis + 1)
            # The parametric image on face b of each corner of face a.
            points = np.zeros((2 ** (block_set.dim - 1), block_set.dim))
            for row, corner in enumerate(_corner_points(fa)):
                for axis in fa.tangent_axes:
                    target, sign = abs(transform[axis]) - 1, np.sign(transform[axis])
                    points[row, target] = corner[axis] if sign > 0 else 1.0 - corner[axis]
                points[row, fb.axis] = fb.side
            gap = float(np.max(np.linalg.norm(block_set.geometries[b].boundary(points) - corners_a, axis=1)))
            if gap < best_gap:
                best, best_gap = tuple(transform), gap
    return best


def check_interfaces(block_set: BlockSet) -> None:
    """Node counts that match along every interface under its Transform (GeometryError naming the
    interface otherwise)."""
    shapes = block_set.node_shapes
    for interface in block_set.interfaces:
        for axis in interface.face_a.tangent_axes:
            target = abs(interface.transform[axis]) - 1
            if shapes[interface.a][axis] != shapes[interface.b][target]:
                raise GeometryError(
                    f"geometry '{block_set.name}': interface {interface_text(block_set, interface.a, interface.face_a, interface.b, interface.face_b)}"
                    f" has {shapes[interface.a][axis] - 1} cells on one side and {shapes[interface.b][target] - 1} on the other"
                )


def _face_range(shape, face: cube.Face) -> np.ndarray:
    """The 1-based vertex range (2, dim) of a block face: first corner, last corner."""
    first, last = [1] * len(shape), list(shape)
    first[face.axis] = last[face.axis] = shape[face.axis] if face.side else 1
    return np.array([first, last])


def _mapped(index, transform, begin_a, begin_b) -> np.ndarray:
    """CGNS: Index_b = T (Index_a - Begin_a) + Begin_b, T's column i the unit vector of axis
    |T[i]| - 1 with T[i]'s sign."""
    result = np.array(begin_b, dtype=int)
    for axis, t in enumerate(transform):
        result[abs(t) - 1] += int(np.sign(t)) * (index[axis] - begin_a[axis])
    return result


def inverse_transform(transform) -> tuple[int, ...]:
    inverse = [0] * len(transform)
    for axis, t in enumerate(transform):
        inverse[abs(t) - 1] = int(np.sign(t)) * (axis + 1)
    return tuple(inverse)


def connectivity_records(block_set: BlockSet) -> list[list[tuple]]:
    """Per block, its 1-to-1 connectivity records as CGNS stores them, every interface from both
    sides: (record name, donor block name, PointRange (2, dim), PointRangeDonor (2, dim),
    Transform), ranges 1-based; PointRange runs from the face's first to its last corner and
    PointRangeDonor gives the donor's vertices of those two corners."""
    shapes = block_set.node_shapes
    records = [[] for _ in block_set.names]
    for interface in block_set.interfaces:
        sides = (
            (interface.a, interface.face_a, interface.b, interface.face_b, interface.transform),
            (interface.b, interface.face_b, interface.a, interface.face_a, inverse_transform(interface.transform)),
        )
        for block, face, donor, donor_face, transform in sides:
            point_range = _face_range(shapes[block], face)
            # The donor's vertex of this face's first corner: the donor face's corner it maps to.
            begin_donor = np.empty(block_set.dim, dtype=int)
            for axis, t in enumerate(transform):
                target = abs(t) - 1
                if axis == face.axis:
                    begin_donor[target] = shapes[donor][target] if donor_face.side else 1
                else:
                    begin_donor[target] = 1 if t > 0 else shapes[donor][target]
            donor_range = np.array([begin_donor, _mapped(point_range[1], transform, point_range[0], begin_donor)])
            name = f"{face.name}_{block_set.names[donor]}"[:32]
            records[block].append((name, block_set.names[donor], point_range, donor_range, tuple(transform)))
    return records


def block_patches(block_set: BlockSet, interfaces: bool = False) -> list[list[Patch]]:
    """Per block, its patches (``meshgen.geometry.patches.Patch``, faces of that block only); with
    ``interfaces``, each interface face too, as a ``patch`` named ``to_<neighbour block>`` (for
    formats whose patches must cover every face of a block)."""
    neighbours = {}
    if interfaces:
        for i in block_set.interfaces:
            neighbours[i.a, i.face_a.name] = (f"to_{block_set.names[i.b]}", "patch")
            neighbours[i.b, i.face_b.name] = (f"to_{block_set.names[i.a]}", "patch")
    result = []
    for block in range(len(block_set.names)):
        faces_of: dict[str, list[str]] = {}
        type_of = {}
        for face in cube.faces(block_set.dim):
            entry = block_set.patches.get((block, face.name)) or neighbours.get((block, face.name))
            if entry is not None:
                name, kind = entry
                faces_of.setdefault(name, []).append(face.name)
                type_of[name] = kind
        result.append([Patch(name, type_of[name], tuple(faces)) for name, faces in faces_of.items()])
    return result


def tfi_blocks(block_set: BlockSet) -> list[np.ndarray]:
    """Transfinite interpolation of every block, interface nodes checked and made identical,
    cyclic pairs checked (``meshgen.geometry.cyclic.check_cyclic``)."""
    Xs = [tfi(geometry, None, list(coords)) for geometry, coords in zip(block_set.geometries, block_set.coords)]
    unify_interfaces(block_set, Xs)
    check_handedness(block_set, Xs)
    check_cyclic(block_set, Xs)
    return Xs


def check_handedness(block_set: BlockSet, Xs) -> None:
    """GeometryError for a block whose map is left-handed (negative total Jacobian)."""
    for name, X in zip(block_set.names, Xs):
        if _signed_volume(X) <= 0:
            raise GeometryError(f"geometry '{block_set.name}': block '{name}' is left-handed (its map turns the cube inside out)")


def _signed_volume(X: np.ndarray) -> float:
    dim = X.shape[-1]
    e = [np.diff(X, axis=a)[tuple(slice(0, -1) if d != a else slice(None) for d in range(dim))] for a in range(dim)]
    if dim == 2:
        return float(np.sum(e[0][..., 0] * e[1][..., 1] - e[0][..., 1] * e[1][..., 0]))
    return float(np.sum(np.einsum("...i,...i", e[0], np.cross(e[1], e[2]))))


def describe(spec: str) -> dict | None:
    """``meshgen geometries`` entry of a multi-block plugin (None for a single-block one): name,
    dim, description, params, patches (name, type, faces as ``block.face``), blocks and what
    --dims counts."""

    module, _ = plugin_module(spec)
    if not hasattr(module, "blocks"):
        return None
    geometry = load_geometry(spec, check=False)
    faces_of, type_of = {}, {}
    for block, faces in _declared(module, "block_patches", geometry).items():
        for face, (name, kind) in faces.items():
            faces_of.setdefault(name, []).append(f"{block}.{face}")
            type_of[name] = kind
    return {
        "name": geometry.name,
        "dim": geometry.dim,
        "description": geometry.description,
        "params": dict(geometry.defaults),
        "patches": [{"name": n, "type": type_of[n], "faces": f} for n, f in faces_of.items()],
        "axes": {},  # several blocks: ``dims`` says what --dims counts
        "blocks": list(module.blocks),
        "dims": getattr(module, "dims_meaning", ""),
    }
