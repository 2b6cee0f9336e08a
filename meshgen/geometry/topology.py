"""A topology file (``meshgen.geometry.topology_file``) as a block-set plugin
(``meshgen.geometry.blocks``): ``topology_module(path)`` returns a module with ``blocks``,
``block_coords``, ``boundary``, ``interfaces`` and ``block_patches``, so every path that meshes,
shows or measures a block set takes a topology file as it takes ``geometries/pipe.py``.

- Interfaces: the block faces with the same vertices (the CGNS Transform then follows from the
  corners, as for any plugin).
- Boundary map of a block: the transfinite interpolation of its edges (straight, arc, polyline,
  spline): X = sum over edges of their blended curves - (dim - 1) sum over corners of theirs,
  which on each face is that face's Coons patch, so two blocks sharing a face see one surface.
  Faces with ``project`` (``meshgen.geometry.topology_project``): their vertices and edges are
  moved onto the surface first, and the map projects the inside of such a face (3D) too.
- Cell counts: per chain of topologically parallel edges (union-find over each block's parallel
  edges; a shared edge joins the chains of its blocks), from ``cells.size`` (the chain's longest
  edge over the size) or a count on one of its edges; ``--param refine=R`` scales them.
- Grading: per chain too (one 1D node distribution, reversed where an edge runs the other way).
- Cyclic pairs: the translation from one patch's vertices to its neighbour's, checked vertex by
  vertex here and node by node after meshing (``meshgen.geometry.cyclic``).
"""

from __future__ import annotations

import types
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry import cube
from meshgen.geometry.cyclic import cyclic_pairs
from meshgen.geometry.topology_file import Topology, is_topology_file, read_topology
from meshgen.geometry.topology_project import projected
from meshgen.methods.clustering import Cluster, clustered_coordinates

__all__ = [
    "TOPOLOGY_DIMS_MEANING",
    "topology_dims",
    "CORNERS",
    "Chains",
    "block_edges",
    "curve",
    "edge_curves",
    "topology_chains",
    "topology_module",
]

# The parametric corner of each vertex of a block, in blockMesh order (2D: the first four, z dropped).
CORNERS = {
    3: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]),
    2: np.array([[0, 0], [1, 0], [1, 1], [0, 1]]),
}
TOPOLOGY_DIMS_MEANING = "not used: the topology file's cells give the counts (--param refine=R scales them)"
GAP = 1e-9  # vertices closer than this (relative to the set's size) are at one point
_CACHE: dict = {}


def _corner(dim: int, point) -> int:
    return int(np.flatnonzero((CORNERS[dim] == np.asarray(point)).all(axis=1))[0])


def block_edges(dim: int) -> list[tuple[int, int, int]]:
    """(axis, corner from, corner to) of the unit cube's edges, each running along +axis."""
    found = []
    for axis in range(dim):
        for low in CORNERS[dim][CORNERS[dim][:, axis] == 0]:
            high = low.copy()
            high[axis] = 1
            found.append((axis, _corner(dim, low), _corner(dim, high)))
    return found


def _face_corners(face: cube.Face) -> list[int]:
    return [int(i) for i in np.flatnonzero(CORNERS[face.dim][:, face.axis] == face.side)]


# ---------------------------------------------------------------------------------------------
# curves


def curve(kind: str, a: np.ndarray, b: np.ndarray, extra=None, where: str = "edge"):
    """The edge from ``a`` to ``b`` as a vectorised map t (N,) in [0, 1] -> (N, dim): ``line``,
    ``arc`` (``extra`` ("through", point) or ("center", point); uniform in angle), ``polyline``
    (uniform in length) or ``spline`` (cubic through the points, uniform in chord length)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if kind == "line":
        return lambda t: a + np.asarray(t, float)[:, None] * (b - a)
    if kind == "arc":
        return _arc(a, b, *extra, where)
    points = np.vstack([a, extra[1], b])
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if np.any(np.diff(chord) <= 0):
        raise GeometryError(f"{where}: two of its points coincide")
    chord /= chord[-1]
    if kind == "polyline":
        return lambda t: np.stack([np.interp(t, chord, points[:, d]) for d in range(points.shape[1])], axis=1)
    return _natural_spline(chord, points)


def _natural_spline(knots: np.ndarray, points: np.ndarray):
    """The natural cubic spline through ``points`` (K, dim) at the increasing ``knots`` (K,), as a
    map t (N,) -> (N, dim) (scipy's CubicSpline with bc_type="natural", without importing
    scipy.interpolate: ~1 s of a command's start). Second derivatives by the Thomas algorithm
    (a loop over the curve's points)."""
    h = np.diff(knots)
    slopes = np.diff(points, axis=0) / h[:, None]
    moments = np.zeros_like(points)
    count = len(knots) - 2  # interior knots: h[i-1] M[i-1] + 2 (h[i-1] + h[i]) M[i] + h[i] M[i+1] = 6 (slope[i] - slope[i-1])
    if count > 0:
        diagonal = 2.0 * (h[:-1] + h[1:])
        rhs = 6.0 * np.diff(slopes, axis=0)
        for i in range(1, count):
            factor = h[i] / diagonal[i - 1]
            diagonal[i] -= factor * h[i]
            rhs[i] -= factor * rhs[i - 1]
        inner = np.zeros_like(rhs)
        inner[-1] = rhs[-1] / diagonal[-1]
        for i in range(count - 2, -1, -1):
            inner[i] = (rhs[i] - h[i + 1] * inner[i + 1]) / diagonal[i]
        moments[1:-1] = inner

    def spline(t):
        t = np.asarray(t, float)
        i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(h) - 1)
        a, b, w = (knots[i + 1] - t)[:, None], (t - knots[i])[:, None], h[i][:, None]
        left, right = moments[i], moments[i + 1]
        return (
            (left * a**3 + right * b**3) / (6 * w) + (points[i] / w - left * w / 6) * a + (points[i + 1] / w - right * w / 6) * b
        )

    return spline


def _arc(a, b, how: str, point, where: str):
    """The circular arc from a to b through ``point`` (or about the centre ``point``)."""
    if how == "center":
        radius = np.linalg.norm(a - point)
        if abs(np.linalg.norm(b - point) - radius) > 1e-6 * radius:
            raise GeometryError(f"{where}: its vertices are at different distances from the center")
        middle = 0.5 * (a + b) - point
        if np.linalg.norm(middle) < 1e-12 * radius:
            raise GeometryError(f"{where}: a half circle about its center: give 'through' instead")
        point = point + radius * middle / np.linalg.norm(middle)
    # The circle through a, point, b: its centre in the plane of the three (barycentric formula).
    u, v = point - a, b - a
    uu, vv, uv = u @ u, v @ v, u @ v
    denominator = 2.0 * (uu * vv - uv * uv)
    if denominator <= 1e-12 * uu * vv:
        raise GeometryError(f"{where}: the point it passes through is on the line between its vertices")
    center = a + (vv * (uu - uv) * u + uu * (vv - uv) * v) / denominator
    radius = float(np.linalg.norm(a - center))
    e1 = (a - center) / radius
    e2 = (point - center) - ((point - center) @ e1) * e1
    e2 /= np.linalg.norm(e2)

    def angle(p):
        return np.arctan2((p - center) @ e2, (p - center) @ e1) % (2 * np.pi)

    end = angle(b)
    end = end if angle(point) < end else end - 2 * np.pi  # the way round that passes the point

    def arc(t):
        theta = np.asarray(t, float)[:, None] * end
        return center + radius * (np.cos(theta) * e1 + np.sin(theta) * e2)

    return arc


def edge_curves(topology: Topology) -> dict:
    """{(i, j): map t -> points from vertex i to vertex j} for every block edge (i < j), straight
    unless the file curves it; GeometryError for a curved edge that no block has."""
    points, names = topology.points, topology.vertex_names
    pairs = {tuple(sorted((int(row[f]), int(row[t])))) for row in topology.blocks for _, f, t in block_edges(topology.dim)}
    curves = {}
    for i, j in pairs:
        curves[i, j] = curve("line", points[i], points[j])
    for (i, j), (kind, *extra) in topology.edges.items():
        where = f"topology file {topology.path}: edge {kind} {names[i]}-{names[j]}"
        if (min(i, j), max(i, j)) not in pairs:
            raise GeometryError(f"{where} is not an edge of any block")
        extra = extra if kind == "arc" else (None, extra[1][::1] if i < j else extra[1][::-1])
        start, end = (i, j) if i < j else (j, i)
        curves[start, end] = curve(kind, points[start], points[end], extra, where)
    return curves


def _length(function) -> float:
    samples = function(np.linspace(0.0, 1.0, 129))
    return float(np.sum(np.linalg.norm(np.diff(samples, axis=0), axis=1)))


# ---------------------------------------------------------------------------------------------
# checks of the blocks against each other


def _check_blocks(topology: Topology) -> tuple[list, dict]:
    """(interfaces as (block a, face a, block b, face b), boundary faces {vertex set: (block,
    face)}) after the checks: left-handed blocks, faces shared by three blocks, faces sharing 3 of
    4 vertices, faces that coincide under different vertex names."""
    dim, points, names = topology.dim, topology.points, topology.vertex_names
    where = f"topology file {topology.path}"
    size = float(np.ptp(points, axis=0).max()) or 1.0
    for name, row in zip(topology.block_names, topology.blocks):
        X = points[row]
        jacobians = []
        for corner in CORNERS[dim]:
            steps = []
            for axis in range(dim):
                other = corner.copy()
                other[axis] = 1 - other[axis]
                steps.append((X[_corner(dim, other)] - X[_corner(dim, corner)]) * (1 if corner[axis] == 0 else -1))
            jacobians.append(np.linalg.det(np.array(steps)))
        if np.sum(jacobians) <= 0:
            raise GeometryError(
                f"{where}: block '{name}' is left-handed (inverted): list its vertices "
                + (
                    "counterclockwise"
                    if dim == 2
                    else "in blockMesh order (the first four counterclockwise seen from the last four)"
                )
            )
    owners: dict = {}
    for block, row in enumerate(topology.blocks):
        for face in cube.faces(dim):
            owners.setdefault(frozenset(int(row[c]) for c in _face_corners(face)), []).append((block, face.name))
    interfaces, boundary = [], {}
    for key, found in owners.items():
        if len(found) > 2:
            said = ", ".join(f"block '{topology.block_names[b]}' {f}" for b, f in found)
            raise GeometryError(f"{where}: the face ({_said(names, key)}) is shared by {len(found)} blocks ({said})")
        if len(found) == 2:
            interfaces.append((*found[0], *found[1]))
        else:
            boundary[key] = found[0]
    keys = list(boundary)
    merged = _merged(points, size)
    for k, first in enumerate(keys):
        for second in keys[k + 1 :]:
            shared = first & second
            (block_a, face_a), (block_b, face_b) = boundary[first], boundary[second]
            said = f"block '{topology.block_names[block_b]}' face {face_b} ({_said(names, second)}) and block '{topology.block_names[block_a]}' face {face_a} ({_said(names, first)})"
            if dim == 3 and len(shared) == 3:
                (p,), (q,) = first - shared, second - shared
                gap = np.linalg.norm(points[p] - points[q])
                raise GeometryError(
                    f"{where}: {said} share 3 of their 4 vertices: '{names[p]}' and '{names[q]}' are {gap:.3g} apart"
                )
            if {merged[v] for v in first} == {merged[v] for v in second}:
                p, q = next((p, q) for p in sorted(first - second) for q in sorted(second - first) if merged[p] == merged[q])
                gap = np.linalg.norm(points[p] - points[q])
                raise GeometryError(
                    f"{where}: {said} coincide but vertices '{names[p]}' and '{names[q]}' (gap {gap:.3g}) are different "
                    "names: give the point one name"
                )
    return interfaces, boundary


def _merged(points: np.ndarray, size: float) -> list[int]:
    """Per vertex, the smallest index of a vertex at the same point (within ``GAP`` of the size)."""
    tolerance = GAP * size
    order = np.argsort(points[:, 0], kind="stable")
    ordered = points[order]
    reach = np.searchsorted(ordered[:, 0], ordered[:, 0] + tolerance, side="right")
    pairs = []
    for a in range(len(points)):  # a loop over the file's vertices, each against those within tolerance in x
        near = a + 1 + np.flatnonzero(np.linalg.norm(ordered[a + 1 : reach[a]] - ordered[a], axis=1) <= tolerance)
        pairs += [tuple(sorted((int(order[a]), int(order[b])))) for b in near]
    label = np.arange(len(points))
    for i, j in sorted(pairs):
        label[label == label[j]] = label[i]
    return [int(x) for x in label]


def _said(names, vertices) -> str:
    return " ".join(names[v] for v in sorted(vertices))


# ---------------------------------------------------------------------------------------------
# chains of parallel edges: counts and node distributions


class Chains:
    """Union-find over the block edges (i, j), i < j, with the orientation of each edge relative
    to its chain's root: the block axes along one chain share their count and nodes."""

    def __init__(self, topology: Topology):
        self.topology = topology
        self.parent: dict = {}
        self.twisted: set = set()
        for row in topology.blocks:
            edges = block_edges(topology.dim)
            for axis in range(topology.dim):
                along = [(int(row[f]), int(row[t])) for a, f, t in edges if a == axis]
                for first, second in zip(along, along[1:]):
                    self.union(_key(*first), _key(*second), _sign(*first) * _sign(*second))

    def find(self, edge) -> tuple[tuple, int]:
        """(root, orientation of ``edge`` relative to the root: +1 or -1)."""
        root, sign = self.parent.setdefault(edge, (edge, 1))
        if root == edge:
            return edge, 1
        top, further = self.find(root)
        self.parent[edge] = (top, sign * further)
        return top, sign * further

    def union(self, a, b, relation: int) -> None:
        (ra, sa), (rb, sb) = self.find(a), self.find(b)
        if ra == rb:
            if sa * sb != relation:
                self.twisted.add(ra)
            return
        self.parent[rb] = (ra, sa * sb * relation)
        if rb in self.twisted:
            self.twisted.add(ra)

    def members(self) -> dict:
        found: dict = {}
        for edge in list(self.parent):
            found.setdefault(self.find(edge)[0], []).append(edge)
        return found

    def text(self, root) -> str:
        names = self.topology.vertex_names
        edges = sorted(self.members()[self.find(root)[0]])
        shown = ", ".join(f"{names[i]}-{names[j]}" for i, j in edges[:6])
        return shown + (f", ... ({len(edges)} edges)" if len(edges) > 6 else "")


def _key(i: int, j: int) -> tuple[int, int]:
    return (i, j) if i < j else (j, i)


def _sign(i: int, j: int) -> int:
    return 1 if i < j else -1


def topology_chains(topology: Topology, curves: dict, refine: float = 1.0) -> tuple[Chains, dict]:
    """(the chains, {root: node coordinates (n + 1,) in [0, 1] along the root edge's i -> j})."""
    chains = Chains(topology)
    names, where = topology.vertex_names, f"topology file {topology.path}"
    members = chains.members()
    counts: dict = {}
    for i, j, n in topology.counts:
        root = chains.find(_key(i, j))[0]
        if root in counts and counts[root][0] != n:
            a, b, m = counts[root][1]
            raise GeometryError(
                f"{where}: cells: the chain of parallel edges {chains.text(root)} is given {m} cells (at {names[a]}-{names[b]}) "
                f"and {n} (at {names[i]}-{names[j]})"
            )
        counts[root] = (n, (i, j, n))
    lengths = {root: [_length(curves[e]) for e in edges] for root, edges in members.items()}
    given = {}
    for root in members:
        if root in counts:
            given[root] = counts[root][0]
        elif topology.size is not None:
            given[root] = int(np.ceil(max(lengths[root]) / topology.size - 1e-9))
        else:
            raise GeometryError(
                f"{where}: cells: the chain of parallel edges {chains.text(root)} has no cell count: give cells: size, or a "
                "count on one of its edges"
            )
    refined = {root: max(1, int(round(n * refine))) for root, n in given.items()}
    graded = _grading(topology, chains, lengths, refined, explicit=set(counts))
    nodes = {root: graded.get(root, np.linspace(0.0, 1.0, refined[root] + 1)) for root in members}
    return chains, nodes


def _grading(topology, chains: Chains, lengths: dict, counts: dict, explicit: set) -> dict:
    """{root: graded nodes} of the chains that ``grading`` names (ratios, first-cell heights)."""
    where = f"topology file {topology.path}"
    graded: dict = {}
    for i, j, ratio in topology.ratios:
        root, sign = chains.find(_key(i, j))
        sign *= _sign(i, j)  # +1: a -> b runs along the root
        n = counts[root]
        growth = ratio ** (1.0 / max(n - 1, 1))
        widths = growth ** np.arange(n, dtype=float)
        nodes = np.concatenate([[0.0], np.cumsum(widths)]) / np.sum(widths)
        nodes = nodes if sign > 0 else 1.0 - nodes[::-1]
        if root in graded and not np.allclose(graded[root], nodes):
            raise GeometryError(f"{where}: grading: the chain {chains.text(root)} is given two different ratios")
        graded[root] = nodes
    if not topology.first_cell:
        return graded
    interfaces, boundary = _check_blocks(topology)
    faces = _patch_faces(topology, boundary)
    walls: dict = {}
    for (block, face_name), (patch, _) in faces.items():
        if patch not in topology.first_cell:
            continue
        face = cube.face_named(face_name, topology.dim)
        row = topology.blocks[block]
        low = np.zeros(topology.dim, int)
        high = low.copy()
        high[face.axis] = 1
        i, j = int(row[_corner(topology.dim, low)]), int(row[_corner(topology.dim, high)])
        root, sign = chains.find(_key(i, j))
        side = face.side if sign * _sign(i, j) > 0 else 1 - face.side
        walls.setdefault(root, {})[side] = min(walls.get(root, {}).get(side, np.inf), topology.first_cell[patch])
    for root, sides in walls.items():
        if root in graded:
            raise GeometryError(f"{where}: grading: the chain {chains.text(root)} has both a ratio and a first-cell height")
        if root in chains.twisted:
            raise GeometryError(f"{where}: grading: the chain {chains.text(root)} runs both ways round: it cannot be graded")
        first = min(sides.values()) / float(np.mean(lengths[root]))
        side = "both" if len(sides) == 2 else ("min" if 0 in sides else "max")
        n = counts[root]
        while True:
            if first >= 1.0 / n:
                raise GeometryError(
                    f"{where}: grading: a first cell of {min(sides.values()):g} is not below the uniform cells of the chain "
                    f"{chains.text(root)} ({n} cells): give a smaller height or fewer cells"
                )
            try:
                nodes = clustered_coordinates(n, Cluster(0, side, first_height=first))
            except MeshgenError as exc:
                raise GeometryError(f"{where}: grading of the chain {chains.text(root)}: {exc}") from None
            widths = np.diff(nodes)
            growth = float(np.max(np.maximum(widths[1:] / widths[:-1], widths[:-1] / widths[1:]))) if n > 1 else 1.0
            if topology.growth is None or growth <= topology.growth * (1 + 1e-9):
                break
            if root in explicit:
                raise GeometryError(
                    f"{where}: grading: the chain {chains.text(root)} needs a growth of {growth:.3g} (above growth "
                    f"{topology.growth:g}) with its {n} cells: give more cells or a larger growth"
                )
            n += 1
        graded[root] = nodes
    return graded


def _patch_faces(topology: Topology, boundary: dict) -> dict:
    """{(block, face name): (patch, type)} for every boundary face; GeometryError for a patch face
    that is no block face, one between blocks, or one listed twice."""
    names, where = topology.vertex_names, f"topology file {topology.path}"
    faces = {}
    interface_faces = set()
    for row in topology.blocks:
        for face in cube.faces(topology.dim):
            key = frozenset(int(row[c]) for c in _face_corners(face))
            if key not in boundary:
                interface_faces.add(key)
    for patch, (kind, listed) in topology.patches.items():
        for vertices in listed:
            key = frozenset(vertices)
            if key in interface_faces:
                raise GeometryError(f"{where}: patch '{patch}': the face ({_said(names, key)}) is between two blocks")
            if key not in boundary:
                raise GeometryError(f"{where}: patch '{patch}': ({_said(names, key)}) is not a face of any block")
            if boundary[key] in faces:
                raise GeometryError(
                    f"{where}: the face ({_said(names, key)}) is in patches '{faces[boundary[key]][0]}' and '{patch}'"
                )
            faces[boundary[key]] = (patch, kind)
    for owner in boundary.values():
        faces.setdefault(owner, topology.default_patch)
    unknown = [p for p in topology.first_cell if p not in {name for name, _ in faces.values()}]
    if unknown:
        known = sorted({name for name, _ in faces.values()})
        raise GeometryError(f"{where}: grading: first_cell names no patch '{unknown[0]}' (patches: {', '.join(known)})")
    return faces


# ---------------------------------------------------------------------------------------------
# the plugin module


def _boundary_map(topology: Topology, curves: dict, block: int, points: np.ndarray):
    """The block's map of the unit cube (N, dim) -> (N, dim): its edges' transfinite interpolation
    (``points``: the vertices), the inside of a projected face (3D) projected onto its surface."""
    dim, row = topology.dim, topology.blocks[block]
    corners = points[row]
    onto = []
    for face in cube.faces(dim) if dim == 3 else ():
        name = topology.projections.get(frozenset(int(row[c]) for c in _face_corners(face)))
        if name is not None:
            onto.append((face.axis, face.side, topology.surfaces[name].project))
    pieces = []
    for axis, f, t in block_edges(dim):
        i, j = int(row[f]), int(row[t])
        fixed = [(d, int(CORNERS[dim][f][d])) for d in range(dim) if d != axis]
        pieces.append((axis, fixed, curves[_key(i, j)], i > j))

    def boundary(points):
        points = np.asarray(points, dtype=float)
        weights = [np.stack([1.0 - points[:, d], points[:, d]]) for d in range(dim)]  # (2, N) per axis
        result = np.zeros_like(points)
        for axis, fixed, function, reverse in pieces:
            weight = np.prod([weights[d][side] for d, side in fixed], axis=0)
            t = points[:, axis]
            result += weight[:, None] * function(1.0 - t if reverse else t)
        for corner, X in zip(CORNERS[dim], corners):
            weight = np.prod([weights[d][int(corner[d])] for d in range(dim)], axis=0)
            result -= (dim - 1) * weight[:, None] * X
        for axis, side, project in onto:
            others = np.delete(points, axis, axis=1)
            inside = (points[:, axis] == side) & np.all((others > 0) & (others < 1), axis=1)
            if inside.any():
                result[inside] = project(result[inside])
        return result

    return boundary


def topology_dims(spec) -> tuple[int, ...] | None:
    """The placeholder ``--dims`` of a topology file (ones, one per axis; its ``cells`` give the
    counts), or None when ``spec`` is not one."""
    return (1,) * topology_module(spec).dim if isinstance(spec, str) and is_topology_file(spec) else None


def topology_module(path) -> types.ModuleType:
    """The block-set plugin module of the topology file ``path`` (module docstring), checked;
    kept per (path, size, modification time)."""
    path = Path(path)
    status = path.stat()
    key = (str(path.resolve()), status.st_size, status.st_mtime_ns)
    if key in _CACHE:
        return _CACHE[key]
    topology = read_topology(path)
    interfaces, boundary = _check_blocks(topology)
    faces = _patch_faces(topology, boundary)
    curves = edge_curves(topology)
    topology_chains(topology, curves)  # every chain has a count and consistent grading: fail now
    points, projected_curves = projected(topology, curves) if topology.surfaces else (topology.points, curves)
    dim, block_names = topology.dim, topology.block_names
    maps = [_boundary_map(topology, projected_curves, b, points) for b in range(len(block_names))]
    module = types.ModuleType(f"meshgen_topology_{topology.name}")
    module.__file__ = str(path)
    module.name, module.dim, module.description = topology.name, dim, topology.description
    module.params = {"refine": 1.0}
    module.blocks = tuple(block_names)
    module.dims_meaning = TOPOLOGY_DIMS_MEANING
    module.interfaces = [(block_names[a], fa, block_names[b], fb) for a, fa, b, fb in interfaces]
    patches: dict = {}
    for (block, face), entry in faces.items():
        patches.setdefault(block_names[block], {})[face] = entry
    module.block_patches = patches
    module.cyclic = cyclic_pairs(topology)
    module.face_surfaces = {  # projected faces whose nodes slide on their surface (``slide: true``)
        (name, face.name): topology.surfaces[topology.projections[key]].project
        for name, row in zip(block_names, topology.blocks)
        for face in cube.faces(dim)
        if (key := frozenset(int(row[c]) for c in _face_corners(face))) in topology.sliding
    }
    module.topology = topology
    size = float(np.linalg.norm(np.ptp(topology.points, axis=0)))

    def characteristic_length(refine=1.0):
        return size

    def block_coords(dims, refine=1.0):
        """Per block, its node coordinates per axis from its chains (``dims`` is not used)."""
        if not refine > 0:
            raise GeometryError(f"topology file {path}: --param refine must be positive, got {refine:g}")
        chains, nodes = topology_chains(topology, curves, refine)
        coords = {}
        for name, row in zip(block_names, topology.blocks):
            axes = []
            for axis in range(dim):
                _, f, t = next(e for e in block_edges(dim) if e[0] == axis)
                i, j = int(row[f]), int(row[t])
                root, sign = chains.find(_key(i, j))
                values = nodes[root]
                axes.append(values if sign * _sign(i, j) > 0 else 1.0 - values[::-1])
            coords[name] = axes
        return coords

    def boundary_of(block, points, refine=1.0):
        return maps[block_names.index(block)](points)

    module.characteristic_length = characteristic_length
    module.block_coords = block_coords
    module.boundary = boundary_of
    _CACHE[key] = module
    return module
