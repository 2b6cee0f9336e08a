"""The terms across the interfaces of a set of several blocks, and its problem (design notes §20):
one MLP per block, all in normalised units of the whole set, and the loss terms that make them one
mesh.

- L1, the Winslow residual: inside every block on its own randomly shifted finite-difference grid
  (as a single shape), and across every interface on stencils whose normal neighbours lie in the
  two blocks (block a's network on a's side, b's on b's side, the normal step scaled by the
  blocks' mean lengths as ``meshgen.methods.interfaces`` pads them), so interface nodes are solved
  as interior nodes of the whole mesh, as the multi-block elliptic mesh solves them;
- L2, the boundary: each block's network fitted to its boundary map on its patch faces (on a flat
  patch only the distance from the plane counts: nodes slide in it, as in the elliptic mesh), and
  the two networks of every interface made to agree on the shared face.

Every draw comes from the run's ``torch.Generator`` in a fixed order (a resumed run repeats an
uninterrupted one); boundary-map values are computed once into fixed pools.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet
from meshgen.methods.interfaces import junction_nodes, mean_length
from meshgen.methods.tfi import tfi, transfinite
from meshgen.neural.derivatives import grid_derivatives, grid_from_draws
from meshgen.neural.inference import face_plane
from meshgen.neural.losses import boundary_local_size, boundary_loss, pde_loss, sample_boundary, sample_interior
from meshgen.neural.model import MLP
from meshgen.neural.problem import Problem, grid_residual
from meshgen.neural.winslow import winslow_residual

__all__ = [
    "INTERFACE_STEP",
    "JUNCTION_MARGIN",
    "JUNCTION_STEP",
    "BlockNetworks",
    "BlockProblem",
    "ANCHOR_POINTS",
    "FLAT_PATCH_STEP",
    "TFI_ANCHOR",
    "anchor_term",
    "block_boundary_term",
    "block_lengths",
    "block_pde_term",
    "block_problem",
    "block_sample",
    "block_samples",
    "fixed_block_points",
    "flat_patch_rows",
    "interface_stencil",
    "junction_pool",
    "lattice_tangents",
    "junction_rows",
    "junction_weights",
    "patch_pool",
    "pretrain_block_pool",
    "tfi_anchor_pool",
]

LENGTH_CELLS = 64  # cells per axis of the TFI grid lines whose mean length scales a block's axis (``block_lengths``)
INTERFACE_STEP = 0.05  # parametric stencil step at interfaces (block a's normal axis, and the tangents)
# Interface stencils within this parametric distance of a junction edge (where the face meets
# another interface: three or more blocks around the edge) are weighted down by (d / margin)^2:
# no map that is smooth in every block is C1 across all the interfaces at a junction, so the
# residual there measures the junction, not the map (``junction_weights``).
JUNCTION_MARGIN = 0.1
# Default weight (``method.tfi_anchor``) of the pull towards the TFI in L1 (``tfi_anchor_pool``): mean squared distance, in
# normalised units, of every block's network from its TFI at fixed interior points. Winslow's
# equations barely resist some motions of a block set (an O-grid's core turned about its axis
# against the wall, the ring between sheared into a spiral: the ring's map stays a Winslow solution);
# the pull picks, among such nearly equal solutions, the one nearest the TFI, as the elliptic
# solver does by starting from it.
TFI_ANCHOR = 1.0
ANCHOR_POINTS = 500  # fixed interior points per block of the pull towards the TFI
# Parametric step of L2's right-angle rule on flat patches (``flat_patch_rows``): the multi-block
# elliptic mesh moves a node on a flat patch to the projection of its neighbour one layer inside,
# so grid lines meet the plane at right angles; the networks are asked the same of the map's
# derivative across the face (second-order one-sided differences of this step). 0 switches it off.
FLAT_PATCH_STEP = 0.05
# L2's parallelogram rule at junction nodes (``junction_pool``): the multi-block elliptic mesh puts
# a node where three or more blocks meet at the mean of the parallelogram completions of the grid
# quadrilaterals around it; the networks are asked the same of quadrilaterals made physically
# square, of side this fraction of the shortest mean block length around the junction. 0: off.
JUNCTION_STEP = 0.05


class BlockNetworks(torch.nn.Module):
    """One MLP per block (``networks[i]`` maps block i's unit cube to normalised physical points)."""

    def __init__(self, dim: int, widths: list[int], count: int):
        super().__init__()
        self.networks = torch.nn.ModuleList(MLP(dim, widths) for _ in range(count))


@dataclass
class BlockProblem:
    """A block set in normalised units (the whole set scaled into [-1/2, 1/2]^d): per block its own
    part (``blocks``: the one-block ``meshgen.neural.problem.Problem`` of its boundary map, whose
    Winslow residual is the set's inside that block), and the terms that join the blocks.

    ``boundaries``: per block, (N, d) cube-boundary points -> (N, d) normalised points (NumPy);
    ``interfaces``: (a, face a, b, face b, transform, ratio) with ratio = a's mean length across
    the interface over b's; ``patch_faces``: (block, face, plane) per patch face, plane None or
    (unit normal (d,), offset) in normalised units."""

    dim: int
    names: tuple
    boundaries: list
    interfaces: list
    patch_faces: list
    center: np.ndarray
    scale: float
    device: torch.device
    exact: bool = False  # the networks are soft-boundary maps; the mesh is corrected to the faces
    # per interface: (tangent number, side) of block a's face edges that are junction edges
    junctions: list = field(default_factory=list)
    # per block: {"points" (K, d), "targets" (K, d)}, the TFI at fixed interior points (``tfi_anchor_pool``)
    anchor: list = field(default_factory=list)
    # the parallelogram rule's quadrilaterals at junction nodes (``junction_pool``), None: no rule
    junction: dict | None = None
    anchor_weight: float = TFI_ANCHOR  # the pull's weight (``method.tfi_anchor``)
    # per block: its one-block problem (soft boundary, the set's normalisation), made by ``block_problem``
    blocks: list = field(default_factory=list)


def block_lengths(geometry, dim: int) -> list[float]:
    """Per axis, the mean length of a block's TFI grid lines along it (``LENGTH_CELLS`` cells per
    axis, one TFI for all axes)."""
    X = tfi(geometry, None, [np.linspace(0.0, 1.0, LENGTH_CELLS + 1)] * dim)
    return [mean_length(X, axis) for axis in range(dim)]


def face_points(face: cube.Face, tangents: np.ndarray) -> np.ndarray:
    """Parametric points (N, d) on ``face`` with ``tangents`` (N, d-1) along its tangent axes."""
    points = np.empty((len(tangents), face.dim))
    points[:, list(face.tangent_axes)] = tangents
    points[:, face.axis] = float(face.side)
    return points


def block_problem(block_set: BlockSet, device: torch.device, center=None, scale=None) -> BlockProblem:
    """The normalised problem of ``block_set``; ``center``/``scale`` default to the bounding box of
    all blocks' boundaries (its centre and largest extent)."""
    dim = block_set.dim
    samples = cube.face_samples(dim, 17)
    if center is None:
        mapped = np.concatenate([g.boundary(samples) for g in block_set.geometries])
        low, high = mapped.min(axis=0), mapped.max(axis=0)
        center, scale = (low + high) / 2.0, float(np.max(high - low))
    center, scale = np.asarray(center, dtype=float), float(scale)

    def normalised(geometry):
        return lambda points: (geometry.boundary(points) - center) / scale

    boundaries = [normalised(g) for g in block_set.geometries]
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 9)] * (dim - 1), indexing="ij"), -1).reshape(-1, dim - 1)
    patch_faces = []
    for (block, face_name), _ in sorted(block_set.patches.items()):
        face = cube.face_named(face_name, dim)
        plane = face_plane(boundaries[block](face_points(face, grid)), 1.0)
        patch_faces.append((block, face, plane))
    interfaces, junctions = [], []
    lengths = [block_lengths(g, dim) for g in block_set.geometries]
    shared = {(i.a, i.face_a.name) for i in block_set.interfaces} | {(i.b, i.face_b.name) for i in block_set.interfaces}
    for i in block_set.interfaces:
        ends = [
            (number, side)
            for number, axis in enumerate(i.face_a.tangent_axes)
            for side in (0, 1)
            if (i.a, f"{cube.AXIS_NAMES[axis]}{side}") in shared
        ]
        junctions.append(ends)
        ratio = lengths[i.a][i.face_a.axis] / lengths[i.b][i.face_b.axis]
        interfaces.append((i.a, i.face_a, i.b, i.face_b, tuple(i.transform), ratio))
    parts = [Problem(dim, boundary, center, scale, False, device) for boundary in boundaries]
    problem = BlockProblem(
        dim, block_set.names, boundaries, interfaces, patch_faces, center, scale, device, junctions=junctions, blocks=parts
    )
    problem.junction = junction_pool(block_set, device, lengths) if JUNCTION_STEP > 0 else None
    return problem


def junction_pool(block_set: BlockSet, device, lengths=None) -> dict | None:
    """The parallelogram rule's quadrilaterals at the junction nodes of ``block_set``'s grid (its
    ``coords``; ``meshgen.methods.interfaces.junction_nodes``: where three or more blocks meet, on no
    patch), as the elliptic mesh takes them (in 3D those across the block edge the node is on, in
    its layer), each rescaled about the node to a physically square one of side ``JUNCTION_STEP``
    times the shortest mean block length around the junction. Returns None without junctions, else
    ``node`` (Q,) the junction number of each quad, ``block`` (Q,), ``points`` (Q, 4, d) the
    parametric node, a, b and ab in the quad's block, ``area`` (J,) the mean over the junction's
    quads of the product of their parametric sides, ``count`` J, the junctions that have quads (in
    3D a node at a corner of every block round it has none: no rows for it). ``lengths``: the blocks'
    ``block_lengths`` (computed when not given)."""
    junctions, numbering, _ = junction_nodes(block_set)
    if len(junctions) == 0:
        return None
    dim = block_set.dim
    lengths = lengths or [block_lengths(g, dim) for g in block_set.geometries]
    order = {int(n): k for k, n in enumerate(junctions)}
    nodes, blocks, quads, sides = [], [], [], []
    for block, ids in enumerate(numbering):
        local = np.argwhere(np.isin(ids, junctions))
        shape = np.array(ids.shape)
        coords = block_set.coords[block]
        free = ~((local == 0) | (local == shape - 1))
        for edge_axis in range(dim) if dim == 3 else [None]:
            if edge_axis is None:
                rows, plane = np.arange(len(local)), [0, 1]
            else:
                rows = np.flatnonzero(free[:, edge_axis] & (free.sum(axis=1) == 1))
                plane = [axis for axis in range(dim) if axis != edge_axis]
            for index in local[rows]:
                point = np.array([coords[axis][index[axis]] for axis in range(dim)])
                for step_a in (-1, 1):
                    for step_b in (-1, 1):
                        a, b = index.copy(), index.copy()
                        a[plane[0]] += step_a
                        b[plane[1]] += step_b
                        if not (0 <= a[plane[0]] < shape[plane[0]] and 0 <= b[plane[1]] < shape[plane[1]]):
                            continue
                        nodes.append(order[int(ids[tuple(index)])])
                        blocks.append(block)
                        quads.append((point, plane, (step_a, step_b)))
                        sides.append(min(lengths[block][axis] for axis in plane))
    if not nodes:
        return None
    nodes = np.array(nodes)
    used = np.unique(nodes)  # a 3D node at a corner of every block round it lies inside no block edge: no quads
    renumber = np.zeros(len(junctions), dtype=nodes.dtype)
    renumber[used] = np.arange(len(used))
    nodes = renumber[nodes]
    side = np.full(len(used), np.inf)
    np.minimum.at(side, nodes, np.array(sides))
    side *= JUNCTION_STEP
    points = np.empty((len(nodes), 4, dim))
    for q, (point, plane, signs) in enumerate(quads):  # node, a, b, ab: physical side ``side``
        offsets = [sign * side[nodes[q]] / lengths[blocks[q]][axis] for axis, sign in zip(plane, signs)]
        corner = [np.zeros(dim) for _ in range(4)]
        corner[1][plane[0]] = corner[3][plane[0]] = offsets[0]
        corner[2][plane[1]] = corner[3][plane[1]] = offsets[1]
        points[q] = point + np.stack(corner)
    areas = np.abs(np.prod(points[:, 3] - points[:, 0], axis=1, where=(points[:, 3] != points[:, 0])))
    area = np.zeros(len(used))
    np.add.at(area, nodes, areas)
    area /= np.bincount(nodes, minlength=len(used))
    return {
        "node": torch.from_numpy(nodes).to(device),
        "block": np.array(blocks),
        "points": torch.from_numpy(points).to(device),
        "area": torch.from_numpy(area).to(device),
        "count": len(used),
    }


def junction_rows(networks, pool: dict) -> torch.Tensor:
    """L1's rows of the parallelogram rule (``JUNCTION_STEP``), (J, d): per junction, the node's
    image (the mean of its blocks' images) minus the mean over its quads of x_a + x_b - x_ab,
    divided by the mean over its quads of the product of their parametric sides: a mean mixed
    second derivative in the blocks' parameters, the units of the Winslow residual (design notes §20)."""
    points = pool["points"]
    dtype = _dtype(networks[0])
    values = torch.empty((*points.shape[:2], points.shape[-1]), dtype=dtype, device=points.device)
    for block in np.unique(pool["block"]):
        rows = torch.from_numpy(np.flatnonzero(pool["block"] == block)).to(points.device)
        chosen = points.index_select(0, rows).to(dtype)
        values[rows] = networks[block](chosen.reshape(-1, chosen.shape[-1])).reshape(chosen.shape)
    node, count = pool["node"], pool["count"]
    hits = torch.zeros(count, dtype=dtype, device=points.device).index_add_(0, node, torch.ones_like(node, dtype=dtype))
    image = torch.zeros((count, points.shape[-1]), dtype=dtype, device=points.device).index_add_(0, node, values[:, 0])
    completion = values[:, 1] + values[:, 2] - values[:, 3]
    predicted = torch.zeros_like(image).index_add_(0, node, completion)
    return (image - predicted) / (hits[:, None] * pool["area"].to(dtype)[:, None])


def lattice_tangents(count: int, dim: int, margin: float) -> torch.Tensor:
    """About ``count`` points of a face (``dim`` - 1 tangent coordinates) on a regular lattice
    inside [margin, 1 - margin]: n per axis, n = round(count^(1/(dim-1))) (at least 2), at the
    centres of the n equal cells, (n^(dim-1), dim-1) float64."""
    n = max(2, round(count ** (1.0 / (dim - 1))))
    axis = margin + (torch.arange(n, dtype=torch.float64) + 0.5) * (1.0 - 2.0 * margin) / n
    grids = torch.meshgrid(*([axis] * (dim - 1)), indexing="ij")
    return torch.stack([g.reshape(-1) for g in grids], -1)


def patch_pool(problem: BlockProblem, count: int, seed: int, lattice: bool = False) -> dict:
    """``count`` points per patch face with their images, local sizes and planes, on the device:
    ``points`` (F, count, d), ``images`` (F, count, d), ``size`` (F, count), ``normal`` (F, d)
    (zero for a curved face); ``interface_size``: per interface, the mean local size of its face.
    ``lattice``: the points of ``lattice_tangents`` (about ``count``) instead of random ones."""
    generator = torch.Generator().manual_seed(seed)
    dim = problem.dim
    points, images, sizes, normals = [], [], [], []
    for block, face, plane in problem.patch_faces:
        if lattice:
            tangents = lattice_tangents(count, dim, 0.0).numpy()
        else:
            tangents = torch.rand((count, dim - 1), generator=generator, dtype=torch.float64).numpy()
        p = face_points(face, tangents)
        image = problem.boundaries[block](p)
        points.append(p)
        images.append(image)
        sizes.append(boundary_local_size(problem.boundaries[block], p, image))
        normals.append(np.zeros(dim) if plane is None else plane[0])
    interface_size = []
    for a, face_a, *_ in problem.interfaces:  # one mean local size per shared face
        p = face_points(face_a, torch.rand((64, dim - 1), generator=generator, dtype=torch.float64).numpy())
        interface_size.append(float(np.mean(boundary_local_size(problem.boundaries[a], p))))
    device = problem.device
    return {
        "interface_size": interface_size,
        "points": torch.from_numpy(np.stack(points)).float().to(device),
        "images": torch.from_numpy(np.stack(images)).float().to(device),
        "size": torch.from_numpy(np.stack(sizes)).float().to(device),
        "normal": torch.from_numpy(np.stack(normals)).float().to(device),
    }


def pretrain_block_pool(problem: BlockProblem, count: int, seed: int) -> list[dict]:
    """Per block, ``count`` interior and ``count`` boundary points with their TFI images (the
    L-BFGS fit that starts a run from a valid map)."""
    generator = torch.Generator().manual_seed(seed)
    pools = []
    for boundary in problem.boundaries:
        points = torch.cat([sample_interior(count, problem.dim, generator), sample_boundary(count, problem.dim, generator)])
        targets = torch.from_numpy(transfinite(boundary, list(points.double().numpy().T)))
        pools.append({"points": points.to(problem.device), "targets": targets.float().to(problem.device)})
    return pools


def tfi_anchor_pool(problem: BlockProblem, count: int, seed: int) -> list[dict]:
    """Per block, ``count`` fixed interior points and the block's TFI there (normalised units, on
    the device): what L1's pull towards the TFI (``TFI_ANCHOR``) measures the networks against."""
    generator = torch.Generator().manual_seed(seed)
    pools = []
    for boundary in problem.boundaries:
        points = sample_interior(count, problem.dim, generator)
        targets = torch.from_numpy(transfinite(boundary, list(points.double().numpy().T)))
        pools.append({"points": points.to(problem.device), "targets": targets.float().to(problem.device)})
    return pools


# ---------------------------------------------------------------------------------------------
# one step's draws


def _nodes_per_block(interior: int, blocks: int, dim: int) -> int:
    return max(1, round((interior / blocks) ** (1.0 / dim)))


def block_sample(problem: BlockProblem, config, generator: torch.Generator, pool_count: int) -> dict:
    """One step's draws on the host (CPU tensors): ``grid`` (blocks, 2d) float64 (each block's
    shifted training grid), ``tangent`` (interfaces, M, d-1) points on every interface (inside a
    margin of one stencil step), ``index`` (patch faces, K) into the patch pool."""
    dim, blocks = problem.dim, len(problem.names)
    shares = len(problem.patch_faces) + len(problem.interfaces)
    per_face = max(8, config.points.boundary // max(1, shares))
    margin = INTERFACE_STEP
    tangent = margin + (1 - 2 * margin) * torch.rand((len(problem.interfaces), per_face, dim - 1), generator=generator)
    return {
        "grid": torch.rand((blocks, 2 * dim), generator=generator, dtype=torch.float64),
        "tangent": tangent,
        "index": torch.randint(0, pool_count, (len(problem.patch_faces), per_face), generator=generator),
    }


def fixed_block_points(problem: BlockProblem, config, pool_count: int, seed: int, lattice: int = 0) -> dict:
    """A fixed draw: the unshifted grids (``grid`` with scale 1) and one draw of interface and
    patch points, from their own seed. ``lattice`` > 0 (the L-BFGS stage): the interface points on
    the regular lattice of ``lattice_tangents`` (as many per face as a draw) and the patch points
    the first ``lattice`` of a lattice pool (``patch_pool(..., lattice=True)``), the same on every
    face: a block set whose map does not change along an axis (an extrusion) then meets the same
    equations in every layer across it, so nothing in the fixed points makes its layers differ."""
    generator = torch.Generator().manual_seed(seed)
    draw = block_sample(problem, config, generator, pool_count)
    draw["grid"] = torch.zeros_like(draw["grid"])
    draw["grid"][:, 0::2] = 1.0  # scale 1 (grid_from_draws with min_scale < 1), offset 0
    if lattice:
        per_face = draw["tangent"].shape[1]
        tangent = lattice_tangents(per_face, problem.dim, INTERFACE_STEP).to(draw["tangent"].dtype)
        draw["tangent"] = tangent.expand(len(problem.interfaces), *tangent.shape).contiguous()
        draw["index"] = torch.arange(lattice).expand(len(problem.patch_faces), lattice).contiguous()
    return {k: v.to(problem.device) for k, v in draw.items()}


def block_samples(config, problem: BlockProblem, inputs: dict, random: bool = True):
    """(PDE sample, boundary sample) of one step's draws on the device."""
    m = _nodes_per_block(config.points.interior, len(problem.names), problem.dim)
    min_scale = config.points.grid_min_scale if (random and config.points.random_grid) else 1.0
    grids = [grid_from_draws(draws, m, min_scale) for draws in inputs["grid"]]
    return (grids, inputs["tangent"]), (inputs["index"], inputs["tangent"])


# ---------------------------------------------------------------------------------------------
# the terms


def _dtype(network) -> torch.dtype:
    """The floating-point type of ``network``'s weights (float64 in an ``lbfgs.float64`` stage);
    float32 for a plain function (the tests' closed-form maps)."""
    if isinstance(network, torch.nn.Module):
        return next(network.parameters()).dtype
    return torch.float32


def _to_b(points_a: torch.Tensor, face_a: cube.Face, face_b: cube.Face, transform) -> torch.Tensor:
    """Block b's parametric points of block a's points ``points_a`` (..., d) near the interface
    face: tangents by the Transform, the normal coordinate mirrored across the shared face."""
    columns = [None] * face_a.dim
    for axis, t in enumerate(transform):
        target = abs(t) - 1
        value = points_a[..., axis]
        if axis == face_a.axis:  # distance from the face, into b
            depth = (value - face_a.side).abs()
            columns[target] = depth if face_b.side == 0 else 1.0 - depth
        else:
            columns[target] = value if t > 0 else 1.0 - value
    return torch.stack(columns, dim=-1)


def interface_stencil(networks, problem: BlockProblem, interface, tangent: torch.Tensor):
    """Winslow residual (M, d) across ``interface`` at its points ``tangent`` (M, d-1), and the two
    networks' images of those points ((M, d) each). The stencil runs along (u, tangents): u < 0 in
    block a (parametric step ``INTERFACE_STEP``), u > 0 in block b (step times the length ratio),
    u = 0 the mean of the two images."""
    a, face_a, b, face_b, transform, ratio = interface
    dim, h = problem.dim, INTERFACE_STEP
    tangent = tangent.to(_dtype(networks[a]))
    offsets = torch.tensor([-1.0, 0.0, 1.0], dtype=tangent.dtype, device=tangent.device)
    m = tangent.shape[0]
    grids = torch.meshgrid(*([offsets] * (dim - 1)), indexing="ij")
    shifts = torch.stack([g.reshape(-1) for g in grids], -1) * h  # (3^(d-1), d-1)
    base = tangent[:, None, :] + shifts[None]  # (M, 3^(d-1), d-1)
    inward = 1.0 if face_a.side == 0 else -1.0

    def on_a(depth):  # block a's points at parametric distance ``depth`` from the face
        points = torch.empty((*base.shape[:2], dim), dtype=tangent.dtype, device=tangent.device)
        points[..., list(face_a.tangent_axes)] = base
        points[..., face_a.axis] = face_a.side + inward * depth
        return points

    inner, surface = on_a(h), on_a(0.0)
    net_a, net_b = networks[a], networks[b]
    value_a = net_a(torch.cat([inner, surface]).reshape(-1, dim)).reshape(2, *base.shape[:2], dim)
    across = _to_b(surface, face_a, face_b, transform)
    outer = across.clone()
    step_b = h * ratio
    outer[..., face_b.axis] = across[..., face_b.axis] + (step_b if face_b.side == 0 else -step_b)
    value_b = net_b(torch.cat([across, outer]).reshape(-1, dim)).reshape(2, *base.shape[:2], dim)
    centre = 0.5 * (value_a[1] + value_b[0])
    values = torch.stack([value_a[0], centre, value_b[1]], dim=1)  # (M, 3, 3^(d-1), d)
    values = values.reshape(m, *([3] * dim), dim)
    _, first, second = grid_derivatives(values, [h] * dim)
    squeeze = (slice(None), *([0] * dim))
    middle = (3 ** (dim - 1) - 1) // 2  # the point itself in the flattened tangent stencil
    return winslow_residual(first[squeeze], second[squeeze]), value_a[1][:, middle], value_b[0][:, middle]


def junction_weights(tangent: torch.Tensor, ends) -> torch.Tensor:
    """Weights (M,) of an interface's stencils at ``tangent`` (M, d-1): (d / JUNCTION_MARGIN)^2 up
    to 1, d the parametric distance to the nearest junction edge of the face (``ends``: (tangent
    number, side) pairs); 1 everywhere without junction edges."""
    distance = torch.full(tangent.shape[:1], JUNCTION_MARGIN, dtype=tangent.dtype, device=tangent.device)
    for number, side in ends:
        distance = torch.minimum(distance, (tangent[:, number] - side).abs())
    return (distance / JUNCTION_MARGIN).square()


def block_pde_term(networks, problem: BlockProblem, sample) -> torch.Tensor:
    """L1: the mean squared Winslow residual over every block's grid (one block's residual,
    ``meshgen.neural.problem.grid_residual`` of its part) and every interface's stencils
    (those near junction edges weighted down: ``junction_weights``), plus ``anchor_weight`` times the
    pull towards the TFI (``anchor_term``) when the problem holds its pool."""
    grids, tangents = sample
    residuals = []
    for net, part, (axes, spacing) in zip(networks, problem.blocks, grids):  # inside each block: one block's residual
        residuals.append(grid_residual(net, part, axes, spacing).reshape(-1, problem.dim))
    junctions = problem.junctions or [[]] * len(problem.interfaces)
    for interface, tangent, ends in zip(problem.interfaces, tangents, junctions):
        residual = interface_stencil(networks, problem, interface, tangent)[0]
        if ends and JUNCTION_MARGIN > 0:
            residual = residual * junction_weights(tangent.to(residual.dtype), ends).sqrt()[:, None]
        residuals.append(residual)
    if problem.junction is not None:
        residuals.append(junction_rows(networks, problem.junction))
    value = pde_loss(torch.cat(residuals))
    if problem.anchor and problem.anchor_weight > 0:
        value = value + problem.anchor_weight * anchor_term(networks, problem.anchor)
    return value


def anchor_term(networks, pools) -> torch.Tensor:
    """Mean over blocks of the mean squared distance of each network from its TFI at the pool's points."""
    dtype = _dtype(networks[0])
    return torch.stack(
        [(net(p["points"].to(dtype)) - p["targets"].to(dtype)).square().sum(-1).mean() for net, p in zip(networks, pools)]
    ).mean()


def block_boundary_term(networks, problem: BlockProblem, config, pool: dict, sample) -> torch.Tensor:
    """L2: patch faces fitted (normal distance only on flat ones), interfaces' images agreeing;
    errors relative to the local size of the boundary where ``method.boundary_error`` says so."""
    index, tangents = sample
    dtype = _dtype(networks[0])
    predicted, targets, sizes = [], [], []
    for number, (block, _, plane) in enumerate(problem.patch_faces):
        rows = index[number]
        points = pool["points"][number].index_select(0, rows).to(dtype)
        image = pool["images"][number].index_select(0, rows).to(dtype)
        value = networks[block](points)
        size = pool["size"][number].index_select(0, rows).to(dtype)
        if plane is not None:  # only the distance from the plane: nodes slide in a flat patch
            normal = pool["normal"][number].to(dtype)
            if FLAT_PATCH_STEP > 0:  # ... and grid lines meet it at right angles
                predicted.append(flat_patch_rows(networks[block], problem.patch_faces[number][1], points, value, normal))
                targets.append(torch.zeros_like(value))
                sizes.append(torch.ones_like(size))
            value = image + ((value - image) @ normal)[:, None] * normal
        predicted.append(value)
        targets.append(image)
        sizes.append(size)
    for number, (interface, tangent) in enumerate(zip(problem.interfaces, tangents)):
        _, value_a, value_b = interface_stencil(networks, problem, interface, tangent)
        predicted.append(value_a)
        targets.append(value_b)
        sizes.append(torch.full((len(value_a),), float(pool["interface_size"][number]), dtype=dtype, device=value_a.device))
    size = torch.cat(sizes) if config.method.boundary_error == "relative" else None
    return boundary_loss(torch.cat(predicted), torch.cat(targets), config.method.point_weights, size)[0]


def flat_patch_rows(network, face: cube.Face, points: torch.Tensor, value: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """L2's rows of the right-angle rule on a flat patch (``FLAT_PATCH_STEP``), (K, d): at the
    face's parametric ``points`` (K, d), where the network's images are ``value`` (K, d), the
    in-plane part of the map's derivative across the face over its length, i.e. the sine of the
    angle by which the grid line leaving the face misses the plane's normal (dimensionless: the
    rows enter L2 with local size 1). The derivative is the second-order one-sided difference
    (-3 x(0) + 4 x(s) - x(2 s)) / 2 s, x(t) the image at parametric depth t inside the block.
    Zero when grid lines meet the plane at right angles, the multi-block elliptic mesh's rule
    (design notes §20)."""
    inward = 1.0 if face.side == 0 else -1.0
    steps = []
    for depth in (FLAT_PATCH_STEP, 2.0 * FLAT_PATCH_STEP):
        moved = points.clone()
        moved[:, face.axis] = face.side + inward * depth
        steps.append(moved)
    inside = network(torch.cat(steps)).reshape(2, *value.shape)
    across = -3.0 * value + 4.0 * inside[0] - inside[1]
    return (across - (across @ normal)[:, None] * normal) / across.norm(dim=-1, keepdim=True)
