"""A trained network's mesh made and boundary-corrected on a GPU slab by slab, for meshes whose
node array is larger than the device's memory (1e9 hexahedra: 24 GB of float64 nodes).

The arithmetic is the chunked path's (``meshgen.run.chunked.neural_array``) moved to torch
tensors on the device: what is face-sized is made once on the host (the boundary map at the face
nodes, the exact-boundary TFI face terms, the network's boundary error and its correction terms,
``meshgen.methods.correction``) and copied to the device; each slab of node planes i0 <= i < i1
is then

    X = scale b(xi) N(xi) + TFI[g](xi) + TFI_8[g - M](xi),  boundary nodes set to g exactly,

N the network (float32, as in training), everything after it in float64. The result agrees with
the CPU mesh to the float32 rounding of N (the CPU runs N in a fixed-order numba kernel, the GPU
in cuBLAS products: scale x 1e-7 or so), not bit for bit.

``slabs`` yields the slabs with a one-node halo on each side (what a per-cell metric needs for the
cells' face neighbours): the device holds a few slabs at a time, never the whole mesh.
"""

from __future__ import annotations

import numpy as np
import torch

from meshgen.geometry import cube
from meshgen.methods.correction import CORRECTION_POWER, correction_terms, error_figures
from meshgen.methods.tfi import face_terms, face_values
from meshgen.neural.gpu_forward import network_layers, network_on_planes
from meshgen.neural.network_map import is_section_model, model_boundary_errors
from meshgen.quality.kernels import DEGENERATE_TOLERANCE

__all__ = ["SLAB_PLANES", "SlabMesher", "slabs"]

SLAB_PLANES = 32  # node planes per slab: at 1001^2 nodes a plane, 0.77 GB of float64 nodes


def _blend(t: torch.Tensor, side: int, power: int) -> torch.Tensor:
    """``meshgen.methods.tfi.blending`` on a tensor."""
    weight = t if side else 1.0 - t
    return weight if power == 1 else weight**power


def _along(values: torch.Tensor, axis: int, dim: int) -> torch.Tensor:
    """1D ``values`` shaped to broadcast along ``axis`` of a (.., dim)-component grid."""
    return values.reshape([-1 if d == axis else 1 for d in range(dim)] + [1])


class SlabMesher:
    """The face-sized data of a network's mesh on the tensor grid of ``coords`` (1D float64 arrays
    from 0 to 1, one per axis; 3D) on ``device``, and the slabs of node planes made from it.

    ``model``: a ``checkpoint["model"]`` description; ``geometry``: the Geometry it was trained on;
    ``correct``: add the boundary correction TFI_8[g - M] and set the boundary nodes to g."""

    def __init__(self, model: dict, geometry, coords, device="cuda", correct: bool = True):
        self.device = torch.device(device)
        self.coords = [np.asarray(c, dtype=float) for c in coords]
        self.shape = tuple(len(c) for c in self.coords)
        if len(self.shape) != 3 or is_section_model(model, self.coords):
            raise ValueError("SlabMesher makes 3D meshes of 3D networks (a section model is meshed by map_on_block)")
        values = face_values(geometry.boundary, self.coords)
        self.exact = bool(model["exact_boundary"])
        self.scale = float(model["scale"])
        self.center = torch.as_tensor(np.asarray(model["center"], dtype=float), device=self.device)
        to_device = self._to_device
        self.t = [to_device(c) for c in self.coords]  # float64 parametric coordinates
        self.u = [(2.0 * torch.from_numpy(c)).float().to(self.device) - 1.0 for c in self.coords]  # network inputs
        self.layers = [(w.to(self.device), b.to(self.device)) for w, b in network_layers(model)]
        terms = face_terms(values, self.coords) if self.exact else None
        self.tfi_terms = [(a, s, to_device(D)) for a, s, D in terms] if self.exact else None
        self.info = {"corrected": False}
        self.error_terms = None
        self.values = None
        if correct:
            errors = model_boundary_errors(model, geometry, self.coords, self.device.type, values, terms)
            self.info = {"corrected": True, "error_before": error_figures(errors, geometry)}
            corners, rest = correction_terms(errors, self.coords)
            self.error_terms = (to_device(corners), [(a, s, to_device(D)) for a, s, D in rest])
            self.values = [to_device(v) for v in values]
        # The degenerate-edge tolerance from the boundary nodes' bounding box (the CPU path takes
        # all nodes': the same for a mesh inside its boundary's box, as a corrected mesh is)
        low = np.min([v.reshape(-1, 3).min(axis=0) for v in values], axis=0)
        high = np.max([v.reshape(-1, 3).max(axis=0) for v in values], axis=0)
        self.tolerance = DEGENERATE_TOLERANCE * float(np.linalg.norm(high - low))

    def _to_device(self, array) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(array, dtype=float), device=self.device)

    def _face_terms(self, terms, i0: int, i1: int, out: torch.Tensor, power: int) -> None:
        """``meshgen.methods.tfi.add_face_terms`` on node planes i0 <= i < i1, into ``out``."""
        for axis, side, D in terms:
            t = self.t[axis][i0:i1] if axis == 0 else self.t[axis]
            on_slab = D if axis == 0 else D[i0:i1]
            out += _along(_blend(t, side, power), axis, 3) * on_slab.unsqueeze(axis)

    def _multilinear(self, corner_values: torch.Tensor, i0: int, i1: int) -> torch.Tensor:
        """``meshgen.methods.correction.multilinear`` of the corner values on node planes i0..i1-1."""
        values = corner_values.reshape((2, 2, 2) + corner_values.shape[1:])
        for axis in reversed(range(3)):
            t = self.t[axis][i0:i1] if axis == 0 else self.t[axis]
            shape = (-1,) + (1,) * (3 - axis)
            low, high = (_blend(t, side, CORRECTION_POWER).reshape(shape) for side in (0, 1))
            before = (slice(None),) * axis
            values = low * values[before + (0, None)] + high * values[before + (1, None)]
        return values

    def planes(self, i0: int, i1: int) -> torch.Tensor:
        """Node planes i0 <= i < i1 of the corrected mesh: (i1 - i0, n2, n3, 3) float64 on the device."""
        n1, n2, n3 = self.shape
        N = network_on_planes(self.layers, self.u, i0, i1).double().reshape(i1 - i0, n2, n3, 3)
        if not self.exact:
            X = N * self.scale + self.center
        else:
            bubble = torch.ones((1, 1, 1), dtype=torch.float64, device=self.device)
            for axis, t in enumerate(self.t):
                t = t[i0:i1] if axis == 0 else t
                bubble = bubble * (4.0 * t * (1.0 - t)).reshape([-1 if d == axis else 1 for d in range(3)])
            X = N * (self.scale * bubble)[..., None]
            self._face_terms(self.tfi_terms, i0, i1, X, 1)
        if self.error_terms is not None:
            corners, rest = self.error_terms
            X += self._multilinear(corners, i0, i1)
            self._face_terms(rest, i0, i1, X, CORRECTION_POWER)
            self._snap(X, i0, i1)
        return X

    def _snap(self, X: torch.Tensor, i0: int, i1: int) -> None:
        """The boundary nodes among planes i0..i1-1 set to the boundary map's values exactly."""
        for face, g in zip(cube.faces(3), self.values):
            end = self.shape[face.axis] - 1 if face.side else 0
            if face.axis == 0:
                if i0 <= end < i1:
                    X[end - i0] = g
            elif face.axis == 1:
                X[:, end] = g[i0:i1]
            else:
                X[:, :, end] = g[i0:i1]


def slabs(mesher: SlabMesher, planes: int = SLAB_PLANES):
    """The mesh of ``mesher`` in slabs: yields (i0, i1, X) for the cells' planes i0 <= i < i1 (node
    planes i0..i1 belong to them), X the node planes max(i0 - 1, 0) .. min(i1 + 1, n1 - 1) (a
    one-plane halo where there is one) as (planes, n2, n3, 3) float64 on the device, and
    ``first`` = i0 - max(i0 - 1, 0), the halo planes before the slab's first node plane."""
    cells = mesher.shape[0] - 1
    for i0 in range(0, cells, planes):
        i1 = min(cells, i0 + planes)
        lo, hi = max(i0 - 1, 0), min(i1 + 1, cells)
        yield i0, i1, i0 - lo, mesher.planes(lo, hi + 1)
