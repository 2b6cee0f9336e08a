"""Inference: a trained map evaluated on a tensor grid of any size, and the choice of the model.

Evaluation (``evaluate_on_grid``, ``mesh_from_model``). A [85]*4 network on 101^3 nodes is about
4.6e10 flop, nearly all in the three 85 x 85 products. Three things keep it near the matrix-product
bound on a small CPU:

- no autograd (``torch.inference_mode``), ``addmm`` into buffers allocated once, ``tanh_`` in place;
- chunks of ``CHUNK_NODES`` nodes, so a chunk's activations (8192 x 85 float32, 2.8 MB) stay in
  cache between layers (chunks of 131072 measured twice as slow);
- one single-threaded torch per worker thread, the workers taking chunks in turn (torch releases
  the GIL): measured 0.34 s for 101^3 nodes on 2 cores, against 0.44 s for torch's own 2 threads
  on each product, which are too small for it to split well.

The network's inputs are made per chunk from the 1D coordinates, so no (N, d) grid of parametric
points exists at any time; the only full-size array is the node array itself.

Boundary correction (``correct_boundary``): the boundary nodes of a structured grid sit at known
parametric points, where the exact boundary is the geometry's boundary map g. The mesh becomes
X = N + TFI[g - N]: the error g - N at the face nodes, interpolated into the volume by the same
Gordon-Hall sum as TFI. Exact on the boundary, smooth inside; the face terms are made once, and
any block of the grid can be corrected from them (``add_boundary_correction``, with the errors
from the grid's faces alone: ``model_boundary_errors``).

Model choice (``find_model``): an explicit checkpoint; else the newest ``runs/*/checkpoint.pt``
(skipping runs of another geometry or other parameters than the ones given); else the model
bundled in ``meshgen/_models/`` for its geometry with default parameters.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen import cube
from meshgen.errors import MeshgenError, ParameterError
from meshgen.neural.polish import polish as polish_mesh
from meshgen.tfi import add_face_terms, blending, boundary_faces, face_terms, transfinite_on_grid

CHUNK_NODES = 8192
CORRECTION_POWER = 8  # blending (1 - t)^p, t^p of the boundary correction (meshgen.tfi.blending)
GPU_CHUNK_NODES = 1 << 20  # 85-wide float32 activations: 350 MB per layer
MODELS_DIR = Path(__file__).resolve().parents[1] / "_models"
RUNS_DIR = "runs"


# ---------------------------------------------------------------------------------------------
# evaluation


def network_layers(model: dict):
    """The MLP of a ``checkpoint["model"]`` description as [(W^T (in, out), b (out,)), ...], float32
    torch tensors, checked against its ``dim`` and ``widths`` (a foreign description raises)."""
    from meshgen.neural.checkpoint import CheckpointError

    try:
        dim, widths = int(model["dim"]), [int(w) for w in model["widths"]]
        state = model["state_dict"]
        sizes = [dim, *widths, dim]
        layers = []
        for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            weight, bias = state[f"layers.{index}.weight"], state[f"layers.{index}.bias"]
            if tuple(weight.shape) != (fan_out, fan_in) or tuple(bias.shape) != (fan_out,):
                raise ValueError(f"layer {index} has shape {tuple(weight.shape)}, expected {(fan_out, fan_in)}")
            # The transposed view, as torch.nn.Linear multiplies: the same kernel, the same rounding.
            layers.append((weight.detach().float().t(), bias.detach().float()))
        if len(state) != 2 * len(layers):
            raise ValueError("extra weights")
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"the checkpoint's model description is not a meshgen network ({exc})") from None
    if model.get("activation", "tanh") != "tanh" or model.get("input", "2*xi-1") != "2*xi-1":
        raise CheckpointError(
            f"the checkpoint's network uses activation {model.get('activation')!r} and input "
            f"{model.get('input')!r}; this meshgen evaluates tanh networks of 2*xi-1"
        )
    return layers


def _grid_inputs(axes, start: int, stop: int):
    """Network inputs u = 2 xi - 1 of the nodes ``start .. stop-1`` of the C-order tensor grid of
    ``axes`` (1D float32 tensors of u per axis): (stop - start, d) float32."""
    import torch

    flat = torch.arange(start, stop, device=axes[0].device)
    columns = []
    for axis in reversed(axes):  # the last axis varies fastest
        columns.append(axis[flat % len(axis)])
        flat = flat // len(axis)
    return torch.stack(columns[::-1], dim=1)


def inference_device(device: str = "auto") -> str:
    """``"cpu"`` or ``"cuda"``: ``auto`` picks cuda when torch sees a GPU; cuda without one raises."""
    import torch

    if device not in ("auto", "cpu", "cuda"):
        raise ParameterError("device", f"unknown {{name}} {device!r}: pick auto, cpu or cuda")
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise ParameterError("device", "{name} cuda: no CUDA device is available to torch here; use cpu")
    return device


def evaluate_on_grid(
    model: dict, coords, out: np.ndarray | None = None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu"
) -> np.ndarray:
    """The network N(xi) of ``model`` (normalised units) at the tensor grid of the 1D parametric
    coordinates ``coords`` (one array per axis, values in [0, 1]).

    Returns (or fills ``out`` with) an array of shape (n1 * n2 [* n3], d), float64, nodes in C order.
    ``workers``: threads taking the chunks in turn, each running a single-threaded torch
    (default: torch's thread count). ``device``: "cpu", "cuda" or "auto" (:func:`inference_device`);
    on a GPU the grid goes through in chunks of ``GPU_CHUNK_NODES``.
    """
    import threading
    from concurrent.futures import ThreadPoolExecutor

    import torch

    layers = network_layers(model)
    dim = int(model["dim"])
    if len(coords) != dim:
        raise MeshgenError(f"the network maps {dim}D points: {len(coords)} coordinate axes given")
    # u = 2 xi - 1 in float32, as the network computes it in training
    axes = [2.0 * torch.from_numpy(np.asarray(c, dtype=np.float64)).float() - 1.0 for c in coords]
    count = int(np.prod([len(c) for c in coords]))
    if out is None:
        out = np.empty((count, dim))
    if inference_device(device) == "cuda":
        return _evaluate_on_gpu(layers, axes, count, out)
    widths = [bias.shape[0] for _, bias in layers]
    local = threading.local()

    def run(start):
        stop = min(count, start + chunk)
        if not hasattr(local, "buffers"):
            local.buffers = [torch.empty(chunk, width) for width in widths]
        with torch.inference_mode():
            hidden = _grid_inputs(axes, start, stop)
            for index, ((weight, bias), buffer) in enumerate(zip(layers, local.buffers)):
                result = buffer[: stop - start]
                torch.addmm(bias, hidden, weight, out=result)
                if index < len(layers) - 1:
                    result.tanh_()
                hidden = result
            out[start:stop] = hidden.numpy()

    workers = workers or torch.get_num_threads()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # parallel over chunks instead: each product is too small to split
    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for _ in pool.map(run, range(0, count, chunk)):
                pass
    finally:
        torch.set_num_threads(threads)
    return out


def _evaluate_on_gpu(layers, axes, count: int, out: np.ndarray) -> np.ndarray:
    """:func:`evaluate_on_grid` on the GPU: large chunks (a GPU needs many rows per product to be
    busy), each copied back into ``out`` as it is done."""
    import torch

    device = torch.device("cuda")
    layers = [(weight.to(device), bias.to(device)) for weight, bias in layers]
    axes = [axis.to(device) for axis in axes]
    target = torch.from_numpy(out)  # the copies land in ``out`` itself, with no host array between
    with torch.inference_mode():
        for start in range(0, count, GPU_CHUNK_NODES):
            stop = min(count, start + GPU_CHUNK_NODES)
            hidden = _grid_inputs(axes, start, stop)
            for index, (weight, bias) in enumerate(layers):
                hidden = torch.addmm(bias, hidden, weight)
                if index < len(layers) - 1:
                    hidden = torch.tanh(hidden)
            target[start:stop].copy_(hidden.double())
    return out


def bubble_on_grid(coords) -> np.ndarray:
    """b(xi) = 4^d prod_i xi_i (1 - xi_i) on the tensor grid of ``coords``: (n1, n2 [, n3])."""
    dim = len(coords)
    result = np.ones([1] * dim)
    for axis, c in enumerate(coords):
        c = np.asarray(c, dtype=float)
        result = result * (4.0 * c * (1.0 - c)).reshape([-1 if d == axis else 1 for d in range(dim)])
    return result


def mesh_from_model(
    model: dict, coords, geometry=None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu"
) -> np.ndarray:
    """The physical map of ``model`` (a ``checkpoint["model"]`` description) on the tensor grid of
    ``coords``: the node array X, shape (len(coords[0]), ..., d), float64.

    Soft boundary: X = center + scale N(xi). Exact boundary: X = TFI(xi) + scale b(xi) N(xi), which
    needs ``geometry`` (the bound Geometry the model was trained on).
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    shape = tuple(len(c) for c in coords)
    dim = len(coords)
    X = evaluate_on_grid(model, coords, chunk=chunk, workers=workers, device=device).reshape(*shape, dim)
    scale = float(model["scale"])
    if not model["exact_boundary"]:
        X *= scale
        X += np.asarray(model["center"], dtype=float)
        return X
    if geometry is None:
        raise MeshgenError("an exact-boundary model needs its geometry to be evaluated")
    X *= (scale * bubble_on_grid(coords))[..., None]
    if coords and all(c[0] == 0.0 and c[-1] == 1.0 for c in coords):
        transfinite_on_grid(geometry.boundary, coords, out=X)
    else:  # a grid that does not span the cube: the direct form
        from meshgen.tfi import tfi

        X += tfi(geometry, None, coords)
    return X


# ---------------------------------------------------------------------------------------------
# boundary correction


def boundary_errors(X: np.ndarray, geometry, coords) -> list[np.ndarray]:
    """The boundary error field g - X at the face nodes of the tensor grid of ``coords`` (1D
    parametric node coordinates per axis, from 0 to 1): per face, in ``meshgen.cube`` order, an
    array (face nodes..., d), g the geometry's boundary map at the nodes' parametric points.

    ``X`` (n1+1, .., d) need only hold the face nodes (a block-wise caller may fill just those)."""
    faces = boundary_faces(coords)
    images = geometry.boundary(np.concatenate([points for _, points in faces]))
    errors, start = [], 0
    for index, points in faces:
        errors.append(images[start : start + len(points)].reshape(X[index].shape) - X[index])
        start += len(points)
    return errors


def model_boundary_errors(model: dict, geometry, coords, device: str = "cpu") -> list[np.ndarray]:
    """:func:`boundary_errors` of the map of ``model`` (a ``checkpoint["model"]`` description) on
    the tensor grid of ``coords``, for a caller that never holds the whole node array: the map is
    evaluated on each face of the grid alone (face-sized work), as :func:`mesh_from_model` would
    evaluate those nodes in the whole grid."""
    errors = []
    for index, points in boundary_faces(coords):
        axis = next(d for d, i in enumerate(index) if not isinstance(i, slice))
        face_coords = [np.asarray(c, dtype=float) for c in coords]
        face_coords[axis] = face_coords[axis][[index[axis]]]
        values = np.take(mesh_from_model(model, face_coords, geometry, device=device), 0, axis=axis)
        errors.append(geometry.boundary(points).reshape(values.shape) - values)
    return errors


def error_figures(errors, geometry) -> dict:
    """Max and mean of |g(xi) - X(xi)| over the boundary nodes of :func:`boundary_errors`: the
    distance of each boundary node from the geometry's boundary map at the node's own parametric
    point (an upper bound of its distance from the surface). JSON-ready."""
    dim = len(errors) // 2
    largest, total, count = 0.0, 0.0, 0
    for number, error in enumerate(errors):
        distance = np.linalg.norm(error, axis=-1)
        largest = max(largest, float(distance.max()))
        # For the mean, each node once: edges shared with the faces of an earlier axis are theirs.
        axis = number // 2
        fresh = tuple(slice(1, -1) if d < axis else slice(None) for d in range(dim) if d != axis)
        total += float(distance[fresh].sum())
        count += distance[fresh].size
    length = float(geometry.characteristic_length)
    return {
        "max": largest,
        "mean": total / count,
        "max_rel": largest / length,
        "characteristic_length": length,
        "definition": ERROR_DEFINITION,
    }


ERROR_DEFINITION = "distance of each boundary node from the geometry's boundary map at the node's parametric point"


def multilinear(corner_values: np.ndarray, coords, block=None) -> np.ndarray:
    """The multilinear interpolant of values at the 2^d corners of the cube (``corner_values``
    (2^d, c), in ``meshgen.cube.corners`` order) on the tensor grid of ``coords``, or on its
    ``block`` (one slice per axis): (n1, .., c)."""
    dim = len(coords)
    block = tuple(block) if block is not None else (slice(None),) * dim
    axes = [np.asarray(c, dtype=float)[b] for c, b in zip(coords, block)]
    result = np.zeros(tuple(len(a) for a in axes) + corner_values.shape[1:])
    for corner, value in zip(cube.corners(dim), corner_values):  # 2^d terms
        weight = np.ones([1] * dim)
        for axis, (t, side) in enumerate(zip(axes, corner)):
            weight = weight * blending(t, int(side)).reshape([-1 if d == axis else 1 for d in range(dim)])
        result += weight[..., None] * value
    return result


def correction_terms(errors, coords) -> tuple:
    """What the boundary correction of the error field ``errors`` (from :func:`boundary_errors`, on
    the grid of ``coords``) needs for any block of the grid, made once (face-sized): the errors at
    the 2^d corners, and the face terms (``meshgen.tfi.face_terms``, blending power
    ``CORRECTION_POWER``) of the rest, the error minus the corners' multilinear interpolant."""
    dim = len(coords)
    corner_points = cube.corners(dim)
    corner_values = np.empty((len(corner_points), errors[0].shape[-1]))
    for number, corner in enumerate(corner_points):  # each corner from the face xi = its first coordinate
        face = errors[int(corner[0])]
        corner_values[number] = face[tuple(-1 if c else 0 for c in corner[1:])]
    rest = []
    for face, error in zip(cube.faces(dim), errors):
        face_coords = [c if d != face.axis else np.array([float(face.side)]) for d, c in enumerate(coords)]
        on_face = np.take(multilinear(corner_values, face_coords), 0, axis=face.axis)
        rest.append(error - on_face)
    return corner_values, face_terms(rest, coords, CORRECTION_POWER)


def add_correction_terms(terms, coords, out: np.ndarray, block=None) -> np.ndarray:
    """Add the correction of :func:`correction_terms` ``terms`` to ``out`` in place: the whole node
    array, or with ``block`` (one slice per axis) the nodes ``X[block]``. Returns ``out``."""
    corner_values, rest = terms
    out += multilinear(corner_values, coords, block)
    return add_face_terms(rest, coords, out, block, CORRECTION_POWER)


def add_boundary_correction(out: np.ndarray, errors, coords, block=None) -> np.ndarray:
    """Add the correction of the boundary error field ``errors`` (from :func:`boundary_errors`, on
    the grid of ``coords``) to ``out`` in place: the whole node array (n1+1, .., d), or with
    ``block`` (one slice per axis) the nodes ``X[block]`` of a block of the grid, ``out`` then of
    that block's shape. Returns ``out``.

    The correction is the multilinear interpolant of the errors at the cube's corners, plus the
    transfinite interpolation of the rest of the error, blended with (1 - t)^p and t^p
    (p = ``CORRECTION_POWER``) instead of TFI's 1 - t and t. It equals the error on the boundary,
    so the corrected nodes lie on the geometry's boundary map to round-off. Inside, the corners'
    part moves the whole volume (a network shifted as a whole is shifted back as a whole), and
    the rest fades smoothly to zero within a layer about 1/p of each axis deep: it repairs the
    outer layers where the network missed the boundary and leaves the interior, where the Winslow
    loss made the network good, as it was. (Linear blending spreads every wrinkle of the error
    through the whole volume: measured, 0.6 to 1.9 degrees of mean min angle lost on topcurve and
    canal, issue 13.)"""
    return add_correction_terms(correction_terms(errors, coords), coords, out, block)


def correct_boundary(X: np.ndarray, geometry, coords, count_inverted: bool = False) -> dict:
    """Correct node array ``X`` (n1+1, .., d) of the tensor grid ``coords`` in place to
    X + TFI[g - X] (:func:`add_boundary_correction`). Returns what it did, JSON-ready:
    ``error_before`` (:func:`error_figures` of the uncorrected nodes); with ``count_inverted``
    also ``inverted_before`` / ``inverted_after`` / ``inverted_by_correction``: inverted cells of
    the whole mesh (two quality passes over it)."""
    errors = boundary_errors(X, geometry, coords)
    before = _inverted(X) if count_inverted else None
    add_boundary_correction(X, errors, coords)
    info = {"corrected": True, "error_before": error_figures(errors, geometry)}
    if count_inverted:
        after = _inverted(X)
        info.update(
            inverted_before=int(np.count_nonzero(before)),
            inverted_after=int(np.count_nonzero(after)),
            inverted_by_correction=int(np.count_nonzero(after & ~before)),
        )
    return info


def _inverted(X: np.ndarray) -> np.ndarray:
    """Per cell (n1, n2 [, n3]) of node array ``X``: inverted as ``meshgen.quality`` counts it
    (scaled Jacobian <= 0 at a corner, or degenerate; 2D against the mesh's orientation)."""
    from meshgen.quality import cell_metrics

    return cell_metrics(X)["scaled_jacobian"].reshape(tuple(n - 1 for n in X.shape[:-1])) <= 0


# ---------------------------------------------------------------------------------------------
# choosing the model


@dataclass
class TrainedModel:
    """A checkpoint chosen for meshing, with where it came from."""

    path: Path
    checkpoint: dict
    source: str  # "checkpoint" (given), "run" (newest under ./runs/), "bundled"
    record: dict = field(default_factory=dict)  # a bundled model's model.json

    @property
    def geometry_entry(self) -> dict:
        return self.checkpoint["geometry"]

    @property
    def dim(self) -> int:
        return int(self.checkpoint["model"]["dim"])

    def preset(self) -> str:
        return self.record.get("preset") or preset_of(self.checkpoint)

    def sha256(self) -> str:
        digest = hashlib.sha256()
        with open(self.path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
        return digest.hexdigest()

    def describe(self) -> str:
        """``<path> (<preset>, trained <n> steps, test loss ...)`` for the terminal."""
        checkpoint = self.checkpoint
        parts = [self.preset()]
        if self.source == "bundled":
            parts.insert(0, "bundled")
        stage = checkpoint.get("stage")
        steps = f"trained {checkpoint.get('step', '?')} steps"
        if isinstance(checkpoint.get("elapsed_seconds"), (int, float)):
            steps += f" in {checkpoint['elapsed_seconds']:.0f} s"
        if stage not in (None, "done"):
            steps += f", unfinished: saved in stage {stage}"
        parts.append(steps)
        loss = checkpoint.get("test_loss") or {}
        if isinstance(loss.get("total"), (int, float)):
            parts.append(
                f"test loss {loss['total']:.3g} (PDE {loss.get('pde', float('nan')):.3g}, "
                f"boundary {loss.get('boundary', float('nan')):.3g})"
            )
        return f"{display_path(self.path)} ({', '.join(parts)})"

    def metadata(self) -> dict:
        checkpoint = self.checkpoint
        return {
            "checkpoint": str(self.path),
            "sha256": self.sha256(),
            "source": self.source,
            "preset": self.preset(),
            "step": checkpoint.get("step"),
            "stage": checkpoint.get("stage"),
            "training_seconds": checkpoint.get("elapsed_seconds"),
            "test_loss": checkpoint.get("test_loss"),
            "widths": list(checkpoint["model"]["widths"]),
            "exact_boundary": bool(checkpoint["model"]["exact_boundary"]),
            "trained_with": checkpoint.get("meshgen_version"),
        }


def display_path(path: Path) -> str:
    """``path`` relative to the working folder when it lies below it, else absolute."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def preset_of(checkpoint: dict) -> str:
    """The preset a checkpoint was trained with: ``checkpoint["preset"]`` when recorded, else the
    preset whose resolved configuration equals the checkpoint's (``"<name>, modified: keys"`` when
    only some keys differ from the preset whose description it carries, ``"custom configuration"``
    when none fits)."""
    if isinstance(checkpoint.get("preset"), str):
        return checkpoint["preset"]
    from meshgen.neural.config import ConfigError, preset_paths, resolve_config, schema, to_dict

    config = checkpoint.get("config") or {}

    def flat(data, prefix=""):
        items = {}
        for key, value in data.items():
            if isinstance(value, dict):
                items.update(flat(value, f"{prefix}{key}."))
            else:
                items[f"{prefix}{key}"] = value
        return items

    recorded = flat(config)
    described = None
    for name in preset_paths():
        try:
            preset = flat(to_dict(resolve_config(name)))
        except ConfigError:
            continue
        differing = sorted(key for key in schema() if recorded.get(key) != preset.get(key))
        if not differing:
            return name
        if described is None and recorded.get("description") == preset.get("description"):
            described = (name, differing)
    if described is not None:
        name, differing = described
        shown = ", ".join(differing[:4]) + (", ..." if len(differing) > 4 else "")
        return f"{name} preset, modified: {shown}"
    return "custom configuration"


def _same_params(given: dict, recorded: dict) -> bool:
    return all(np.isclose(float(recorded.get(k, np.nan)), float(v), rtol=1e-12, atol=0.0) for k, v in given.items())


def _disagreement(entry: dict, geometry_name: str | None, params: dict) -> str | None:
    """Why a checkpoint's geometry ``entry`` is not the one asked for (None when it is)."""
    if geometry_name is not None and entry.get("name") != geometry_name:
        return f"was trained on '{entry.get('name')}', not on '{geometry_name}'"
    recorded = entry.get("params", {})
    for key, value in params.items():
        if not _same_params({key: value}, recorded):
            trained = recorded.get(key)
            return (
                f"was trained with {key}={trained:g}, not {key}={value:g}" if trained is not None else f"has no parameter '{key}'"
            )
    return None


def bundled_models() -> dict[str, Path]:
    """Geometry name -> bundled model folder (holding checkpoint.pt and model.json)."""
    if not MODELS_DIR.is_dir():
        return {}
    return {p.name: p for p in sorted(MODELS_DIR.iterdir()) if (p / "checkpoint.pt").is_file()}


def load_model(path, source: str = "checkpoint", record: dict | None = None) -> TrainedModel:
    """Load the checkpoint at ``path`` (``weights_only``: a file carrying code fails to load)."""
    from meshgen.neural.checkpoint import CheckpointError, load_checkpoint

    path = Path(path)
    checkpoint = load_checkpoint(path)
    if "family" in checkpoint:  # meshgen.neural.family: a member is chosen with --param
        raise CheckpointError(
            f"checkpoint {path} holds a family of shapes: mesh a member with --checkpoint {path} --param name=value"
        )
    network_layers(checkpoint["model"])  # a foreign model description fails here, before any work
    return TrainedModel(path, checkpoint, source, record or {})


def find_model(
    checkpoint_path=None,
    geometry_name: str | None = None,
    params: dict | None = None,
    default_geometry: str = "semicylinder",
    runs_dir=RUNS_DIR,
    warn=None,
) -> TrainedModel:
    """The model to mesh with.

    ``checkpoint_path``: use it; ``geometry_name`` / ``params`` (what was given explicitly on the
    command line, None / {} when not) must then agree with what it was trained on. Without it: the
    newest ``runs_dir/*/checkpoint.pt`` (by modification time) trained on ``geometry_name`` with
    ``params`` (any, when not given), else the bundled model of ``geometry_name`` (default
    ``default_geometry``) when the parameters are its defaults. ``warn(text)`` hears about run
    checkpoints that cannot be read (they are skipped). Raises MeshgenError when nothing fits.
    """
    params = dict(params or {})
    if checkpoint_path is not None:
        model = load_model(checkpoint_path)
        reason = _disagreement(model.geometry_entry, geometry_name, params)
        if reason is not None:
            raise MeshgenError(
                f"checkpoint {checkpoint_path} {reason}: leave out --geometry/--param (the checkpoint "
                f"sets them) or pick another checkpoint"
            )
        return model
    from meshgen.neural.checkpoint import CheckpointError

    runs = [p for p in Path(runs_dir).glob("*/checkpoint.pt") if p.is_file()]
    for path in sorted(runs, key=lambda p: p.stat().st_mtime, reverse=True):
        try:
            model = load_model(path, source="run")
        except CheckpointError as exc:
            if warn is not None:
                warn(f"skipped {path}: {exc}")
            continue
        if _disagreement(model.geometry_entry, geometry_name, params) is None:
            return model
    name = geometry_name or default_geometry
    folder = bundled_models().get(name)
    if folder is not None:
        record = json.loads((folder / "model.json").read_text()) if (folder / "model.json").is_file() else {}
        model = load_model(folder / "checkpoint.pt", source="bundled", record=record)
        defaults = _default_params(name)
        if _disagreement(model.geometry_entry, name, {**defaults, **params}) is None:
            return model
    bundled = ", ".join(f"{n} (default parameters)" for n in bundled_models()) or "none"
    given = name + (" with " + ", ".join(f"{k}={v:g}" for k, v in params.items()) if params else "")
    raise MeshgenError(
        f"no trained model for {given}: none in {runs_dir}{os.sep} and no bundled one (bundled: {bundled}); "
        f"train one with `meshgen train -g {name}` or pick --method tfi or --method elliptic"
    )


def _default_params(name: str) -> dict:
    from meshgen.geometry import load_geometry

    return dict(load_geometry(name, check=False).defaults)  # the defaults need no boundary check


# ---------------------------------------------------------------------------------------------
# the method


def build_neural(geometry, coords, model=None, correct=True, device="auto", polish=True):
    """The ``neural`` method of ``meshgen.methods``: the trained map of ``model`` (a TrainedModel,
    a checkpoint path, or None for ``find_model``'s choice for ``geometry``) on the tensor grid of
    ``coords``, evaluated on ``device`` ("cpu", "cuda" or "auto"), then corrected to
    X + TFI[g - X] (:func:`correct_boundary`) unless ``correct`` is False, then (``polish``, with
    ``correct``) polished: faces and interior brought to the discrete Winslow equations at the
    mesh's resolution (``meshgen.neural.polish``), which is what a flow solver needs. Returns (X, info) with info {"model", "correction",
    "warnings"}; ``info["correction"]["error_before"]`` is the network's boundary error, reported
    the same way whether or not the mesh is corrected."""
    if model is None:
        model = find_model(geometry_name=geometry.name, params=dict(geometry.values))
    elif not isinstance(model, TrainedModel):
        model = find_model(model, geometry_name=geometry.name, params=dict(geometry.values))
    if len(coords) != model.dim:
        raise ParameterError("dims", f"model {model.path} is {model.dim}D: {{name}} needs {model.dim} numbers, got {len(coords)}")
    from meshgen.layout import trained_layout, with_layout

    geometry = with_layout(geometry, trained_layout(model.checkpoint))  # the boundary it was trained on
    X = mesh_from_model(model.checkpoint["model"], coords, geometry, device=device)
    info = {"model": model.metadata(), "warnings": []}
    if correct:
        info["correction"] = correct_boundary(X, geometry, coords)
    else:
        info["correction"] = {"corrected": False, "error_before": error_figures(boundary_errors(X, geometry, coords), geometry)}
    if correct and polish:  # the discrete Winslow equations at the mesh's resolution (meshgen.neural.polish)
        info["polish"] = polish_mesh(X, geometry, coords)
    return X, info
