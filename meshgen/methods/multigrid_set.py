"""The elliptic solver's multigrid for a block set: the FAS V-cycles of ``meshgen.methods.multigrid``
run on every block at every level, with the interface nodes as interior nodes of the whole mesh.

Levels: the blocks coarsen together. An axis of one block and the axis of its neighbour that runs
along the same interface are one family (union over the interfaces' Transforms); a family coarsens
while it has more than ``COARSEST_CELLS`` cells and one of its axes is coupled at least
``SEMI_COARSENING`` times as strongly as its block's strongest coarsenable axis (the one-block
hierarchy's semi-coarsening: a pipe's cells, long along the pipe, couple ~100 times more weakly
along it), so the blocks' coarse grids share their interface nodes (``coarser_coordinates`` picks
nodes by index, the same on both sides). A block whose axes are all coarse stays as it is.
In 2D the hierarchy stops at the first level with at most ``DIRECT_NODES`` nodes, which Newton's
method solves (``coarsest_equations``, ``meshgen.methods.sparse_newton``): on the coarse levels a
block's line solve ends at its halo, so where a strong direction crosses several blocks of a few
cells each (the DFG channel's stacked blocks, their long axis ~25 times weaker) the sweeps leave
the modes rough along the weak axis, and further coarsening of that axis does not reach them.

On each level (``SetLevel``) each block is padded with a halo layer on its interface faces
(``meshgen.methods.interfaces.Halo``), all of them slices of one flat buffer
(``meshgen.methods.interfaces.Layout``). Between the grids the state is the unique nodes (count,
dim). A relaxation sweep is: one line-ADI sweep of the Winslow equations per block (the block's
edges and corners frozen: they are junctions or on patches; a sliding node on an axis-aligned
flat patch is the Neumann end of its normal line, ``wall_rows``), one Jacobi step of the sliding
nodes' and the junctions' equations (``meshgen.methods.sliding``, ``meshgen.methods.interfaces``)
at their owners, then every copy of a node (halos, ghosts, shared faces) from its owner: only the
blocks' surfaces move between sweeps.
Residuals are restricted per block (the Winslow residual with the residual restriction, the
boundary rules' residuals by interpolation along the patch), corrections prolonged per block.
The fixed point is the finest level's equations at every node: block interiors, interface nodes
(the two blocks glued), sliding nodes and junctions.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from meshgen.geometry.block_nodes import global_numbering
from meshgen.methods.anderson import ANDERSON_DEPTH, AndersonMixing
from meshgen.methods.interfaces import (
    Halo,
    JunctionRule,
    Layout,
    faces_holding,
    gather,
    junction_nodes,
    junction_stencil,
    mean_length,
)
from meshgen.methods.multigrid import (
    COARSEST_CELLS,
    DAMPING,
    SEMI_COARSENING,
    Level,
    coarser_coordinates,
    progress_fraction,
    stencil_weights,
)
from meshgen.methods.sliding import SlideRule, local_cell_sizes, planar_sliding
from meshgen.methods.sparse_newton import LaggedNewton
from meshgen.methods.winslow import component_array

SMOOTHING = 2  # relaxation sweeps before and after the coarse-grid correction (1: half as many cycles more)
COARSEST_SET_SWEEPS = (
    10  # relaxation sweeps on the coarsest level (40 for one grid: 10 gave the same cycles in 3D, 4 more in 2D, in less time)
)

# A 2D hierarchy stops at the first level with at most DIRECT_NODES nodes, solved by Newton's method
# (dfg-cylinder 34 x 20: 0.58 -> 0.19 per V-cycle). Not in 3D: the pipe's slow modes are on its
# finest level (0.47 per cycle either way) and a 27-point Jacobian costs ~150 residuals (2x the time).
DIRECT_NODES = 1500
DIRECT_TOL = 1e-12  # its Newton steps stop below this times the characteristic length (or after DIRECT_STEPS)
DIRECT_REDUCTION = 1e-2  # or below this times its first step: the coarse-grid correction to 1 %
DIRECT_STEPS = 20

__all__ = [
    "COARSEST_SET_SWEEPS",
    "DIRECT_NODES",
    "DIRECT_REDUCTION",
    "DIRECT_STEPS",
    "DIRECT_TOL",
    "SMOOTHING",
    "SetLevel",
    "axis_families",
    "axis_weights",
    "coarsest_equations",
    "relax_set",
    "set_levels",
    "solve_set",
    "v_cycle_set",
    "wall_rows",
]


def axis_families(block_set) -> np.ndarray:
    """(blocks, dim) family number of each block axis: axes that run along a common interface share one."""
    dim = block_set.dim
    parent = np.arange(len(block_set.coords) * dim)

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for interface in block_set.interfaces:  # a loop over interfaces, not nodes
        for axis in interface.face_a.tangent_axes:
            a, b = root(interface.a * dim + axis), root(interface.b * dim + abs(interface.transform[axis]) - 1)
            parent[max(a, b)] = min(a, b)
    return np.array([root(i) for i in range(len(parent))]).reshape(-1, dim)


class SetLevel:
    """One grid of the block set's hierarchy: the halo, per block the smoother's grid (padded
    coordinates) and the transfers to the next coarser grid (own coordinates), the sliding nodes
    and junctions with their stencils."""

    def __init__(self, block_set, Xs, lengths, coarse_coords=None, compiled: bool = False, slide: bool = True, strong=None):
        self.block_set = block_set
        self.halo = Halo(block_set, lengths)
        self.layout = Layout(self.halo, block_set.dim)
        self.smoothers = [Level(c, compiled=compiled) for c in self.halo.padded_coords]
        self.weights = [stencil_weights(s.grid) if block_set.dim == 2 else None for s in self.smoothers]
        self.transfers = None
        if coarse_coords is not None:
            self.transfers = [Level(c, cc, compiled=compiled) for c, cc in zip(block_set.coords, coarse_coords)]
        numbering, count = self.halo.numbering, self.halo.count
        values = gather(Xs, numbering, count)
        self.rules = []  # the boundary rules: sliding nodes, junctions
        sliding = planar_sliding(block_set, Xs, numbering, count) if slide else None
        if sliding is not None:
            self.rules.append(SlideRule(sliding, values))
        junctions, _, _ = junction_nodes(block_set)
        if len(junctions):
            self.rules.append(JunctionRule(junction_stencil(block_set, numbering, junctions), values))
        self.frozen = []  # per block: the nodes the line relaxation keeps (edges, corners, patch faces)
        for block, ids in enumerate(self.halo.numbering):
            frozen = faces_holding(ids.shape) >= 2
            for face in self.halo.ghost_faces[block]:
                frozen[face.node_index] = True
            self.frozen.append(np.nonzero(frozen))  # as indices: the block's faces, a small part of it
        self.slide_rule = self.rules[0] if sliding is not None else None
        self.newton = self.equations = None  # the coarsest level's Newton solver and ``coarsest_equations``
        terms = [t for rule in self.rules for t in rule.terms if t.dtype.kind in "iu"]
        self.moved = np.unique(np.concatenate([rule.nodes for rule in self.rules])) if self.rules else np.zeros(0, int)
        self.touched = np.unique(np.concatenate([self.moved] + [t.reshape(-1) for t in terms]))  # what the rules read
        self.walls = [
            wall_rows(
                self.slide_rule,
                self.halo,
                block,
                self.weights[block] or self.smoothers[block].weights,
                None if strong is None else strong[block],
            )
            if sliding is not None
            else None
            for block in range(len(self.halo.numbering))
        ]

    def own(self, values: np.ndarray) -> list[np.ndarray]:
        """Each block's own component-first array (dim, ...) from the unique nodes."""
        return [np.ascontiguousarray(np.moveaxis(values[ids], -1, 0)) for ids in self.halo.numbering]


def wall_rows(rule: SlideRule, halo: Halo, block: int, weights, strong=None):
    """The sliding nodes of ``block`` whose rule the line relaxation solves with the interior (a
    Neumann row at the end of the grid line normal to their face): nodes inside a patch face whose
    plane is normal to a coordinate axis (the projector diagonal, its entries 0 or 1), one inner
    neighbour each, on faces normal to a ``strong`` axis (bool per axis; None: all): along a weakly
    coupled axis (a pipe's, along its length) a fixed line end passes little error on, and the
    extra line solve does not pay. ``weights``: the block's ``stencil_weights``. Returns None when there are none,
    else (the nodes' rows in ``rule``'s residual (S,), passes): per group of components with the
    same tangential nodes, a pass (components, which of the S nodes are tangential in them, and for
    those: index of the step's rows, of the axial coefficient along their face's axis, of the
    nodes (tuples of index arrays into the block's own array), 1 / the second-derivative weight
    that couples a node to its inner neighbour)."""
    ids = halo.numbering[block]
    dim = ids.ndim
    inner, projector = rule.terms
    single = rule.count[rule.slot] == 1
    pair_of = np.full(len(rule.nodes), -1)
    pair_of[rule.slot[single]] = np.flatnonzero(single)
    interior_face = faces_holding(ids.shape) == 1
    weights = weights[dim:]  # the second-derivative weights per axis (``stencil_weights``)
    index, axes, couplings, slots = [], [], [], []
    for face in halo.ghost_faces[block]:
        if strong is not None and not strong[face.axis]:
            continue
        on_face = np.zeros(ids.shape, dtype=bool)
        on_face[face.node_index] = True
        local = np.argwhere(on_face & interior_face)
        gids = ids[tuple(local.T)]
        slot = np.clip(np.searchsorted(rule.nodes, gids), 0, len(rule.nodes) - 1)
        pair = np.where(rule.nodes[slot] == gids, pair_of[slot], -1)
        neighbour = local.copy()
        neighbour[:, face.axis] += -1 if face.side else 1
        P = projector[np.maximum(pair, 0)]
        aligned = np.all(np.abs(P - np.round(P)) < 1e-9, axis=(1, 2)) & np.all(
            np.abs(P - np.einsum("pii->pi", P)[:, :, None] * np.eye(dim)) < 1e-9, axis=(1, 2)
        )
        keep = (pair >= 0) & aligned & (inner[np.maximum(pair, 0), 0] == ids[tuple(neighbour.T)])
        w = weights[face.axis]
        coupling = 1.0 / (w[0, -1] if face.side else w[2, 0])  # the row's coupling, times this, is -1
        index.append(local[keep])
        axes.append(np.full(int(keep.sum()), face.axis))
        couplings.append(np.full(int(keep.sum()), coupling))
        slots.append(slot[keep])
    if not sum(len(a) for a in axes):
        return None
    local, slots = np.concatenate(index), np.concatenate(slots)
    tangential = np.round(np.einsum("pii->pi", projector[pair_of[slots]])) == 1
    axes, couplings = np.concatenate(axes), np.concatenate(couplings)
    passes = {}
    for component in range(dim):
        rows = tangential[:, component]
        nodes = tuple(i[rows] for i in local.T)
        passes.setdefault(
            rows.tobytes(), ([], np.flatnonzero(rows), (slice(None),) + nodes, (axes[rows],) + nodes, nodes, couplings[rows])
        )
        passes[rows.tobytes()][0].append(component)
    return slots, list(passes.values())


def axis_weights(block_set, Xs, compiled: bool) -> np.ndarray:
    """(blocks, dim) the median over each block's interior nodes of the Winslow equations' axial
    coefficient A_aa / trace per axis on the start mesh ``Xs``: an axis's coupling on a grid is
    this over its parametric cell size squared (``meshgen.methods.multigrid.hierarchy``)."""
    rows = []
    for X, coords in zip(Xs, block_set.coords):
        _, axial = Level(coords, compiled=compiled).operator(component_array(X))
        rows.append([float(np.median(a)) for a in axial])
    return np.array(rows)


def set_levels(block_set, Xs, lengths, slide: bool = True) -> list[SetLevel]:
    """The hierarchy of ``block_set`` (finest first) from the start node arrays ``Xs`` (each
    level's sliding nodes are classified on the start mesh restricted to it) and the interfaces'
    mean lengths."""
    families = axis_families(block_set)
    compiled = block_set.dim == 3
    weights = axis_weights(block_set, Xs, compiled)
    spans = np.array([[t[-1] - t[0] for t in c] for c in block_set.coords], dtype=float)
    finest = weights * (np.array([[len(t) - 1 for t in c] for c in block_set.coords]) / spans) ** 2
    strong = finest >= SEMI_COARSENING * finest.max(axis=1, keepdims=True)  # per block axis, for wall_rows
    levels, sets, starts = [], [block_set], [list(Xs)]
    direct = DIRECT_NODES if block_set.dim == 2 else 0  # 3D: see DIRECT_NODES
    while global_numbering(sets[-1])[1] > direct:
        current = sets[-1]
        cells = np.array([[len(t) - 1 for t in c] for c in current.coords])
        strength = weights * (cells / spans) ** 2
        coarsenable = cells > COARSEST_CELLS
        strongest = np.where(coarsenable, strength, 0.0).max(axis=1, keepdims=True)
        coarsen = np.zeros(families.max() + 1, dtype=bool)
        coarsen[families[coarsenable & (strength >= SEMI_COARSENING * strongest)]] = True
        coarsen = coarsen[families] & coarsenable
        if not coarsen.any():
            break
        coarse = tuple(
            tuple(
                coarser_coordinates(np.asarray(t, dtype=float)) if c else np.asarray(t, dtype=float) for t, c in zip(block, flags)
            )
            for block, flags in zip(current.coords, coarsen)
        )
        sets.append(dataclasses.replace(current, coords=coarse))
    for index, current in enumerate(sets):
        coarse = sets[index + 1].coords if index + 1 < len(sets) else None
        level = SetLevel(current, starts[index], lengths, coarse, compiled, slide, strong)
        levels.append(level)
        if coarse is not None:
            restricted = [
                np.moveaxis(t.transfer("restrict_solution", np.moveaxis(X, -1, 0)), 0, -1)
                for t, X in zip(level.transfers, starts[index])
            ]
            starts.append(restricted)
    if levels[-1].halo.count <= direct:
        levels[-1].equations = coarsest_equations(levels[-1])
        halo = levels[-1].halo
        colours = np.zeros(halo.count, dtype=np.int64)  # the owner's index modulo 3 per axis
        for ids, (flat, nodes) in zip(halo.numbering, halo.writes):
            colours[nodes] = np.ravel_multi_index(tuple(i % 3 for i in np.unravel_index(flat, ids.shape)), (3,) * ids.ndim)
        levels[-1].newton = LaggedNewton(levels[-1].equations[0], block_set.length, colours)
    return levels


def coarsest_equations(level: SetLevel) -> tuple:
    """The equations of ``level`` as one system over its unique nodes (count, dim), for Newton's
    method: at a node a rule holds, the rule (a sliding node also keeps its offset normal to its
    plane or line); at a node its owner's line relaxation keeps (a block edge on a patch), that
    it stays; elsewhere the owner's Winslow equations (an interface node's: the blocks glued).
    Returns the sparsity (count, count) (equation i reads node j), the fixed nodes, per node
    the projector (count, dim, dim) onto what its rule leaves fixed (zero where nothing is) and
    (count, dim) the coordinates kept exactly (fixed nodes, sliding nodes' coordinate normal to
    an axis-aligned plane)."""
    halo, dim, count = level.halo, level.block_set.dim, level.halo.count
    owner = np.empty(count, dtype=np.int64)
    frozen = np.zeros(count, dtype=bool)
    for block, (flat, ids) in enumerate(halo.writes):  # as Halo.unique: later blocks override
        owner[ids] = block
        mask = np.zeros(halo.numbering[block].shape, dtype=bool)
        mask[level.frozen[block]] = True
        frozen[ids] = mask.reshape(-1)[flat]
    fixed = np.ones(count, dtype=bool)
    fixed[level.moved] = False
    fixed &= frozen
    rows, cols = [np.arange(count)], [np.arange(count)]
    for block, padded in enumerate(halo.padded_ids):  # halos and ghosts: every pad is one layer
        centre = padded[(slice(1, -1),) * dim]
        solved = (owner[centre] == block) & ~frozen[centre]
        for offset in itertools.product((-1, 0, 1), repeat=dim):
            shifted = padded[tuple(slice(1 + o, n - 1 + o) for o, n in zip(offset, padded.shape))]
            rows.append(centre[solved])
            cols.append(shifted[solved])
    normal = np.zeros((count, dim, dim))
    for rule in level.rules:
        for term in (t for t in rule.terms if t.dtype.kind in "iu"):
            rows.extend([rule.rows] * term.shape[1])
            cols.extend(term.T)
        if rule is level.slide_rule:
            projector = rule.terms[1]
            normal[rule.rows] = np.eye(dim)
            np.add.at(normal, rule.rows, -projector / rule.count[rule.slot, None, None])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    import scipy.sparse as sp  # on first use: `meshgen mesh --help` imports this module

    pattern = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(count, count))
    pattern.data[:] = 1.0
    kept = np.all((normal == np.eye(dim)) | (normal == 0.0), axis=2) & (np.einsum("nii->ni", normal) == 1.0)
    kept[fixed] = True
    return pattern, np.flatnonzero(fixed), normal, kept


def _coarsest_residual(level: SetLevel, equations, values: np.ndarray, f, start: np.ndarray) -> np.ndarray:
    """F (count, dim) of ``coarsest_equations`` at ``values``: N - f at the Winslow nodes, the
    rules' residual - f less the normal offset from ``start`` at theirs, the offset from
    ``start`` at the fixed nodes."""
    _, fixed, normal, _ = equations
    winslow = []
    for block, R in enumerate(level.layout.views(level.layout.load(values))):
        with np.errstate(all="ignore"):
            full = _defect_block(R, None if f is None else f[0][block], level.smoothers[block], level.weights[block])
        winslow.append(full[level.halo.inside(block)])
    residual = -level.halo.unique(winslow)
    for number, rule in enumerate(level.rules):
        residual[rule.nodes] = rule.residual(values) - (0.0 if f is None else f[1][number])
    moved = level.moved
    residual[moved] -= np.einsum("nij,nj->ni", normal[moved], values[moved] - start[moved])
    residual[fixed] = values[fixed] - start[fixed]
    return residual


def _relax_block(R: np.ndarray, f, level: Level, weights, frozen, walls=None, wall_step=None) -> None:
    """One line-ADI sweep of N(R) = f on the padded block R (in place), the ``frozen`` nodes (a
    tuple of index arrays into the block's own nodes) kept:
    the compiled sweep of ``meshgen.methods.multigrid.smooth`` with fixed line ends inside the
    grid (``weights``: the 2D kernels' stencil weights, None in 3D).

    ``walls`` (``wall_rows``), ``wall_step`` (S, dim): the sliding rule's Jacobi step at those
    nodes. Their tangential components are solved in the line normal to their face, a Neumann row
    delta_node - delta_inner = step (their normal component stays a fixed line end): one line
    solve per group of components with the same tangential nodes. A wave of tangential error
    along a flat wall, which fixed line ends pass on by one node per sweep, is solved at once."""
    from meshgen.methods import winslow_compiled, winslow_compiled_2d  # numba: loaded on first use

    kernels, weights = (winslow_compiled_2d, weights) if weights is not None else (winslow_compiled, level.weights)
    step, axial, inverse_centre = kernels.jacobi_step(R, f, weights)
    step[(slice(None),) + frozen] = 0.0  # fixed line ends: identity rows, zero right-hand side
    axial[(slice(None),) + frozen] = 0.0
    inverse_centre[frozen] = 0.0
    if walls is None:
        kernels.lines(step, axial, inverse_centre, weights, R, DAMPING)
        return
    _, passes = walls
    for components, rows, all_axes, normal_axis, nodes, couplings in passes:
        part = step[components]  # a copy: the kernels solve only these components' lines
        if len(couplings):
            saved = axial[all_axes].copy(), inverse_centre[nodes].copy()
            axial[all_axes] = 0.0
            axial[normal_axis] = 1.0
            inverse_centre[nodes] = couplings
            part[(slice(None),) + nodes] = wall_step[rows][:, components].T
        moved = np.zeros(part.shape[:1] + R.shape[1:])
        kernels.lines(part, axial, inverse_centre, weights, moved, DAMPING)
        R[components] += moved
        if len(couplings):
            axial[all_axes], inverse_centre[nodes] = saved


def _defect_block(R: np.ndarray, f, level: Level, weights) -> np.ndarray:
    from meshgen.methods import winslow_compiled_2d

    return winslow_compiled_2d.defect(R, f, weights) if weights is not None else level.defect(R, f)


def _operator_block(R: np.ndarray, level: Level, weights) -> np.ndarray:
    from meshgen.methods import winslow_compiled_2d

    return (winslow_compiled_2d.operator(R, weights) if weights is not None else level.operator(R))[0]


def relax_set(level: SetLevel, values: np.ndarray, f, sweeps: int) -> np.ndarray:
    """``sweeps`` relaxation sweeps of the block set's equations on ``level`` from the unique nodes
    ``values`` (count, dim); ``f``: None, or (per block the padded interior right-hand side,
    per rule the right-hand side at its nodes). Returns the new unique nodes."""
    layout = level.layout
    buffer = layout.load(values)
    padded = layout.views(buffer)
    values = values.copy()  # up to date at ``level.touched``, the nodes the rules read
    for _ in range(sweeps):
        slide_step = None
        if level.slide_rule is not None:
            slide_step = level.slide_rule.residual(values)
            if f is not None:
                slide_step -= f[1][0]
        for block, R in enumerate(padded):
            rhs = None if f is None else f[0][block]
            walls = level.walls[block]
            wall_step = None if walls is None else slide_step[walls[0]]
            _relax_block(R, rhs, level.smoothers[block], level.weights[block], level.frozen[block], walls, wall_step)
        if len(level.touched):
            values[level.touched] = layout.read(buffer, level.touched)
        for number, rule in enumerate(level.rules):
            residual = rule.residual(values)
            values[rule.nodes] += residual if f is None else residual - f[1][number]
        if len(level.moved):
            layout.write(buffer, level.moved, values[level.moved])
        layout.exchange(buffer)
    return layout.unique(buffer)


def _defects(level: SetLevel, values: np.ndarray, f) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per block: the Winslow defect f - N at its own nodes (zero at frozen and boundary nodes),
    and the rules' defect f - S at its own nodes (zero elsewhere), both component-first."""
    halo = level.halo
    winslow = []
    for block, R in enumerate(level.layout.views(level.layout.load(values))):
        smoother = level.smoothers[block]
        with np.errstate(all="ignore"):
            full = _defect_block(R, None if f is None else f[0][block], smoother, level.weights[block])
        full[smoother.interior][(slice(None),) + level.frozen[block]] = 0.0
        winslow.append(np.ascontiguousarray(full[halo.inside(block)]))
    rule_defect = np.zeros_like(values)  # per cell size to the rule's power: compared across levels so
    for number, rule in enumerate(level.rules):
        residual = rule.residual(values)
        rule_defect[rule.nodes] = (-residual if f is None else f[1][number] - residual) / rule.spacing[:, None] ** rule.power
    return winslow, level.own(rule_defect)


def v_cycle_set(levels: list[SetLevel], index: int, values: np.ndarray, f) -> np.ndarray:
    """One FAS V-cycle of the block set's equations on ``levels[index]`` from the unique nodes
    ``values``; returns the new unique nodes."""
    level = levels[index]
    if index == len(levels) - 1:
        start = values.copy()
        solved = (
            None
            if level.newton is None
            else level.newton.solve(
                lambda x: _coarsest_residual(level, level.equations, x, f, start),
                values,
                DIRECT_TOL,
                DIRECT_REDUCTION,
                DIRECT_STEPS,
            )
        )
        if solved is None:
            return relax_set(level, values, f, COARSEST_SET_SWEEPS)
        kept = level.equations[3]
        solved[kept] = start[kept]  # exactly, as the relaxation keeps them (not to round-off)
        return solved
    values = relax_set(level, values, f, SMOOTHING)
    coarse = levels[index + 1]
    transfers = level.transfers
    own = level.own(values)
    start = coarse.halo.unique([t.transfer("restrict_solution", R) for t, R in zip(transfers, own)])
    winslow, rules = _defects(level, values, f)
    coarse_winslow = []
    for block, (t, defect, R) in enumerate(zip(transfers, winslow, coarse.layout.views(coarse.layout.load(start)))):
        smoother = coarse.smoothers[block]
        with np.errstate(all="ignore"):
            operator = _operator_block(R, smoother, coarse.weights[block])
        padded = np.zeros_like(R)
        padded[coarse.halo.inside(block)] = t.transfer("restrict_residual", defect)
        coarse_winslow.append(operator + padded[smoother.interior])
    restricted = coarse.halo.unique([t.transfer("restrict_solution", D) for t, D in zip(transfers, rules)])
    coarse_rules = [rule.residual(start) + restricted[rule.nodes] * rule.spacing[:, None] ** rule.power for rule in coarse.rules]
    solved = v_cycle_set(levels, index + 1, start.copy(), (coarse_winslow, coarse_rules))
    correction = coarse.own(solved - start)
    values = values + level.halo.unique([t.transfer("prolong", C) for t, C in zip(transfers, correction)])
    return relax_set(level, values, f, SMOOTHING)


def solve_set(block_set, Xs, tol: float, max_cycles: int, slide: bool = True, progress=None):
    """V-cycles of the block set's equations from the conforming node arrays ``Xs`` until a cycle
    moves no node by more than ``tol`` times its local cell size (``local_cell_sizes`` of ``Xs``)
    or ``max_cycles`` cycles, Anderson mixing of the cycles as for one block. Returns (unique nodes
    (count, dim) in ``global_numbering``'s order, cycles, last update, the levels' cell counts)."""
    numbering, count = global_numbering(block_set)
    lengths = [(mean_length(Xs[i.a], i.face_a.axis), mean_length(Xs[i.b], i.face_b.axis)) for i in block_set.interfaces]
    levels = set_levels(block_set, Xs, lengths, slide=slide)
    sizes = local_cell_sizes(block_set, Xs, numbering, count)
    values = gather(Xs, numbering, count)
    mixing = AndersonMixing(ANDERSON_DEPTH)
    update, cycles, first = np.inf, 0, None
    while cycles < max_cycles:
        before = values
        output = v_cycle_set(levels, 0, values, None)
        cycles += 1
        previous, update = update, float(np.max(np.linalg.norm(output - before, axis=-1) / sizes))
        if not np.isfinite(update):  # diverged: hand back the last finite state
            values = before
            break
        first = first or update
        if progress is not None:
            progress(progress_fraction(first, update, tol), cycle=cycles, update=update)
        if update < tol:
            values = output
            break
        if update > previous:
            mixing.restart()
        values = mixing.next_iterate(before, output)
    cells = [[[len(t) - 1 for t in c] for c in level.block_set.coords] for level in levels]
    return values, cycles, update, cells
