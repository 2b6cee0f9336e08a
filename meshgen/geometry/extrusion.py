"""Extruded block sets: a 3D block set that is a 2D block set (its section) swept along a straight
line, with flat end caps square to it, as the pipe and the 3D DFG channel are (design notes §20).

Winslow's equations keep such a set's mesh an extrusion: with x(xi, eta, zeta) = o + s(xi, eta) +
zeta v, s in the plane square to v, the zeta grid lines are straight and square to every section,
the 3D equations reduce to |v|^2 times the section's 2D ones, grid lines meet the caps at right
angles (the rule of flat patches) and interface and junction rules are those of the section. So
the extruded block set's elliptic mesh is the extrusion of its section's, and a block set's
network is trained on the section alone: its mesh is then an exact extrusion at every --dims,
where 3D networks leave cross-sections that vary along the axis, a motion the equations barely
resist when the cells are long along it.

The extrusion axis is every block's third parametric axis (zeta); a set qualifies when, to
``TOLERANCE`` times its characteristic length, every block's boundary map is s(xi, eta) + zeta v
with one v for all blocks, its zeta = 0 cap lies in one plane square to v, and every interface
keeps zeta as zeta (transform entry 3). The section's 2D coordinates are those in the frame
``(e1, e2)`` of ``Extrusion``: (x - origin) . e1, (x - origin) . e2.
"""

from __future__ import annotations

import dataclasses
import types
from dataclasses import dataclass

import numpy as np

from meshgen.errors import GeometryError, ParameterError
from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet, Interface
from meshgen.geometry.domain import Geometry
from meshgen.methods.tfi import transfinite

__all__ = [
    "TOLERANCE",
    "Extrusion",
    "extrude",
    "extruded_plugin",
    "extrusion_from",
    "extrusion_of",
    "geometry_extrusion",
    "section_geometry",
    "section_of",
    "sweep_frame",
]

TOLERANCE = 1e-9  # relative to the block set's characteristic length
_SAMPLES = 9  # sample points per face axis of the test


@dataclass(frozen=True)
class Extrusion:
    """x = origin + s1 e1 + s2 e2 + zeta direction: ``origin`` (3,) the foot of the section's
    plane on the line through 0 along ``direction``; ``frame`` (2, 3) orthonormal e1, e2 square to
    ``direction`` (3,), the sweep from zeta = 0 to zeta = 1, with (e1, e2, direction) right-handed."""

    origin: np.ndarray
    frame: np.ndarray
    direction: np.ndarray

    def describe(self) -> dict:
        """Plain data (a checkpoint's ``model["extruded"]``)."""
        return {"origin": self.origin.tolist(), "frame": self.frame.tolist(), "direction": self.direction.tolist()}

    def matches(self, entry: dict, length: float) -> bool:
        """Whether the plain data ``entry`` (``describe``) is this extrusion to ``TOLERANCE * length``."""
        mine = np.concatenate([self.origin, self.frame.ravel(), self.direction])
        theirs = np.concatenate([np.ravel(entry[key]) for key in ("origin", "frame", "direction")]).astype(float)
        return mine.shape == theirs.shape and bool(np.max(np.abs(mine - theirs)) <= TOLERANCE * max(length, 1.0))


def extrusion_from(entry: dict) -> Extrusion:
    """The ``Extrusion`` of its plain data ``entry`` (``Extrusion.describe``)."""
    return Extrusion(*(np.asarray(entry[key], dtype=float) for key in ("origin", "frame", "direction")))


def sweep_frame(direction: np.ndarray) -> np.ndarray:
    """Orthonormal (e1, e2) square to ``direction`` with (e1, e2, direction) right-handed: the two
    coordinate axes after the direction's, cyclically, when it lies along one (z: e1 = x, e2 = y)."""
    unit = direction / np.linalg.norm(direction)
    axis = int(np.argmin(np.abs(unit)))
    if np.count_nonzero(np.abs(unit) > TOLERANCE) == 1:
        axis = (int(np.argmax(np.abs(unit))) + 1) % 3
    e1 = np.eye(3)[axis] - unit[axis] * unit
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(unit, e1)])


def extrusion_of(block_set: BlockSet) -> Extrusion | None:
    """The block set's ``Extrusion`` along every block's zeta axis, or None when it is not one
    (the module docstring's tests)."""
    if block_set.dim != 3 or any(i.transform[2] != 3 or 2 in (i.face_a.axis, i.face_b.axis) for i in block_set.interfaces):
        return None
    if any(not np.array_equal(coords[2], block_set.coords[0][2]) for coords in block_set.coords):
        return None
    tolerance = TOLERANCE * block_set.length
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, _SAMPLES)] * 2, indexing="ij"), -1).reshape(-1, 2)
    zetas = np.linspace(0.0, 1.0, _SAMPLES)
    direction, caps = None, ([], [])
    for geometry in block_set.geometries:
        for face in cube.faces(3):
            if face.axis == 2:
                continue
            points = np.empty((len(grid), 3))
            points[:, list(face.tangent_axes)] = grid
            points[:, face.axis] = float(face.side)
            images = geometry.boundary(points).reshape(_SAMPLES, _SAMPLES, 3)  # the tangent axes: (xi or eta, zeta)
            sweep = images[:, -1] - images[:, 0]
            if direction is None:
                direction = sweep[0]
            if np.max(np.abs(sweep - direction)) > tolerance:
                return None
            linear = images[:, :1] + zetas[None, :, None] * direction
            if np.max(np.abs(images - linear)) > tolerance:
                return None
        for side, cap in enumerate(caps):  # the caps inside: the same section, the sweep apart
            cap.append(geometry.boundary(np.column_stack([grid, np.full(len(grid), float(side))])) - side * direction)
    if direction is None or not np.linalg.norm(direction) > tolerance:
        return None
    start, end = np.concatenate(caps[0]), np.concatenate(caps[1])
    if np.max(np.abs(end - start)) > tolerance:
        return None
    unit = direction / np.linalg.norm(direction)
    heights = start @ unit
    if np.ptp(heights) > tolerance:
        return None
    return Extrusion(float(heights.mean()) * unit, sweep_frame(direction), direction)


def geometry_extrusion(geometry: Geometry) -> Extrusion | None:
    """The ``Extrusion`` of a one-block 3D geometry along its zeta axis (:func:`extrusion_of` of the
    set of that one block), or None when it is not one."""
    if geometry.dim != 3:
        return None
    ends = (np.array([0.0, 1.0]),) * 3
    one = BlockSet(
        geometry.name,
        3,
        "",
        dict(geometry.values),
        (geometry.name,),
        (geometry,),
        (ends,),
        (),
        {},
        "",
        geometry.characteristic_length,
    )
    return extrusion_of(one)


def section_geometry(geometry: Geometry, extrusion: Extrusion) -> Geometry:
    """The 2D geometry of the zeta = 0 cap of the extruded 3D ``geometry`` in the frame's
    coordinates: boundary map (N, 2) -> (N, 2), (g(xi, eta, 0) - origin) . (e1, e2)."""
    return dataclasses.replace(
        geometry, name=f"{geometry.name}.section", dim=2, boundary_map=_section_map(geometry, extrusion), length_map=None
    )


def _section_map(geometry: Geometry, extrusion: Extrusion):
    def section(points, **values):
        points = np.asarray(points, dtype=float)
        images = geometry.boundary(np.column_stack([points, np.zeros(len(points))]))
        return (images - extrusion.origin) @ extrusion.frame.T

    return section


def section_of(block_set: BlockSet, extrusion: Extrusion) -> BlockSet:
    """The 2D block set of the extruded ``block_set``'s section (its zeta = 0 cap in the frame's
    coordinates): the same blocks, interfaces, side patches and sliding side faces, each block's
    first two axes."""
    geometries = tuple(section_geometry(g, extrusion) for g in block_set.geometries)
    interfaces = tuple(
        Interface(i.a, cube.face_named(i.face_a.name, 2), i.b, cube.face_named(i.face_b.name, 2), tuple(i.transform[:2]))
        for i in block_set.interfaces
    )
    patches = {key: value for key, value in block_set.patches.items() if not key[1].startswith("zeta")}
    sample = np.concatenate([g.boundary(cube.face_samples(2, 17)) for g in geometries])
    length = float(np.linalg.norm(sample.max(axis=0) - sample.min(axis=0)))
    maps = {project: _section_projection(project, extrusion) for project in block_set.surfaces.values()}
    surfaces = {key: maps[project] for key, project in block_set.surfaces.items() if not key[1].startswith("zeta")}
    return BlockSet(
        f"{block_set.name} (section)", 2, block_set.description, dict(block_set.values), block_set.names, geometries,
        tuple(coords[:2] for coords in block_set.coords), interfaces, patches, block_set.dims_meaning, length,
        surfaces=surfaces,
    )  # fmt: skip


def _section_projection(project, extrusion: Extrusion):
    """A surface's closest-point map in the section's frame coordinates (N, 2) -> (N, 2): the
    surface of a side face of an extrusion is swept along it, so the closest point of a point in
    the cap's plane lies in that plane."""

    def section(points):
        images = project(extrusion.origin + np.asarray(points, dtype=float) @ extrusion.frame)
        return (images - extrusion.origin) @ extrusion.frame.T

    return section


def extrude(extrusion: Extrusion, sections, zeta: np.ndarray) -> list[np.ndarray]:
    """Node arrays (n1, n2, len(zeta), 3) of the 3D blocks from the section's (n1, n2, 2) ones at
    the parametric nodes ``zeta`` along the axis: origin + s1 e1 + s2 e2 + zeta direction."""
    zeta = np.asarray(zeta, dtype=float)
    blocks = []
    for S in sections:
        plane = extrusion.origin + np.asarray(S, dtype=float) @ extrusion.frame  # (n1, n2, 3)
        blocks.append(plane[:, :, None, :] + zeta[None, None, :, None] * extrusion.direction)
    return blocks


def extruded_plugin(section, depth="span", default=1.0, sides=(("front", "symmetry"), ("back", "symmetry")), filled=False):
    """The 3D block-set plugin (a module) of the 2D block-set plugin module ``section`` swept
    ``depth`` (a new parameter, default ``default``) along z: each block the section's times
    [0, depth] (on the caps its Coons patch or, ``filled``, its own map, which the section then
    defines on the whole unit square), the section's interfaces and patches with zeta0 and
    zeta1 of every block the patches ``sides`` (name, type); --dims N M K: the section's N M, K
    cells along z, equally spaced. The section's ``mesh_elliptic`` and ``notes`` hooks carry over:
    the 3D mesh is the extrusion of the section's (module docstring)."""
    names = tuple(section.params)
    module = types.ModuleType(f"{section.__name__}_extruded")
    module.__file__ = getattr(section, "__file__", None)
    module.name, module.dim, module.blocks = section.name, 3, tuple(section.blocks)
    module.description = f"{section.description}; extruded {depth} along z"
    module.params = {**section.params, depth: float(default)}
    module.dims_meaning = getattr(section, "dims_meaning", "")

    def own(values):
        return {key: value for key, value in values.items() if key in names}

    def declared(attribute, values):
        value = getattr(section, attribute)
        return value(**own(values)) if callable(value) else value

    def check(values) -> float:
        length = float(values.get(depth, default))
        if not (0.0 < length <= 1e4):
            raise ParameterError(depth, f"{{name}} {length:g}: the extrusion's length must lie in (0, 10000]")
        return length

    def characteristic_length(**values):
        size = section.characteristic_length(**own(values)) if hasattr(section, "characteristic_length") else 1.0
        return float(np.hypot(size, check(values)))

    def block_coords(dims, **values):
        check(values)
        coords = section.block_coords(tuple(dims[:2]), **own(values))
        return {block: [*axes, np.linspace(0.0, 1.0, int(dims[2]) + 1)] for block, axes in coords.items()}

    def boundary(block, points, **values):
        length = check(values)
        if filled:
            return np.column_stack([section.boundary(block, points[:, :2], **own(values)), length * points[:, 2]])
        xy = transfinite(lambda p: section.boundary(block, p, **own(values)), [points[:, 0], points[:, 1]])
        return np.column_stack([xy, length * points[:, 2]])

    module.characteristic_length, module.block_coords, module.boundary = characteristic_length, block_coords, boundary
    module.interfaces = lambda **values: list(declared("interfaces", values))
    faces = {"zeta0": tuple(sides[0]), "zeta1": tuple(sides[1])}
    module.block_patches = lambda **values: {
        block: {**declared("block_patches", values).get(block, {}), **faces} for block in module.blocks
    }
    if hasattr(section, "notes"):
        module.notes = section.notes
    if hasattr(section, "mesh_elliptic"):

        def mesh_elliptic(block_set, tol=None, max_iter=None, progress=None):
            """The section's ``mesh_elliptic``, extruded (``extrude``)."""
            extrusion = extrusion_of(block_set)
            if extrusion is None:
                raise GeometryError(f"geometry '{block_set.name}': the extruded block set is not an extrusion")
            Xs, info = section.mesh_elliptic(section_of(block_set, extrusion), tol=tol, max_iter=max_iter, progress=progress)
            return extrude(extrusion, Xs, block_set.coords[0][2]), info

        module.mesh_elliptic = mesh_elliptic
    return module
