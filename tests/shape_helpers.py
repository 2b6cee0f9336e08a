"""Test shapes built by the tests themselves: random four-cornered surface patches, a bent
rectangular duct written as a multi-solid ASCII STL, a twisted loft exported to STEP by gmsh,
triangulated bends (a polygon turned about an axis, capped)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def random_patch(triangles: int, seed: int):
    """A random four-cornered patch of about ``triangles`` triangles: the Delaunay triangulation
    of random points in the unit disk (a share of them on its circle) with ears added on its boundary, lifted onto a random bumpy
    height field with an in-plane warp, randomly oriented. Returns (vertices (n, 3), triangles
    (m, 3), corners: four boundary vertex indices in boundary order)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    n_points = triangles // 2 + 2
    n_circle = max(int(8 * np.sqrt(n_points)), 12)
    angles = np.sort(rng.uniform(0.0, 2 * np.pi, n_circle))
    radius = np.sqrt(rng.uniform(0.0, 0.97**2, n_points - n_circle))
    theta = rng.uniform(0.0, 2 * np.pi, n_points - n_circle)
    xy = np.concatenate(
        [np.column_stack([np.cos(angles), np.sin(angles)]), np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])]
    )
    tri = Delaunay(xy).simplices
    d1, d2 = xy[tri[:, 1]] - xy[tri[:, 0]], xy[tri[:, 2]] - xy[tri[:, 0]]
    area = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    tri = np.where((area < 0)[:, None], tri[:, ::-1], tri)
    # Ears: a new vertex just outside some boundary edges (a, b) and the triangle (a, new, b),
    # whose three vertices all lie on the boundary: its edge a-b joins two vertices of one side.
    eared = rng.choice(n_circle, n_circle // 8, replace=False)
    mid = angles[eared] + 0.5 * (np.append(angles, angles[0] + 2 * np.pi)[eared + 1] - angles[eared])
    ear_xy = 1.01 * np.column_stack([np.cos(mid), np.sin(mid)])
    new = len(xy) + np.arange(len(eared))
    tri = np.concatenate([tri, np.column_stack([eared, new, (eared + 1) % n_circle])])
    xy = np.concatenate([xy, ear_xy])
    boundary_order = np.concatenate([np.arange(n_circle), new])[np.argsort(np.concatenate([angles, np.mod(mid, 2 * np.pi)]))]
    a, b, c = rng.uniform(0.5, 3.0, 3)
    warp = 0.15 * np.column_stack([np.sin(a * xy[:, 1]), np.sin(b * xy[:, 0])])
    height = 0.4 * np.sin(a * xy[:, 0] + 1.0) * np.cos(b * xy[:, 1]) + 0.3 * np.sin(c * (xy[:, 0] + xy[:, 1]))
    vertices = np.column_stack([xy + warp, height])
    if rng.random() < 0.5:
        tri = tri[:, ::-1]
    quarter = len(boundary_order) // 4
    picks = rng.integers(0, quarter, 4) + np.arange(4) * quarter
    corners = boundary_order[picks]
    return vertices, tri, corners


DUCT_NAMES = ("inlet", "outlet", "inner", "outer", "floor", "ceiling")


def duct_point(theta, a, b, bend_radius=2.0):
    """The bent duct's point at bend angle ``theta`` (0 .. pi/2), radial offset ``a`` from the
    bend's centre line and height ``b``: ((R + a) cos theta, b, (R + a) sin theta)."""
    r = bend_radius + a
    return np.stack([r * np.cos(theta), b, r * np.sin(theta)], axis=-1)


def duct_surface(n_bend=24, n_width=8, n_height=6, width=1.0, height=0.6, seed=0):
    """A 90 degree bend of a width x height rectangle as a closed triangulated surface with
    outward normals: vertices (n, 3), triangles (m, 3), labels (m,) indices into DUCT_NAMES. The
    lattice of each face is jittered in the surface's own parameters (so every vertex stays on the
    exact surface) and each quad is split along a random diagonal."""
    rng = np.random.default_rng(seed)
    shape = (n_bend, n_width, n_height)
    lattice, triangles, labels = [], [], []
    offset = 0
    # faces: (axis, side, label) with axis 0 = bend angle, 1 = width, 2 = height
    for axis, side, label in ((0, 0, 0), (0, 1, 1), (1, 0, 2), (1, 1, 3), (2, 0, 4), (2, 1, 5)):
        p, q = (d for d in range(3) if d != axis)
        u, v = np.meshgrid(np.arange(shape[p] + 1), np.arange(shape[q] + 1), indexing="ij")
        nodes = np.empty(u.shape + (3,), dtype=np.int64)
        nodes[..., axis], nodes[..., p], nodes[..., q] = side * shape[axis], u, v
        index = np.arange(u.size).reshape(u.shape) + offset
        a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
        diagonal = rng.random(len(a)) < 0.5
        first = np.where(diagonal[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
        second = np.where(diagonal[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
        tri = np.concatenate([first, second])
        # (p, q, axis) cyclic -> the lattice normal is +axis: outward on side 1
        cyclic = (p, q, axis) in ((1, 2, 0), (2, 0, 1), (0, 1, 2))
        tri = tri if cyclic == bool(side) else tri[:, ::-1]
        triangles.append(tri)
        labels.append(np.full(len(tri), label))
        lattice.append(nodes.reshape(-1, 3))
        offset += u.size
    lattice = np.concatenate([*lattice])
    unique, inverse = np.unique(lattice, axis=0, return_inverse=True)
    triangles = inverse.reshape(-1)[np.concatenate(triangles)]
    t = unique / np.array(shape, dtype=float)
    inside = (t > 0) & (t < 1)
    spacing = 1.0 / np.array(shape, dtype=float)
    t = t + inside * rng.uniform(-0.3, 0.3, t.shape) * spacing
    vertices = duct_point(0.5 * np.pi * t[:, 0], width * (t[:, 1] - 0.5), height * (t[:, 2] - 0.5))
    # orientation: theta and the (width, height) pair... fix by the enclosed volume's sign
    p, q, r = (vertices[triangles[:, k]] for k in range(3))
    if np.einsum("ij,ij->i", p, np.cross(q, r)).sum() < 0:
        triangles = triangles[:, ::-1]
    return vertices, triangles, np.concatenate(labels)


def write_ascii_stl(path, vertices, triangles, labels=None, names=DUCT_NAMES):
    """An ASCII STL with one ``solid NAME`` block per label (all in one block without labels);
    coordinates written exactly (17 significant digits)."""
    blocks = []
    groups = [(names[k], triangles[labels == k]) for k in range(len(names))] if labels is not None else [("surface", triangles)]
    for name, tris in groups:
        lines = [f"solid {name}"]
        for tri in tris:
            lines.append("  facet normal 0 0 0\n    outer loop")
            lines += [f"      vertex {x:.17g} {y:.17g} {z:.17g}" for x, y, z in vertices[tri]]
            lines.append("    endloop\n  endfacet")
        lines.append(f"endsolid {name}")
        blocks.append("\n".join(lines))
    path.write_text("\n".join(blocks) + "\n")
    return path


def turned_outline(kind: str) -> np.ndarray:
    """The (x, z) outline (K, 2), counterclockwise, of a triangulated bend's cap in the plane
    y = 0: ``torus`` a disk of radius 0.5 centred 2 from the z axis (64 sides), ``pentagon`` a
    regular pentagon of circumradius 0.5 centred there (the CAD ``bent_pentagon``'s), ``hole`` a
    disk of radius 0.2 centred there (the torus's hole, for a bent pipe's wall)."""
    count, radius = {"torus": (64, 0.5), "pentagon": (5, 0.5), "hole": (64, 0.2)}[kind]
    angles = np.pi / 2 + 2 * np.pi * np.arange(count) / count
    return np.column_stack([2.0 + radius * np.cos(angles), radius * np.sin(angles)])


def turned_surface(
    outline,
    angle: float,
    sections: int,
    lift: float = 0.0,
    taper: float = 0.0,
    bump: float = 0.0,
    offset: float = 0.0,
    seed=None,
    hole=None,
):
    """A closed triangulated bend: the polygon ``outline`` (K, 2) of (x, z) points in the plane
    y = 0 turned by ``angle`` radians about the z axis in ``sections`` equal steps (rings of K
    vertices, each quadrilateral between two rings two triangles), each end capped by a fan from
    the ring's centroid, or with ``hole`` (K, 2, inside the outline, as many points) by the
    quadrilaterals between the two loops; triangles turned outward. Bad bends: ``lift`` raises
    ring k by lift k / sections along z (a helix: the caps are no rotation of each other),
    ``taper`` scales ring k about the outline's centroid by 1 + taper k / sections, ``bump`` pushes
    the middle ring's vertices that far from the axis (its triangles leave the surface the
    outline sweeps). ``offset`` puts the cap in the plane y = offset instead (the axis off the
    cap's plane: the quadrilaterals between rings are not planar); ``seed``: each quadrilateral
    cut along either diagonal at random. Returns (vertices (n, 3), triangles (m, 3)), lengths as
    given."""
    outline = np.asarray(outline, dtype=float)
    K, S = len(outline), int(sections)
    share = np.arange(S + 1) / S
    centre = outline.mean(axis=0)
    cos, sin = np.cos(angle * share)[:, None], np.sin(angle * share)[:, None]
    rng = np.random.default_rng(seed)

    def rings(loop):  # (S + 1, K, 3): the loop turned step by step
        scaled = centre + (1.0 + taper * share)[:, None, None] * (loop - centre)
        x = scaled[..., 0] + bump * (np.arange(S + 1) == S // 2)[:, None]
        return np.stack([x * cos - offset * sin, x * sin + offset * cos, scaled[..., 1] + lift * share[:, None]], axis=-1)

    k, i = (a.ravel() for a in np.meshgrid(np.arange(S), np.arange(K), indexing="ij"))

    def sides(start):  # the quadrilaterals between rings of the loop whose vertices start at ``start``
        a, b = start + k * K + i, start + k * K + (i + 1) % K
        c, d = b + K, a + K
        other = rng.random(len(a)) < 0.5 if seed is not None else np.zeros(len(a), dtype=bool)
        return np.concatenate(
            [
                np.where(other[:, None], np.column_stack([a, b, d]), np.column_stack([a, b, c])),
                np.where(other[:, None], np.column_stack([b, c, d]), np.column_stack([a, c, d])),
            ]
        )

    ring, n = np.arange(K), (S + 1) * K
    if hole is None:
        turned = rings(outline)
        vertices = np.concatenate([turned.reshape(-1, 3), turned[[0, -1]].mean(axis=1)])
        first, last = np.full(K, n), np.full(K, n + 1)
        caps = [np.column_stack([first, (ring + 1) % K, ring]), np.column_stack([last, S * K + ring, S * K + (ring + 1) % K])]
        triangles = np.concatenate([sides(0), *caps])
    else:
        vertices = np.concatenate([rings(outline).reshape(-1, 3), rings(np.asarray(hole, dtype=float)).reshape(-1, 3)])
        caps = []
        for step, turn in ((0, False), (S, True)):
            o0, o1 = step * K + ring, step * K + (ring + 1) % K
            strip = np.concatenate([np.column_stack([o0, n + o1, o1]), np.column_stack([o0, n + o0, n + o1])])
            caps.append(strip[:, ::-1] if turn else strip)
        triangles = np.concatenate([sides(0), sides(n)[:, ::-1], *caps])
    p, q, r = (vertices[triangles[:, m]] for m in range(3))
    if np.einsum("ij,ij->i", p, np.cross(q, r)).sum() < 0:
        triangles = triangles[:, ::-1]
    return vertices, triangles


def surface_volume(vertices, triangles) -> float:
    """The volume (length^3) a closed, outward-oriented triangulated surface encloses, by the
    divergence theorem over its triangles."""
    p, q, r = (vertices[triangles[:, n]] for n in range(3))
    return float(np.einsum("ij,ij->i", p, np.cross(q, r)).sum() / 6.0)


def write_surface(path, vertices, triangles):
    """The surface written to ``path`` by its extension: ``.stl`` binary (float32, trimesh), ``.obj``
    (trimesh, 17 digits), ``.ply`` (trimesh, binary float32); ``.ascii.stl`` an exact ASCII STL."""
    path = Path(path)
    if path.name.endswith(".ascii.stl"):
        return write_ascii_stl(path, vertices, triangles)
    import trimesh

    mesh = trimesh.Trimesh(vertices, triangles, process=False)
    if path.suffix == ".obj":
        path.write_text(trimesh.exchange.obj.export_obj(mesh, digits=17))
    else:
        mesh.export(path)
    return path


DUCT_CORNERS = [(t, a, b) for t in (0.0, 0.5 * np.pi) for a in (-0.5, 0.5) for b in (-0.3, 0.3)]


def distance_to_triangles(points, vertices, triangles) -> np.ndarray:
    """Distance (N,) from each point to a triangulated surface, by VTK's cell locator (an
    implementation independent of meshgen's)."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    poly = vtk.vtkPolyData()
    vtk_points = vtk.vtkPoints()
    vtk_points.SetData(numpy_to_vtk(np.ascontiguousarray(vertices, dtype=float), deep=True))
    poly.SetPoints(vtk_points)
    cells = vtk.vtkCellArray()
    offsets = np.arange(0, 3 * len(triangles) + 1, 3, dtype=np.int64)
    connectivity = np.ascontiguousarray(triangles, dtype=np.int64).ravel()
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True), numpy_to_vtkIdTypeArray(connectivity, deep=True))
    poly.SetPolys(cells)
    locator = vtk.vtkCellLocator()
    locator.SetDataSet(poly)
    locator.BuildLocator()
    closest, cell, sub, dist2 = [0.0, 0.0, 0.0], vtk.mutable(0), vtk.mutable(0), vtk.mutable(0.0)
    out = np.empty(len(points))
    for n, point in enumerate(np.asarray(points, dtype=float)):
        locator.FindClosestPoint(point.tolist(), closest, cell, sub, dist2)
        out[n] = np.sqrt(float(dist2))
    return out


def write_twisted_loft(path, solids: int = 1):
    """A loft through three rectangles, each turned and shifted (curved, twisted B-spline sides,
    flat ends), built with gmsh's OCC kernel and written to ``path`` (.step, .iges, .brep).
    ``solids=2`` writes a second, separate box beside it. Returns OCC's volume of the loft."""
    import math

    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    previous = gmsh.model.getCurrent() if not started else None
    gmsh.model.add(f"loft-{path.name}")
    occ = gmsh.model.occ

    def rectangle(z, w, h, angle, dx):
        c, s = math.cos(angle), math.sin(angle)
        points = [
            occ.addPoint(c * x - s * y + dx, s * x + c * y, z)
            for x, y in ((-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2))
        ]
        return occ.addWire([occ.addLine(points[k], points[(k + 1) % 4]) for k in range(4)])

    wires = [
        rectangle(0.0, 2.0, 1.0, 0.0, 0.0),
        rectangle(1.5, 1.4, 0.8, math.radians(35), 0.3),
        rectangle(3.0, 1.8, 1.0, math.radians(70), 0.0),
    ]
    loft = occ.addThruSections(wires, makeSolid=True, makeRuled=False)
    if solids == 2:
        occ.addBox(5, 0, 0, 1, 1, 1)
    occ.synchronize()
    volume = occ.getMass(3, loft[0][1])
    from meshgen.geometry.shapes.cad import quiet_stdout

    with quiet_stdout():  # OCC's writers print statistics to the process's stdout
        gmsh.write(str(path))
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    elif previous:
        gmsh.model.setCurrent(previous)
    return volume


def distance_to_cad(points, path) -> np.ndarray:
    """Distance (N,) from each point to the nearest face of the CAD file ``path``, by gmsh's own
    closest point on each face's surface (a model of its own, read afresh)."""
    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    previous = None if started else gmsh.model.getCurrent()
    gmsh.model.add(f"check-{path.name}")
    gmsh.model.occ.importShapes(str(path))
    gmsh.model.occ.synchronize()
    flat = np.asarray(points, dtype=float).ravel().tolist()
    best = np.full(len(points), np.inf)
    for _, tag in gmsh.model.getEntities(2):
        closest, _ = gmsh.model.getClosestPoint(2, tag, flat)
        best = np.minimum(best, np.linalg.norm(np.array(closest).reshape(-1, 3) - points, axis=1))
    vertices = np.array([gmsh.model.getValue(0, tag, []) for _, tag in gmsh.model.getEntities(0)])
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    elif previous:
        gmsh.model.setCurrent(previous)
    return best, vertices


def enclosed_volume(X) -> float:
    """The volume inside the boundary quads of a node array X (n1+1, n2+1, n3+1, 3), each quad as
    two triangles, by the divergence theorem; sign from the orientation of the first quad
    turned outward by the mesh's index order (positive for a right-handed mesh)."""
    total = 0.0
    for axis in range(3):
        for side, sign in ((0, -1.0), (-1, 1.0)):
            face = np.take(X, side, axis=axis)  # (m, n, 3), the two other axes in increasing order
            a, b, c, d = face[:-1, :-1], face[1:, :-1], face[1:, 1:], face[:-1, 1:]
            orient = sign * (1.0 if axis != 1 else -1.0)
            for p, q, r in ((a, b, c), (a, c, d)):
                total += orient * np.einsum("...i,...i->...", p, np.cross(q, r)).sum() / 6.0
    return float(total)


def voxel_surface(cells):
    """The closed boundary of a union of unit cubes (``cells``: integer (i, j, k) triples): every
    cube face not shared by two cubes, as two triangles with the outward normal. Returns vertices
    (n, 3), triangles (m, 3) and the outward normal axis and sign of each triangle (m, 2)."""
    cells = {tuple(c) for c in cells}
    quads, normals = [], []
    for cell in cells:
        for axis in range(3):
            for sign in (-1, 1):
                neighbour = list(cell)
                neighbour[axis] += sign
                if tuple(neighbour) in cells:
                    continue
                p, q = (axis + 1) % 3, (axis + 2) % 3  # (p, q, axis) cyclic: p x q = +axis
                base = np.array(cell, dtype=float)
                base[axis] += 1 if sign > 0 else 0
                corners = []
                for dp, dq in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    point = base.copy()
                    point[p] += dp
                    point[q] += dq
                    corners.append(point)
                quads.append(corners if sign > 0 else corners[::-1])
                normals.append((axis, sign))
    points = np.array(quads).reshape(-1, 3)
    vertices, inverse = np.unique(points, axis=0, return_inverse=True)
    quads = inverse.reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return vertices, triangles, np.concatenate([normals, normals])


SWEEP_SOLIDS = ("cylinder", "hole", "fillet", "pentagon", "wedge", "bend", "bent_pentagon", "tube", "wing", "loft")


def write_sweep_solid(kind: str, path) -> float:
    """A swept solid built with gmsh's OCC kernel, written to ``path`` (.step): ``cylinder``
    (radius 0.5, length 2 along z), ``hole`` (that cylinder with a coaxial hole of radius 0.2),
    ``fillet`` (a 1 x 1 x 2 box whose edge along z at x = y = 0 is filleted with radius 0.3: its
    faces z = 0 and z = 2 are the caps), ``pentagon`` (a regular pentagon of circumradius 1 moved
    1.5 along z), ``wedge`` (gmsh's right-angled wedge 1 x 1, 2 long in z), ``bend`` (a disk of
    radius 0.5 centred 2 from the z axis turned 90 degrees about it) or ``bent_pentagon`` (a regular
    pentagon of circumradius 0.5 centred 2 from the z axis turned 120 degrees about it) or
    ``tube`` (a square tube: a 1 x 1 x 3 box less a 0.4 x 0.4 one along its axis) or ``wing`` (a
    NACA 0012 section of chord 1 with a sharp trailing edge: two splines through 61 points each,
    upper and lower, meeting with a vertical tangent at the leading edge; extruded 1 along z) or
    ``loft`` (a ruled loft, ``addThruSections``, from a circle of radius 0.5 at z = 0, four arcs
    from -45 degrees, to a 0.8 x 0.8 square at z = 2, its corners at the arcs' ends' angles). Returns OCC's volume."""
    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    previous = gmsh.model.getCurrent() if not started else None
    gmsh.model.add(f"sweep-{kind}-{path.name}")
    occ = gmsh.model.occ
    if kind in ("cylinder", "hole"):
        solid = occ.addCylinder(0, 0, 0, 0, 0, 2, 0.5)
        if kind == "hole":
            solid = occ.cut([(3, solid)], [(3, occ.addCylinder(0, 0, 0, 0, 0, 2, 0.2))])[0][0][1]
    elif kind == "fillet":
        box = occ.addBox(0, 0, 0, 1, 1, 2)
        occ.synchronize()
        edge = next(
            tag
            for _, tag in gmsh.model.getBoundary(
                gmsh.model.getBoundary([(3, box)], oriented=False), combined=False, oriented=False
            )
            if np.allclose(occ.getBoundingBox(1, abs(tag)), (0, 0, 0, 0, 0, 2), atol=1e-6)
        )
        solid = occ.fillet([box], [abs(edge)], [0.3])[0][1]
    elif kind == "pentagon":
        angles = np.pi / 2 + 2 * np.pi * np.arange(5) / 5
        points = [occ.addPoint(np.cos(a), np.sin(a), 0) for a in angles]
        loop = occ.addCurveLoop([occ.addLine(points[k], points[(k + 1) % 5]) for k in range(5)])
        extruded = occ.extrude([(2, occ.addPlaneSurface([loop]))], 0, 0, 1.5)
        solid = next(tag for dim, tag in extruded if dim == 3)
    elif kind == "wedge":
        solid = occ.addWedge(0, 0, 0, 1, 1, 2)
    elif kind == "tube":
        solid = occ.cut([(3, occ.addBox(0, 0, 0, 1, 1, 3))], [(3, occ.addBox(0.3, 0.3, 0, 0.4, 0.4, 3))])[0][0][1]
    elif kind == "wing":
        x = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, 61)))[::-1]  # trailing edge to leading edge
        y = 0.6 * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)
        upper = [occ.addPoint(a, b, 0) for a, b in zip(x, y)]
        lower = [upper[-1]] + [occ.addPoint(a, -b, 0) for a, b in zip(x[::-1][1:-1], y[::-1][1:-1])] + [upper[0]]
        down = np.zeros((61, 3))  # the tangents: none but a vertical one at the leading edge
        down[-1, 1] = -1.0
        curves = [
            occ.addSpline(upper, tangents=down.ravel().tolist()),
            occ.addSpline(lower, tangents=down[::-1].ravel().tolist()),
        ]
        surface = occ.addPlaneSurface([occ.addCurveLoop(curves)])
        solid = next(tag for dim, tag in occ.extrude([(2, surface)], 0, 0, 1.0) if dim == 3)
    elif kind == "loft":  # the circle in four arcs, from -45 degrees, as the square's corners
        angles = np.pi / 4 * (2 * np.arange(4) - 1)
        ring = [occ.addPoint(0.5 * np.cos(a), 0.5 * np.sin(a), 0) for a in angles]
        centre = occ.addPoint(0, 0, 0)
        circle = occ.addCurveLoop([occ.addCircleArc(ring[k], centre, ring[(k + 1) % 4]) for k in range(4)])
        corners = [occ.addPoint(0.4 * np.sign(np.cos(a)), 0.4 * np.sign(np.sin(a)), 2) for a in angles]
        square = occ.addCurveLoop([occ.addLine(corners[k], corners[(k + 1) % 4]) for k in range(4)])
        solid = next(tag for dim, tag in occ.addThruSections([circle, square], makeSolid=True, makeRuled=True) if dim == 3)
    elif kind == "bend":
        disk = occ.addDisk(2, 0, 0, 0.5, 0.5, zAxis=[0, 1, 0])
        solid = next(tag for dim, tag in occ.revolve([(2, disk)], 0, 0, 0, 0, 0, 1, np.pi / 2) if dim == 3)
    elif kind == "bent_pentagon":
        angles = np.pi / 2 + 2 * np.pi * np.arange(5) / 5
        points = [occ.addPoint(2 + 0.5 * np.cos(a), 0, 0.5 * np.sin(a)) for a in angles]
        loop = occ.addCurveLoop([occ.addLine(points[k], points[(k + 1) % 5]) for k in range(5)])
        turned = occ.revolve([(2, occ.addPlaneSurface([loop]))], 0, 0, 0, 0, 0, 1, 2 * np.pi / 3)
        solid = next(tag for dim, tag in turned if dim == 3)
    else:
        raise ValueError(kind)
    occ.synchronize()
    volume = occ.getMass(3, solid)
    from meshgen.geometry.shapes.cad import quiet_stdout

    with quiet_stdout():
        gmsh.write(str(path))
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    elif previous:
        gmsh.model.setCurrent(previous)
    return volume


def prism_distance(path, nodes) -> float:
    """Largest distance of ``nodes`` (N, 3) from the triangulated prism in ``path`` (its caps at
    the z extremes, its outline the bottom cap's vertices in angle order): min of the distance
    from the outline's segments in xy and from the nearer cap plane."""
    import trimesh

    V = trimesh.load(path).vertices
    low, high = V[:, 2].min(), V[:, 2].max()
    ring = V[np.abs(V[:, 2] - low) < 1e-9][:, :2]
    ring = ring[np.hypot(ring[:, 0], ring[:, 1]) > 1e-9]
    ring = ring[np.argsort(np.arctan2(ring[:, 1], ring[:, 0]))]
    a, b, p = ring, np.roll(ring, -1, axis=0), nodes[:, None, :2]
    t = np.clip(((p - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0.0, 1.0)
    across = np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=2).min(axis=1)
    return float(np.minimum(across, np.minimum(abs(nodes[:, 2] - low), abs(nodes[:, 2] - high))).max())
