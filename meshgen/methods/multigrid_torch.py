"""The one-grid elliptic solver of ``meshgen.methods.multigrid`` as torch tensor operations, so that
it runs on a GPU (``device="cuda"``) as well as on torch's CPU device: the same discrete Winslow
equations (``meshgen.methods.winslow``), the same FAS V(1,1) cycles with line-ADI relaxation, the
same grid hierarchy and transfers (``hierarchy``, built by the NumPy module from the 1D parametric
coordinates), the same full-multigrid start, stopping test and Anderson mixing, in float64.

What differs is only how the pieces are computed:

- stencils: shifted slices of the component-first array (dim, n1+1, ...), every weight a tensor
  (a uniform axis too), so the residual is the NumPy operator's to rounding;
- line solves: parallel cyclic reduction (PCR) along the axis, ceil(log2 m) steps over the whole
  array (each step a handful of element-wise operations; no loop over the nodes of a line, which
  the Thomas algorithm needs: m sequential steps, each a kernel launch on a GPU);
- transfers: the dense 1D interpolation matrices applied axis by axis (``tensordot``);
- on CUDA the finest-grid V-cycle is captured once as a CUDA graph and replayed, so that a cycle
  costs its kernels' time and not Python's launch overhead (thousands of small kernels per cycle).

Only this module imports torch; the method's CPU path never loads it (``meshgen.methods.elliptic``
imports it when a GPU device is asked for).
"""

from __future__ import annotations

import itertools
import time

import numpy as np
import torch
import torch.nn.functional as tf

from meshgen.methods.anderson import ANDERSON_DEPTH
from meshgen.methods.multigrid import (
    COARSEST_SWEEPS,
    DAMPING,
    DEFAULT_MAX_ITER,
    DEFAULT_TOL,
    POST_SMOOTHING,
    PRE_SMOOTHING,
    Level,
    hierarchy,
    progress_fraction,
)
from meshgen.methods.winslow import component_array, node_array

__all__ = [
    "TorchLevel",
    "solve_lines_pcr",
    "solve_winslow_torch",
    "torch_hierarchy",
    "torch_operator",
    "torch_smooth",
    "torch_v_cycle",
]


class TorchLevel:
    """One grid of the hierarchy on a torch device: the stencil weights (minus, centre, plus) of the
    first and second derivatives per axis as float64 tensors shaped to broadcast over the interior
    nodes ((n_a - 1) along axis a, 1 elsewhere; the first derivative's centre None when zero), and
    the transfers to the next coarser grid as dense matrices (rows, columns) per axis."""

    def __init__(self, level: Level, device):
        grid = level.grid
        self.dim = grid.dim
        self.shape = tuple(len(t) for t in grid.coords)
        self.interior = (slice(None),) + (slice(1, -1),) * self.dim

        def weights(kind, axis, skip_zero_centre):
            shape = [1] * self.dim
            shape[axis] = self.shape[axis] - 2
            out = []
            for w in kind:
                if isinstance(w, float):
                    out.append(
                        None if (skip_zero_centre and w == 0.0) else torch.full(shape, w, dtype=torch.float64, device=device)
                    )
                else:
                    out.append(torch.as_tensor(np.ravel(w).reshape(shape), dtype=torch.float64, device=device))
            return tuple(out)

        self.first = [weights(w, a, True) for a, w in enumerate(grid.first)]
        self.second = [weights(w, a, False) for a, w in enumerate(grid.second)]
        self.transfers = {}
        self.solver = None  # the coarsest grid's solve as a replayed CUDA graph (``_coarsest_solve``)
        if hasattr(level, "prolong"):
            for name in ("prolong", "restrict_solution", "restrict_residual"):
                self.transfers[name] = [torch.as_tensor(m, dtype=torch.float64, device=device) for m in getattr(level, name)]

    def transfer(self, name: str, F: torch.Tensor) -> torch.Tensor:
        """The transfer ``name`` (prolong, restrict_solution, restrict_residual) applied to F (dim, ...)."""
        for axis, matrix in enumerate(self.transfers[name], start=1):
            F = torch.tensordot(matrix, F, dims=([1], [axis])).movedim(0, axis)
        return F.contiguous()

    def defect(self, R: torch.Tensor, f) -> torch.Tensor:
        """f - N(R) (``f`` None: zero) at the interior nodes, zero on the boundary: shaped as R."""
        residual, _ = torch_operator(R, self)
        full = torch.zeros_like(R)
        full[self.interior] = -residual if f is None else f - residual
        return full


def torch_hierarchy(coords, axis_weights, device) -> list[TorchLevel]:
    """The levels of ``meshgen.methods.multigrid.hierarchy`` (NumPy, its own coarsening rule) on ``device``."""
    return [TorchLevel(level, device) for level in hierarchy(coords, axis_weights, compiled=False)]


def _along(F, axis: int, offset: int, trimmed: tuple):
    """View of F (dim, ...) at its inner nodes along ``axis`` shifted by ``offset``, and at the inner
    nodes of the ``trimmed`` axes (the rest whole)."""
    index = [slice(None)] * F.ndim
    for other in trimmed:
        index[other + 1] = slice(1, -1)
    index[axis + 1] = slice(1 + offset, F.shape[axis + 1] - 1 + offset)
    return F[tuple(index)]


def _stencil(F, axis: int, weights, trimmed: tuple = ()):
    """Three-point stencil (minus, centre, plus) along ``axis`` of F (dim, ...), at F's inner nodes
    along ``axis`` and the ``trimmed`` axes."""
    minus, centre, plus = weights
    values = plus * _along(F, axis, 1, trimmed) + minus * _along(F, axis, -1, trimmed)
    if centre is not None:
        values = values + centre * _along(F, axis, 0, trimmed)
    return values


def torch_operator(R: torch.Tensor, level: TorchLevel):
    """``meshgen.methods.winslow.winslow_operator`` in torch: the normalised Winslow residual at the
    interior nodes (dim, n1-1, ...) and the axial coefficients A_aa / trace(A), each (n1-1, ...)."""
    axes = range(level.dim)
    along = [_stencil(R, a, level.first[a]) for a in axes]
    r = [along[a][(slice(None),) + tuple(slice(None) if b == a else slice(1, -1) for b in axes)] for a in axes]
    g = {(a, b): (r[a] * r[b]).sum(0) for a in axes for b in range(a, level.dim)}
    if level.dim == 3:
        g11, g22, g33, g12, g23, g13 = g[0, 0], g[1, 1], g[2, 2], g[0, 1], g[1, 2], g[0, 2]
        A = {
            (0, 0): g22 * g33 - g23 * g23,
            (1, 1): g11 * g33 - g13 * g13,
            (2, 2): g11 * g22 - g12 * g12,
            (0, 1): g13 * g23 - g12 * g33,
            (1, 2): g12 * g13 - g11 * g23,
            (0, 2): g12 * g23 - g13 * g22,
        }
    else:
        A = {(0, 0): g[1, 1], (1, 1): g[0, 0], (0, 1): -g[0, 1]}
    inverse_trace = 1.0 / sum(A[a, a] for a in axes)
    residual = None
    for a, b in itertools.combinations(axes, 2):
        values = _stencil(along[b], a, level.first[a], tuple(c for c in axes if c not in (a, b)))
        term = values * (2.0 * A[a, b] * inverse_trace)
        residual = term if residual is None else residual + term
    axial = [A[a, a] * inverse_trace for a in axes]
    for a in axes:
        residual = residual + _stencil(R, a, level.second[a], tuple(b for b in axes if b != a)) * axial[a]
    return residual, axial


def _largest_node_norm(D: torch.Tensor) -> torch.Tensor:
    """Largest Euclidean norm over the nodes of a component-first tensor (dim, ...): a 0-d tensor."""
    return (D * D).sum(0).max().sqrt()


def solve_lines_pcr(sub: torch.Tensor, sup: torch.Tensor, rhs: torch.Tensor, axis: int) -> torch.Tensor:
    """Solve ``x[i] + sub[i] x[i-1] + sup[i] x[i+1] = rhs[i]`` along every grid line parallel to
    ``axis`` at once by parallel cyclic reduction (``meshgen.methods.multigrid.solve_lines``'s
    systems: line ends couple to fixed boundary nodes, whose correction is zero).

    ``sub``, ``sup``: (m1, m2[, m3]); ``rhs``: (dim, m1, m2[, m3]). Each step eliminates the
    neighbours at distance s from every equation, which then couples to those at 2s; after
    ceil(log2 m) steps every equation is decoupled. Rows are kept normalised (diagonal 1). Stable
    without pivoting for the diagonally dominant systems of the relaxation (|sub| + |sup| < 1).
    """
    a = sub.movedim(axis, -1)
    c = sup.movedim(axis, -1)
    d = rhs.movedim(axis + 1, -1)
    size = a.shape[-1]
    stride = 1
    while stride < size:
        a_minus, c_minus, d_minus = (tf.pad(t[..., :-stride], (stride, 0)) for t in (a, c, d))
        a_plus, c_plus, d_plus = (tf.pad(t[..., stride:], (0, stride)) for t in (a, c, d))
        inverse = 1.0 / (1.0 - a * c_minus - c * a_plus)
        d = (d - a * d_minus - c * d_plus) * inverse
        a, c = -(a * a_minus) * inverse, -(c * c_plus) * inverse
        stride *= 2
    return d.movedim(-1, axis + 1)


def torch_smooth(R: torch.Tensor, f, level: TorchLevel, sweeps: int) -> torch.Tensor:
    """``meshgen.methods.multigrid.smooth`` in torch (R updated in place): line-ADI sweeps of
    N(R) = f. Returns the largest Jacobi step of the last sweep's start, a 0-d tensor."""
    jacobi_step = None
    for sweep in range(sweeps):
        residual, axial = torch_operator(R, level)
        if f is not None:
            residual = residual - f
        centre = -sum(c * w[1] for c, w in zip(axial, level.second))
        step = residual / centre
        if sweep == sweeps - 1:
            jacobi_step = _largest_node_norm(step)
        for axis, (coupling, (minus, _, plus)) in enumerate(zip(axial, level.second)):
            scale = coupling / centre
            step = solve_lines_pcr(-minus * scale, -plus * scale, step, axis)
        R[level.interior] += DAMPING * step
    return jacobi_step


def torch_v_cycle(levels: list[TorchLevel], index: int, R: torch.Tensor, f) -> torch.Tensor:
    """One FAS V-cycle for N(R) = f on ``levels[index]`` (``meshgen.methods.multigrid.v_cycle``; R in place)."""
    level = levels[index]
    if index == len(levels) - 1:
        if level.solver is not None:
            return level.solver(R, f)
        return torch_smooth(R, f, level, COARSEST_SWEEPS)
    torch_smooth(R, f, level, PRE_SMOOTHING)
    coarse = levels[index + 1]
    R_coarse_start = level.transfer("restrict_solution", R)
    full_residual = level.defect(R, f)
    coarse_f, _ = torch_operator(R_coarse_start, coarse)
    coarse_f = coarse_f + level.transfer("restrict_residual", full_residual)[coarse.interior]
    R_coarse = R_coarse_start.clone()
    torch_v_cycle(levels, index + 1, R_coarse, coarse_f)
    R += level.transfer("prolong", R_coarse - R_coarse_start)
    return torch_smooth(R, f, level, POST_SMOOTHING)


class _Anderson:
    """``meshgen.methods.anderson.AndersonMixing`` on tensors: the next iterate G(x) - dG gamma,
    gamma the least-squares fit of the update f = G(x) - x by the last ``depth`` update changes."""

    def __init__(self, depth: int):
        self.depth = depth
        self.restart()

    def restart(self) -> None:
        self.output_changes, self.update_changes, self.previous = [], [], None

    def next_iterate(self, x: torch.Tensor, output: torch.Tensor) -> torch.Tensor:
        if self.depth == 0:
            return output
        update = output - x
        if self.previous is not None:
            self.update_changes.append(update - self.previous[0])
            self.output_changes.append(output - self.previous[1])
            del self.update_changes[: -self.depth], self.output_changes[: -self.depth]
        self.previous = (update, output)
        if not self.update_changes:
            return output
        changes = torch.stack([u.reshape(-1) for u in self.update_changes])
        gram = (changes @ changes.T).cpu().numpy()
        target = (changes @ update.reshape(-1)).cpu().numpy()
        gamma = np.linalg.lstsq(gram, target, rcond=1e-12)[0]
        mixed = output.clone()
        for weight, change in zip(gamma, self.output_changes):
            mixed -= float(weight) * change
        return mixed


def _on_side_stream(function, *args):
    """``function(*args)`` run eagerly on a side CUDA stream, as the warm-up before a graph capture
    should be (torch.cuda.graphs); the caller's stream waits for it. The solver's warm-ups are work
    it needs anyway (the first coarsest solve, the first finest cycle), so they cost nothing extra."""
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        output = function(*args)
    torch.cuda.current_stream().wait_stream(side)
    return output


def _capture(function, *static):
    """A CUDA graph of ``function(*static)`` and the output tensor of the captured call (capture runs
    nothing: ``static`` keeps its values)."""
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        output = function(*static)
    return graph, output


def _coarsest_solve(levels: list[TorchLevel], R: torch.Tensor, graph: bool) -> None:
    """The full-multigrid start's solve of the coarsest grid (R in place); with ``graph`` (CUDA) run as
    the warm-up on a side stream, after which the coarsest level gets a ``solver(R, f)``: its
    ``COARSEST_SWEEPS`` relaxation sweeps (thousands of tiny kernels) as one replayed CUDA graph
    (f None is f = 0: the same arithmetic)."""
    level = levels[-1]
    if not graph:
        torch_v_cycle(levels, len(levels) - 1, R, None)
        return
    _on_side_stream(torch_v_cycle, levels, len(levels) - 1, R, None)
    static_R = R.clone()
    static_f = torch.zeros_like(R[level.interior])
    captured, static_step = _capture(lambda r, f: torch_smooth(r, f, level, COARSEST_SWEEPS), static_R, static_f)

    def solver(R, f):
        static_R.copy_(R)
        static_f.copy_(f) if f is not None else static_f.zero_()
        captured.replay()
        R.copy_(static_R)
        return static_step.clone()

    level.solver = solver


def _cycle(levels: list[TorchLevel], graph: bool):
    """The finest-grid V-cycle as a function ``cycle(R) -> (new R, Jacobi step)``: with ``graph`` (CUDA)
    the first call runs eagerly (the warm-up, on a side stream) and captures the cycle as a CUDA graph,
    which the later calls replay on a static input; else eager."""

    def eager(state):
        out = state.clone()
        return out, torch_v_cycle(levels, 0, out, None)

    if not graph:
        return eager
    captured = []

    def replay(state):
        if not captured:
            out, step = _on_side_stream(eager, state)
            static = state.clone()
            coarsest, levels[-1].solver = levels[-1].solver, None  # the graph holds the coarsest sweeps themselves
            captured.extend((static, *_capture(lambda r: torch_v_cycle(levels, 0, r, None), static)))
            levels[-1].solver = coarsest
            return out, step
        static, graph_, static_step = captured
        static.copy_(state)
        graph_.replay()
        return static.clone(), static_step.clone()

    return replay


def _graphs_possible(device) -> bool:
    """Whether the solver can capture CUDA graphs on ``device`` (a CUDA device)."""
    return device.type == "cuda"


def _clock(device, start: float) -> float:
    """Seconds since ``start``, the device's queued work finished first (CUDA)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter() - start


def solve_winslow_torch(
    X0: np.ndarray,
    coords,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ITER,
    length: float = 1.0,
    device="cpu",
    progress=None,
    graph: bool = True,
):
    """``meshgen.methods.multigrid.solve_winslow`` on the torch device ``device`` ("cpu", "cuda", ...).

    ``X0``: initial node array (n1+1, n2+1[, n3+1], dim), float64, its boundary nodes kept;
    ``coords``: parametric node coordinates per axis; ``tol``, ``max_iter``, ``length``,
    ``progress``: as ``solve_winslow``'s; ``graph``: on CUDA, replay the finest cycle as a CUDA graph.
    Returns ``(X, info)``: the node array (NumPy float64, same shape as X0) and an info dict with
    ``solve_winslow``'s keys plus ``device`` and ``phase_seconds`` (setup: copy to the device, hierarchy;
    start: full-multigrid start; cycles: the finest-grid cycles, the capture of their CUDA graph included).
    """
    start = time.perf_counter()
    device = torch.device(device)
    R0 = torch.as_tensor(component_array(X0), dtype=torch.float64, device=device)
    finest = TorchLevel(Level(coords), device)
    _, axial = torch_operator(R0, finest)
    axial = torch.stack([a.reshape(-1) for a in axial])
    if axial.numel() <= 2**24:  # torch.quantile's limit; linear interpolation: NumPy's median
        weights = torch.quantile(axial, 0.5, dim=1).tolist()
    else:
        weights = np.median(axial.cpu().numpy(), axis=1).tolist()
    levels = torch_hierarchy(coords, weights, device)
    phases = {"setup": _clock(device, start)}
    starts = [R0]
    for level in levels[:-1]:
        starts.append(level.transfer("restrict_solution", starts[-1]))

    graph = graph and _graphs_possible(device)
    R = starts[-1].clone()
    _coarsest_solve(levels, R, graph)
    for index in range(len(levels) - 2, -1, -1):
        R = starts[index] + levels[index].transfer("prolong", R - starts[index + 1])
        if index > 0:
            torch_v_cycle(levels, index, R, None)
    del starts
    phases["start"] = _clock(device, start) - sum(phases.values())
    cycle = _cycle(levels, graph)

    acceleration = _Anderson(ANDERSON_DEPTH)
    update, first_update, iterations = np.inf, None, 0
    while True:
        before = R
        R, step = cycle(before)
        iterations += 1
        previous_update = update
        figures = torch.stack([_largest_node_norm(R - before), step]).cpu().numpy() / length
        update, residual = float(figures[0]), float(figures[1])
        if not np.isfinite(update):
            R = before
            break
        first_update = first_update or update
        if progress is not None:
            progress(progress_fraction(first_update, update, tol), cycle=iterations, update=update, residual=residual)
        if update < tol or iterations >= max_iter:
            break
        if update > previous_update:
            acceleration.restart()
        R = acceleration.next_iterate(before, R)

    phases["cycles"] = _clock(device, start) - sum(phases.values())  # the first one's graph capture included
    step, axial = torch_operator(R, levels[0])
    centre = -sum(c * w[1] for c, w in zip(axial, levels[0].second))
    final_residual = float(_largest_node_norm(step / centre)) / length
    X = node_array(R.cpu().numpy())
    info = {
        "solver": "nonlinear multigrid on torch (FAS V(1,1) cycles, line-ADI relaxation by parallel cyclic "
        "reduction, full-multigrid start, Anderson mixing)",
        "iterations": iterations,
        "final_update": float(update),
        "final_residual": final_residual,
        "tol": float(tol),
        "converged": bool(update < tol),
        "seconds": time.perf_counter() - start,
        "levels": [list(np.array(level.shape) - 1) for level in levels],
        "device": str(device),
        "phase_seconds": phases,
    }
    info["levels"] = [[int(n) for n in shape] for shape in info["levels"]]
    return X, info
