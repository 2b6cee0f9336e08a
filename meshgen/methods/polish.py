"""Polish: the discrete Winslow equations solved at the mesh's own resolution, starting from the
network's mesh (design notes, fidelity section).

A trained network approximates the continuous Winslow map; a flow solver sees the discrete mesh.
Measured on the semicylinder at 20x20x40 (potentialFoam, exact answer U = (0, 0, 1)): the bundled
network's mesh departs from the discrete Winslow solution by 3e-3 of the radius next to the inlet
(its layers are not extruded: a sideways shift of 1.8% of the layer's depth in the first layer),
which gives max |U - U_exact| = 0.20 where the elliptic mesh gives 2.6e-5. No boundary blending
removes that (it is the network's interior, and an exact-boundary network has no boundary error to
blend), and the layout's fine-grid faces alone give 0.31 even with a converged interior: the faces
must be the discrete surface grids at the mesh's resolution (``meshgen.geometry.layout.relax_faces``), as
the elliptic method makes them.

So the polish does what the elliptic method does after its start: relax the faces (smoothed
layout), then multigrid cycles of ``meshgen.methods.elliptic.solve_winslow`` from the network's nodes until
no node moves by more than ``tol`` of the characteristic length. The result is the elliptic mesh
to within that tolerance; the network supplies the starting mesh.

Whether ``meshgen mesh`` polishes by default depends on how the network was trained
(``polishes_by_default``): a network trained with the exact boundary on the smoothed layout's fine
lattice (``model.exact_boundary``, ``points.lattice``, ``boundary_layout: smoothed``; the ``exact``
preset, the bundled model) has faces that solve the discrete Winslow equations and an interior
that is their extrusion, and its own mesh meets the solver-fidelity target (potentialFoam within
10x of the elliptic mesh's error); it is not polished unless asked. Every other network (the soft
boundary, the fixed layout, off the lattice, families) is polished unless ``--no-polish``.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry.layout import relax_faces
from meshgen.methods.elliptic import extruded_solve
from meshgen.methods.multigrid import DEFAULT_MAX_ITER, DEFAULT_TOL, solve_winslow

__all__ = ["NOT_POLISHED_REASON", "polish", "polishes_by_default"]

NOT_POLISHED_REASON = (
    "the network was trained with the exact boundary on the smoothed layout's lattice: its own mesh is solver-ready"
)


def polish(X: np.ndarray, geometry, coords, tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER) -> dict:
    """Polish node array ``X`` (n1+1, .., d) of the tensor grid ``coords`` in place: faces relaxed to
    their discrete surface grids when ``geometry`` has the smoothed layout (3D), then Winslow
    multigrid cycles from ``X`` until the largest node update is below ``tol`` times the
    characteristic length. Returns JSON-ready figures: cycles, final update, and the largest node
    move relative to the characteristic length (how far the network was); no wall-clock time, so
    that a mesh's recorded metadata repeats exactly (the meshing time is recorded beside it)."""
    length = float(geometry.characteristic_length)
    start = X.copy()
    smoothed = getattr(geometry.boundary_map, "smoothed_from", None) is not None and X.shape[-1] == 3
    # an extrusion (the semicylinder) is polished as the elliptic method solves it: its section's
    # 2D solve from the network's cap, extruded, so every layer stays the same (the 3D cycles left
    # layers apart by 7e-7 of the length and potentialFoam's error 130 times the raw mesh's)
    solved = extruded_solve(X, coords, tol, max_iter, length) if smoothed and min(len(c) for c in coords) >= 3 else None
    if solved is None and smoothed:
        relax_faces(geometry, coords, X)
    if solved is not None:
        X[...], info = solved
    elif min(len(c) for c in coords) >= 3:
        X[...], info = solve_winslow(X, coords, tol=tol, max_iter=max_iter, length=length)
    else:
        info = {"iterations": 0, "final_update": 0.0, "converged": True, "seconds": 0.0}
    moved = float(np.linalg.norm(X - start, axis=-1).max()) / length
    return {
        "polished": True,
        "cycles": int(info["iterations"]),
        "final_update": float(info["final_update"]),
        "converged": bool(info["converged"]),
        "largest_move_rel": moved,
    }


def polishes_by_default(checkpoint: dict) -> bool:
    """Whether a mesh of the network of ``checkpoint`` (a checkpoint dict: ``model``, ``config``) is
    polished when the user does not say (module docstring): False only for a network trained with
    the exact boundary on the smoothed layout's lattice; True for every other, and for a checkpoint
    that does not record its training configuration."""
    config = checkpoint.get("config") if isinstance(checkpoint.get("config"), dict) else {}
    points = config.get("points") if isinstance(config.get("points"), dict) else {}
    model = checkpoint.get("model") if isinstance(checkpoint.get("model"), dict) else {}
    lattice_exact = (
        model.get("exact_boundary") is True and points.get("lattice") is True and config.get("boundary_layout") == "smoothed"
    )
    return not lattice_exact
