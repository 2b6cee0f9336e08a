"""The network and its plain-data description (design notes §6).

A trained map is fully described by ``checkpoint["model"]``, plain data that needs none of the
training code::

    {"dim": 3, "widths": [85, 85, 85, 85], "activation": "tanh", "input": "2*xi-1",
     "exact_boundary": False, "center": [x, y, z], "scale": s,
     "state_dict": {"layers.0.weight": (w0, dim), "layers.0.bias": (w0,), ...}}

The MLP reads u = 2 xi - 1 (parametric coordinates moved to [-1, 1]), applies tanh after every
layer but the last, and returns N(xi) in normalised units. The physical map is

    soft boundary:   X(xi) = center + scale * N(xi)
    exact boundary:  X(xi) = TFI(xi) + scale * b(xi) N(xi),  b = 4^d prod_i xi_i (1 - xi_i),

with TFI the transfinite interpolant of the geometry's boundary map; b vanishes on the cube's
boundary, so there the map is the geometry's boundary exactly. ``mesh_from_checkpoint`` evaluates
either form on a tensor grid (``meshgen.neural.network_map``).
"""

from __future__ import annotations

import numpy as np
import torch

from meshgen.geometry.cube import face_samples
from meshgen.geometry.layout import trained_layout, with_layout
from meshgen.geometry.plugins import load_recorded_geometry
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.network_map import CHUNK_NODES, mesh_from_model

__all__ = ["MLP", "bubble", "normalisation", "describe", "load_checkpoint", "mesh_from_checkpoint"]

INPUT_MAP = "2*xi-1"


class MLP(torch.nn.Module):
    """(N, dim) parametric points in [0, 1]^dim -> (N, dim) normalised physical points."""

    def __init__(self, dim: int, widths: list[int]):
        super().__init__()
        sizes = [dim, *widths, dim]
        self.layers = torch.nn.ModuleList(torch.nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))

    def forward(self, xi: torch.Tensor) -> torch.Tensor:
        return self.layers[-1](self.hidden(xi))

    def hidden(self, xi: torch.Tensor) -> torch.Tensor:
        """The last hidden layer (N, widths[-1]) at ``xi`` (N, dim)."""
        hidden = 2.0 * xi - 1.0
        for layer in self.layers[:-1]:
            hidden = torch.tanh(layer(hidden))
        return hidden


def bubble(xi):
    """b(xi) = 4^d prod_i xi_i (1 - xi_i): 1 at the cube's centre, 0 on its boundary.
    ``xi``: (..., d) array or tensor -> (...)."""
    dim = xi.shape[-1]
    return 4.0**dim * (xi * (1.0 - xi)).prod(-1)


def normalisation(geometry, samples: int = 17) -> tuple[np.ndarray, float]:
    """Centre and scale that map the geometry into [-1/2, 1/2]^d: the centre of the bounding box of
    the boundary (sampled on a ``samples``-per-edge grid of every face) and its largest extent."""
    mapped = geometry.boundary(face_samples(geometry.dim, samples))
    low, high = mapped.min(axis=0), mapped.max(axis=0)
    return (low + high) / 2.0, float(np.max(high - low))


def normalised_boundary(geometry, center, scale):
    """The geometry's boundary map in normalised units: (N, d) -> (N, d) float64."""
    center = np.asarray(center, dtype=float)
    return lambda points: (geometry.boundary(points) - center) / scale


def describe(network: MLP, widths, exact_boundary: bool, center, scale) -> dict:
    """The plain-data description of a trained map (see the module docstring)."""
    return {
        "dim": network.layers[0].in_features,
        "widths": [int(w) for w in widths],
        "activation": "tanh",
        "input": INPUT_MAP,
        "exact_boundary": bool(exact_boundary),
        "center": [float(c) for c in center],
        "scale": float(scale),
        "state_dict": {k: v.detach().cpu().clone() for k, v in network.state_dict().items()},
    }


def network_from_description(model: dict) -> MLP:
    """Rebuild the MLP of a ``checkpoint["model"]`` description (float32, CPU, eval mode)."""
    network = MLP(int(model["dim"]), list(model["widths"]))
    network.load_state_dict(model["state_dict"])
    return network.eval()


def mesh_from_checkpoint(checkpoint: dict, coords, geometry=None, chunk: int | None = None) -> np.ndarray:
    """The trained map on the tensor grid of 1D parametric coordinates ``coords`` (one array per axis).

    ``checkpoint``: a dict from ``load_checkpoint`` (only ``"model"`` and, for the exact-boundary form
    without ``geometry``, ``"geometry"`` are read). ``geometry``: the bound Geometry, needed for the
    exact-boundary form (loaded from the checkpoint's name and parameters when omitted).
    Evaluated without autograd in cache-sized chunks of nodes (``meshgen.neural.network_map``).
    Returns the node array X, shape (len(coords[0]), ..., dim), float64.
    """
    model = checkpoint["model"]
    if model["exact_boundary"] and geometry is None:
        geometry = geometry_from_checkpoint(checkpoint)
    if geometry is not None:  # the boundary the network was trained on
        geometry = with_layout(geometry, trained_layout(checkpoint))
    return mesh_from_model(model, coords, geometry, chunk=chunk or CHUNK_NODES)


def geometry_from_checkpoint(checkpoint: dict):
    """The geometry a checkpoint was trained on, with its parameters (by name or plugin path)."""
    entry = checkpoint["geometry"]
    return load_recorded_geometry(entry["spec"], dict(entry["params"]), where="the checkpoint")
