"""What makes a file a meshgen checkpoint, checked on the plain data it holds, without torch.

``check_checkpoint`` (format, version, the entries meshing needs, finite weights, a training state
that is one) and ``check_network`` (the model description is a tanh MLP of 2 xi - 1 whose weights
have the shapes its widths say) hold for a checkpoint read by ``torch.load``
(``meshgen.neural.checkpoint.load_checkpoint``: tensors) and for one read by the restricted
unpickler of ``meshgen.neural.mlp_numpy`` (``read_plain_checkpoint``: NumPy arrays), so meshing on a CPU
needs no torch and both readers refuse the same files with the same words.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.neural.mlp_numpy import read_checkpoint
from meshgen.run.inputs import InputError, check_input_file

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "CheckpointError",
    "as_array",
    "check_checkpoint",
    "check_network",
    "check_readable",
    "check_resumable_state",
    "read_plain_checkpoint",
]

FORMAT = "meshgen-checkpoint"
FORMAT_VERSION = 1


class CheckpointError(MeshgenError):
    """A checkpoint is missing, damaged, foreign or too new."""


def as_array(value) -> np.ndarray:
    """A weight (NumPy array or CPU tensor) as a NumPy array."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


def check_readable(path: Path) -> None:
    """CheckpointError unless ``path`` is an existing regular file (never a FIFO or a device)."""
    if not path.exists():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        check_input_file(path, "checkpoint")
    except InputError as exc:
        raise CheckpointError(str(exc)) from None


def _check_extruded(entry, path: Path) -> None:
    """CheckpointError unless ``entry`` is an extrusion's plain data: finite origin (3,), frame (2, 3), direction (3,)."""
    shapes = {"origin": (3,), "frame": (2, 3), "direction": (3,)}
    try:
        ok = isinstance(entry, dict) and all(
            np.shape(entry[key]) == shape and np.isfinite(np.asarray(entry[key], dtype=float)).all()
            for key, shape in shapes.items()
        )
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise CheckpointError(f"checkpoint {path}: its model's extrusion entry is damaged: not a meshgen checkpoint")


def check_checkpoint(checkpoint, path: Path) -> dict:
    """``checkpoint`` when it is a complete meshgen checkpoint this meshgen reads, else CheckpointError."""
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a meshgen checkpoint")
    version = checkpoint.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {path} has format version {version!r}, newer than this meshgen reads ({FORMAT_VERSION}): upgrade meshgen"
        )
    missing = [key for key in ("model", "geometry", "config") if key not in checkpoint]
    if missing:
        raise CheckpointError(f"checkpoint {path} lacks {', '.join(missing)}: not a complete meshgen checkpoint")
    model, geometry = checkpoint["model"], checkpoint["geometry"]
    if not (isinstance(model, dict) and isinstance(geometry, dict) and {"name", "spec", "dim", "params"} <= set(geometry)):
        raise CheckpointError(f"checkpoint {path}: its model or geometry entry is damaged: not a meshgen checkpoint")
    if "extruded" in model:  # the section model of an extruded block set (meshgen.geometry.extrusion)
        _check_extruded(model["extruded"], path)
    if model.get("dim") != geometry["dim"] - ("extruded" in model):
        raise CheckpointError(
            f"checkpoint {path} holds a {model.get('dim')}D map but records the {geometry['dim']}D geometry "
            f"'{geometry['name']}': not a consistent meshgen checkpoint"
        )
    state = model.get("state_dict", {})
    weights = list(state.values()) if isinstance(state, dict) else []
    if not all(_is_weight(w) and np.isfinite(as_array(w)).all() for w in weights):
        raise CheckpointError(f"checkpoint {path}: its network holds non-finite weights (NaN or infinity): the file is damaged")
    if "stage" in checkpoint:
        steps = [checkpoint.get(key) for key in ("step", "stage_step")]
        if checkpoint["stage"] not in ("pretrain", "adam", "lbfgs", "done") or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in steps
        ):
            raise CheckpointError(f"checkpoint {path}: its training state (stage, step) is damaged")
    return checkpoint


# The entries a resumed run reads, besides the model: (key, the type it must have).
RESUME_ENTRIES = (
    ("optimizer", dict),
    ("scheduler", dict),
    ("rng", dict),
    ("guard", dict),
    ("history", dict),
    ("elapsed_seconds", (int, float)),
)
NESTING = 8  # optimiser and scheduler states are dicts of lists of tensors: deeper is not one


def _non_finite(value, depth: int = 0) -> bool:
    """Whether ``value`` (plain data: tensors, arrays, numbers, dicts, lists) holds NaN or infinity
    anywhere, or nests deeper than ``NESTING``."""
    if depth > NESTING:
        return True
    if isinstance(value, dict):
        return any(_non_finite(v, depth + 1) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_non_finite(v, depth + 1) for v in value)
    if _is_weight(value):
        array = as_array(value)
        return array.dtype.kind in "fc" and not np.isfinite(array).all()
    if isinstance(value, float):
        return not np.isfinite(value)
    return False


def check_resumable_state(checkpoint: dict, path: Path) -> None:
    """CheckpointError unless the training state of ``checkpoint`` (checked as a whole by
    ``check_checkpoint`` already) is one a run can go on from: every entry a resumed run reads
    (``RESUME_ENTRIES``, ``rng["sampler"]``, ``guard["lr_reductions"]``, the reweighting of a
    one-shape or block run) present, and its optimiser, scheduler and reweighting states finite,
    as the weights are. Checked before the run folder is touched; the optimiser state's shapes
    against the network are checked where the network is made (``meshgen.neural.stages.check_resumable``)."""
    missing = [key for key, kind in RESUME_ENTRIES if not isinstance(checkpoint.get(key), kind)]
    if not missing:
        if "sampler" not in checkpoint["rng"]:
            missing.append("rng.sampler")
        if not isinstance(checkpoint["guard"].get("lr_reductions"), int):
            missing.append("guard.lr_reductions")
        optimizer = checkpoint["optimizer"]
        if optimizer and not (isinstance(optimizer.get("state"), dict) and isinstance(optimizer.get("param_groups"), list)):
            missing.append("optimizer.state/param_groups")
    if "family" not in checkpoint and not isinstance(checkpoint.get("reweighting"), dict):
        missing.append("reweighting")
    if missing:
        raise CheckpointError(
            f"checkpoint {path} lacks its training state's {', '.join(missing)} (or holds another kind of value): "
            "the file is damaged, it cannot be resumed"
        )
    words = {"optimizer": "optimiser state", "scheduler": "scheduler state", "reweighting": "reweighting state"}
    for key in ("optimizer", "scheduler", "reweighting", "elapsed_seconds"):
        if _non_finite(checkpoint.get(key)):
            raise CheckpointError(
                f"checkpoint {path}: its {words.get(key, 'elapsed seconds')} holds non-finite numbers (NaN or infinity): the file is damaged, "
                "it cannot be resumed"
            )


def _is_weight(value) -> bool:
    return isinstance(value, np.ndarray) or hasattr(value, "detach")


def check_network(model: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """The layers [(W (out, in), b (out,)), ...] of a ``checkpoint["model"]`` description as NumPy
    arrays, checked against its ``dim`` and ``widths``, its activation and input, and finite
    (a foreign or damaged description raises CheckpointError)."""
    try:
        dim, widths = int(model["dim"]), [int(w) for w in model["widths"]]
        state = model["state_dict"]
        sizes = [dim, *widths, dim]
        layers = []
        for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            weight, bias = as_array(state[f"layers.{index}.weight"]), as_array(state[f"layers.{index}.bias"])
            if weight.shape != (fan_out, fan_in) or bias.shape != (fan_out,):
                raise ValueError(f"layer {index} has shape {weight.shape}, expected {(fan_out, fan_in)}")
            layers.append((weight, bias))
        if len(state) != 2 * len(layers):
            raise ValueError("extra weights")
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"the checkpoint's model description is not a meshgen network ({exc})") from None
    if model.get("activation", "tanh") != "tanh" or model.get("input", "2*xi-1") != "2*xi-1":
        raise CheckpointError(
            f"the checkpoint's network uses activation {model.get('activation')!r} and input "
            f"{model.get('input')!r}; this meshgen evaluates tanh networks of 2*xi-1"
        )
    # A file is data: weights, scale and centre that are not finite numbers would make an all-NaN mesh.
    finite = all(np.isfinite(weight).all() and np.isfinite(bias).all() for weight, bias in layers)
    try:
        finite = finite and all(np.isfinite(np.asarray(model.get(key, 1.0), dtype=float)).all() for key in ("scale", "center"))
    except (TypeError, ValueError):
        finite = False
    if not finite:
        raise CheckpointError("the checkpoint's network holds non-finite numbers (NaN or infinity): the file is damaged")
    return layers


def read_plain_checkpoint(path: str | os.PathLike) -> dict:
    """A meshgen checkpoint read without torch (its tensors as NumPy arrays), checked as
    ``load_checkpoint`` checks it. A file that holds anything but plain data is refused unread."""
    path = Path(path)
    check_readable(path)
    try:
        checkpoint = read_checkpoint(path)
    except MeshgenError as exc:
        detail = str(exc).split(": ", 1)[-1]
        if detail.endswith(" is not plain checkpoint data"):
            found = detail[: -len(" is not plain checkpoint data")]
            detail = f"it carries Python objects, not plain data: {found}; refused without running them"
        raise CheckpointError(f"checkpoint {path} is truncated or not a meshgen checkpoint ({detail})") from None
    return check_checkpoint(checkpoint, path)
