"""The trained model to mesh with, and the ``neural`` method that meshes with it.

Model choice (``find_model``): an explicit checkpoint; else the newest ``runs/*/checkpoint.pt``
(skipping runs of another geometry or other parameters than the ones given); else the model
bundled in ``meshgen/_models/`` for its geometry with default parameters.

The method (``build_neural``): the model's map on the tensor grid (``meshgen.neural.inference.block_nodes``,
the path every block of a block set takes too),
then the boundary correction X = N + TFI[g - N] (``meshgen.methods.correction``).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError, ParameterError
from meshgen.geometry.layout import trained_layout, with_layout
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.correction import boundary_errors, correct_boundary, error_figures
from meshgen.methods.polish import NOT_POLISHED_REASON, polishes_by_default
from meshgen.methods.polish import polish as polish_mesh
from meshgen.neural.checkpoint_data import CheckpointError, read_plain_checkpoint
from meshgen.neural.config import ConfigError, dotted_items, preset_paths, resolve_config, schema, to_dict
from meshgen.neural.inference import block_nodes, check_model, is_block_model

__all__ = [
    "MODELS_DIR",
    "RUNS_DIR",
    "TrainedModel",
    "build_neural",
    "bundled_models",
    "display_path",
    "find_model",
    "load_model",
    "preset_of",
]

MODELS_DIR = Path(__file__).resolve().parents[1] / "_models"
RUNS_DIR = "runs"


@dataclass
class TrainedModel:
    """A checkpoint chosen for meshing, with where it came from."""

    path: Path
    checkpoint: dict
    source: str  # "checkpoint" (given), "run" (newest under ./runs/), "bundled"
    record: dict = field(default_factory=dict)  # a bundled model's model.json
    named_preset: str | None = field(default=None, repr=False, compare=False)  # preset(), found once

    @property
    def geometry_entry(self) -> dict:
        return self.checkpoint["geometry"]

    @property
    def dim(self) -> int:
        """The dimension of the meshes it makes: its network's, plus one for a section model (``extruded``)."""
        model = self.checkpoint["model"]
        return int(model["dim"]) + ("extruded" in model)

    def preset(self) -> str:
        """The preset the model was trained with (``preset_of``: every preset resolved, so found once per model)."""
        if self.named_preset is None:
            self.named_preset = self.record.get("preset") or preset_of(self.checkpoint)
        return self.named_preset

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
        if isinstance(loss.get("fit"), (int, float)):  # a wall-layer model: a fit, no PDE term
            parts.append(f"held-out misfit {loss['fit']:.3g}")
        elif isinstance(loss.get("total"), (int, float)):
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
    config = checkpoint.get("config") or {}

    recorded = dotted_items(config)
    described = None
    for name in preset_paths():
        try:
            preset = dotted_items(to_dict(resolve_config(name)))
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
    """Load the checkpoint at ``path`` as plain data, without torch (a file carrying code is refused unread)."""
    path = Path(path)
    checkpoint = read_plain_checkpoint(path)
    if "family" in checkpoint:  # meshgen.neural.family: a member is chosen with --param
        raise CheckpointError(
            f"checkpoint {path} holds a family of shapes: mesh a member with --checkpoint {path} --param name=value"
        )
    check_model(checkpoint["model"])  # a foreign model description fails here, before any work
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
    return dict(load_geometry(name, check=False).defaults)  # the defaults need no boundary check


# ---------------------------------------------------------------------------------------------
# the method


def build_neural(geometry, coords, model=None, correct=True, device="auto", polish=None):
    """The ``neural`` method of ``meshgen.methods.registry``: the trained map of ``model`` (a TrainedModel,
    a checkpoint path, or None for ``find_model``'s choice for ``geometry``) on the tensor grid of
    ``coords``, evaluated on ``device`` ("cpu", "cuda" or "auto"), then corrected to
    X + TFI[g - X] (:func:`correct_boundary`) unless ``correct`` is False, then (``polish``, with
    ``correct``) polished: faces and interior brought to the discrete Winslow equations at the
    mesh's resolution (``meshgen.methods.polish``), which is what a flow solver needs. ``polish`` None: the
    model's default (``meshgen.methods.polish.polishes_by_default``: not for a network trained on the
    smoothed layout's lattice with the exact boundary). Returns (X, info) with info {"model",
    "correction", "polish", "warnings"}; ``info["polish"]["polished"]`` says whether the mesh was
    polished (with the reason when it was not); ``info["correction"]["error_before"]`` is the
    network's boundary error, reported the same way whether or not the mesh is corrected."""
    if model is None:
        model = find_model(geometry_name=geometry.name, params=dict(geometry.values))
    elif not isinstance(model, TrainedModel):
        model = find_model(model, geometry_name=geometry.name, params=dict(geometry.values))
    if is_block_model(model.checkpoint["model"]):
        name = model.geometry_entry["name"]
        raise ParameterError("checkpoint", f"{{name}} {model.path} meshes the multi-block geometry '{name}': mesh with -g {name}")
    if len(coords) != model.dim:
        raise ParameterError("dims", f"model {model.path} is {model.dim}D: {{name}} needs {model.dim} numbers, got {len(coords)}")
    geometry = with_layout(geometry, trained_layout(model.checkpoint))  # the boundary it was trained on
    X = block_nodes(model.checkpoint["model"], 0, coords, geometry, device=device)  # the one inference path
    info = {"model": model.metadata(), "warnings": []}
    if correct:
        info["correction"] = correct_boundary(X, geometry, coords)
    else:
        info["correction"] = {"corrected": False, "error_before": error_figures(boundary_errors(X, geometry, coords), geometry)}
    by_default = polish is None
    if by_default:
        polish = polishes_by_default(model.checkpoint)
    if correct and polish:
        info["polish"] = polish_mesh(X, geometry, coords)
    elif not correct:
        info["polish"] = {"polished": False, "reason": "not corrected (--no-correct)"}
    else:
        info["polish"] = {"polished": False, "reason": NOT_POLISHED_REASON if by_default else "--no-polish"}
    return X, info
