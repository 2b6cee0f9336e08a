"""Running a comparison: one row per method (each meshed by ``meshgen.run.request.carry_out``, as
``meshgen mesh`` meshes) or per mesh file (measured as ``meshgen evaluate`` measures).

The trained methods (``3dmeshnet``, ``exact``, ``pinn`` ...: registered methods with a training
preset) first get their network through one adapter, ``neural_method`` (trained here, or a given
checkpoint), and then mesh like ``meshgen mesh --method neural --checkpoint`` of that network.
"""

from __future__ import annotations

import contextlib
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.cli.comparison.columns import COLUMNS_JSON, best_rows, headline, number_or_none
from meshgen.cli.comparison.outputs import prepare_out_dir
from meshgen.errors import MeshgenError, ParameterError
from meshgen.formats import read_mesh
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.registry import METHODS, TRAINED, get_method
from meshgen.neural.config import resolve_config
from meshgen.neural.device import inference_device
from meshgen.neural.models import load_model
from meshgen.neural.session import check_training_size
from meshgen.quality import VALID_RULE, as_node_array, cells_for_quality, evaluate_file, recorded_metadata
from meshgen.run.request import MeshRequest, carry_out

__all__ = [
    "DEFAULT_METHODS",
    "Budget",
    "Outcome",
    "Picture",
    "check_mesh_files",
    "compare_files",
    "compare_methods",
    "method_names",
    "neural_method",
    "parse_checkpoints",
    "parse_methods",
]

DEFAULT_METHODS = ("tfi", "elliptic")


def method_names() -> list[str]:
    """Every method compare knows: the registered ones (``meshgen.methods.registry``)."""
    return list(METHODS)


def parse_methods(text: str) -> list[str]:
    """``"tfi,elliptic"`` -> ["tfi", "elliptic"] (repeats dropped); MeshgenError naming the valid
    ones for an unknown name."""
    names = list(dict.fromkeys(part.strip().lower() for part in text.split(",") if part.strip()))
    if not names:
        raise MeshgenError(f"no methods given (methods: {', '.join(method_names())})")
    for name in names:
        get_method(name)
    return names


def parse_checkpoints(specs) -> dict[str, Path]:
    """``["pinn=runs/pinn/checkpoint.pt", ...]`` -> {"pinn": Path(...)}; neural methods only."""
    checkpoints = {}
    for spec in specs:
        name, sep, path = spec.partition("=")
        name = name.strip().lower()
        if not sep or not name or not path.strip():
            raise ParameterError(
                "checkpoint", f"malformed {{name}} {spec!r}: expected METHOD=PATH, e.g. pinn=runs/pinn/checkpoint.pt"
            )
        if name not in TRAINED:
            raise ParameterError(
                "checkpoint", f"{{name}} {spec!r}: '{name}' is not a neural method (neural methods: {', '.join(TRAINED)})"
            )
        if name in checkpoints:
            raise ParameterError("checkpoint", f"{{name}} given twice for '{name}'")
        checkpoints[name] = Path(path.strip())
    return checkpoints


@dataclass
class Budget:
    """How neural methods train: Adam steps, ``key=value`` overrides of the preset, seed, device."""

    steps: int | None = None
    overrides: tuple[str, ...] = ()
    seed: int | None = None
    device: str = "auto"  # auto: cuda when torch has it

    def given(self) -> list[str]:
        """The parameters given (not at their defaults)."""
        return [name for name, value in (("steps", self.steps), ("overrides", self.overrides), ("seed", self.seed)) if value]


# ---------------------------------------------------------------------------------------------
# the neural adapter: the one place that knows meshgen.neural


def neural_method(name: str, geometry, budget: Budget, checkpoint_path=None, reporter=None):
    """Prepare trained method ``name`` (a registered method with a training preset) on ``geometry``.

    Checks everything that can be checked cheaply now (the preset and the
    overrides, the device, the checkpoint and its geometry), so that bad input fails before any
    method runs. Returns ``run(run_dir) -> (model, record)``: it trains in ``run_dir`` (or loads the
    checkpoint); ``model`` is the ``TrainedModel`` to give ``make_mesh(name, ..., model=model)``,
    and ``record`` holds ``training_seconds``, ``test_loss`` (float or None), ``checkpoint`` and
    ``history`` (path of the loss history CSV, or None). ``reporter``: a function of the training
    configuration that returns a training reporter (``meshgen.neural.progress.reporter_for``), or None.
    """
    from meshgen.neural.train import train

    def total_loss(test_loss):
        if isinstance(test_loss, dict):
            test_loss = test_loss.get("total")
        return float(test_loss) if isinstance(test_loss, (int, float)) else None

    if checkpoint_path is not None:
        checkpoint_path = Path(checkpoint_path)
        model = load_model(checkpoint_path)
        trained_on = model.geometry_entry.get("name")
        if trained_on != geometry.name:
            raise MeshgenError(f"checkpoint {checkpoint_path} was trained on '{trained_on}', not on '{geometry.name}'")
        history = checkpoint_path.with_name("history.csv")

        def run(run_dir):
            record = {
                "checkpoint": str(checkpoint_path),
                "training_seconds": model.checkpoint.get("elapsed_seconds"),
                "test_loss": total_loss(model.checkpoint.get("test_loss")),
                "history": str(history) if history.is_file() else None,
            }
            return model, record

        return run

    config = resolve_config(get_method(name).preset, overrides=budget.overrides, steps=budget.steps, seed=budget.seed)
    check_training_size(config, geometry.dim)  # a network too large for memory fails before any method runs
    device = inference_device(budget.device)

    def run(run_dir):
        run_dir = Path(run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        progress = reporter(config) if reporter is not None else None
        with progress if progress is not None else contextlib.nullcontext():
            result = train(config, geometry, run_dir, device=device, reporter=progress, summary=False)
        record = {
            "checkpoint": str(result.checkpoint_path),
            "training_seconds": float(result.seconds),
            "test_loss": total_loss(result.test_loss),
            "history": str(run_dir / "history.csv") if (run_dir / "history.csv").is_file() else None,
        }
        return load_model(result.checkpoint_path, source="run"), record

    return run


@dataclass
class Picture:
    """What the pictures need of one row: a node array, or points and quads (2D files), or nothing."""

    label: str
    X: np.ndarray | None = None
    points: np.ndarray | None = None
    cells: np.ndarray | None = None
    history: str | None = None  # loss history CSV of a neural method


@dataclass
class Outcome:
    comparison: dict
    pictures: list[Picture] = field(default_factory=list)
    interrupted: bool = False  # Ctrl-C after some methods finished: the comparison holds their rows


def compare_methods(
    geometry,
    dims,
    methods,
    *,
    clusters=(),
    method_options: dict | None = None,
    budget: Budget | None = None,
    checkpoints: dict | None = None,
    timing_repeats: int = 1,
    out_dir=None,
    mesh_format: str = ".vtu",
    say=lambda text: None,
    reporter=None,
) -> Outcome:
    """Mesh ``geometry`` (a loaded Geometry) with ``dims`` cells per axis and the wall clustering
    ``clusters`` with each method of ``methods`` and measure the meshes.

    ``method_options``: options of classical methods (e.g. ``tol``, ``max_iter``), each given to
    the methods that take it; an option no chosen method takes is an error. ``budget`` and
    ``checkpoints`` ({method: path}) concern the neural methods (see ``neural_method``).
    ``out_dir``: where meshes (``<method><mesh_format>`` with their quality sidecars) and the
    neural methods' run folders (``runs/<method>/``) go, created after the checks of the input
    and before any method runs; None keeps nothing. ``say`` receives a line per step. A method
    that fails with a MeshgenError gets a row with its ``error``; the others still run.
    ``reporter``: how training shows its progress (see ``neural_method``).
    Ctrl-C while a method meshes, after others finished, ends the comparison there: the Outcome
    holds the finished rows (``interrupted``; ``comparison["interrupted"]`` names the methods not
    run, the interrupted one first); before any row is finished it stops as usual.
    """
    budget = budget or Budget()
    checkpoints = dict(checkpoints or {})
    method_options = {k: v for k, v in (method_options or {}).items() if v is not None}
    dims = [int(n) for n in dims]
    clusters = tuple(clusters)
    _check_comparison(geometry, dims, clusters, methods, method_options, budget, checkpoints)
    neural = [name for name in methods if name in TRAINED]
    prepared = {name: neural_method(name, geometry, budget, checkpoints.get(name), reporter) for name in neural}

    out_dir = prepare_out_dir(out_dir) if out_dir is not None else None
    scratch = tempfile.TemporaryDirectory(prefix="meshgen-compare-") if neural and out_dir is None else None
    rows, pictures = [], []
    not_run = []
    try:
        for number, name in enumerate(methods):
            run_dir = (out_dir if out_dir is not None else Path(scratch.name if scratch else ".")) / "runs" / name
            if name in prepared:
                say(f"{name}: {'loading ' + str(checkpoints[name]) if name in checkpoints else 'training'} ...")
            request = MeshRequest(
                tuple(dims),
                geometry,
                method=name,
                clusters=clusters,
                output=out_dir / f"{name}{mesh_format}" if out_dir is not None else None,
                chunked=False,
                timing_repeats=timing_repeats,
                **{k: v for k, v in method_options.items() if k in get_method(name).options},
            )
            try:
                row, picture = _method_row(request, prepared.get(name), run_dir, say)
            except KeyboardInterrupt:
                if not rows:
                    raise
                not_run = list(methods)[number:]  # an interrupted mesh is published whole or not at all
                finished = ", ".join(row["name"] for row in rows)
                say(f"interrupted: the table holds what finished ({finished}); not run: {', '.join(not_run)}")
                break
            rows.append(row)
            if picture is not None:
                pictures.append(picture)
    finally:
        if scratch is not None:
            scratch.cleanup()
    comparison = {
        "meshgen_version": __version__,
        "mode": "methods",
        "geometry": geometry.name,
        "params": geometry.values,
        "dims": dims,
        "timing_repeats": timing_repeats,
        "columns": COLUMNS_JSON,
        "best": best_rows(rows),
        "rows": rows,
        "valid_rule": VALID_RULE,
    }
    if not_run:
        comparison["interrupted"] = {"not_run": not_run}
        comparison["notes"] = [f"Interrupted (Ctrl-C) before these methods finished: {', '.join(not_run)}."]
    return Outcome(comparison, pictures, interrupted=bool(not_run))


def _check_comparison(geometry, dims, clusters, methods, method_options, budget, checkpoints) -> None:
    """Everything that can be checked before anything runs: MeshgenError naming what is wrong."""
    if len(dims) != geometry.dim:
        raise ParameterError(
            "dims", f"geometry '{geometry.name}' is {geometry.dim}D: {{name}} needs {geometry.dim} numbers, got {len(dims)}"
        )
    node_coordinates(dims, clusters)  # a malformed cluster fails here
    neural = [name for name in methods if name in TRAINED]
    for name in checkpoints:
        if name not in methods:
            raise ParameterError(
                "checkpoint", f"{{name}} for '{name}', which is not among the compared methods ({', '.join(methods)})"
            )
    if not neural and (budget.given() or checkpoints):
        given = (budget.given() or ["checkpoint"])[0]
        raise ParameterError(given, f"{{name}} applies to neural methods only ({', '.join(TRAINED)})")
    classical = [name for name in methods if name not in TRAINED]
    for option in method_options:
        if not any(option in get_method(name).options for name in classical):
            raise ParameterError(option, "{name} applies to none of the compared methods")


def _method_row(request: MeshRequest, prepare, run_dir, say) -> tuple[dict, Picture | None]:
    """The row of one method (``error`` instead of figures when it failed) and its picture."""
    name = request.method
    row = {"name": name, "kind": "neural" if get_method(name).neural else "classical"}
    record = {}
    try:
        if prepare is not None:
            model, record = prepare(run_dir)
            row.update({k: v for k, v in record.items() if k != "history"})
            request = replace(request, checkpoint=model)
        made = carry_out(request)
    except MeshgenError as exc:
        row["error"] = str(exc)
        say(f"{name}: failed: {exc}")
        return row, None
    report = made.quality_report
    report.pop("quality_seconds", None)
    if made.output is not None:
        row["file"] = str(made.output)
    figures = {
        "meshing_seconds": made.seconds,
        "training_seconds": record.get("training_seconds"),
        "test_loss": record.get("test_loss"),
    }
    row.update(
        headline=headline(report, **figures),
        meshing_seconds=made.seconds,
        meshing_timings=list(made.timings),
        quality=report,
        **({"method_info": made.info} if made.info else {}),
    )
    for warning in made.info.get("warnings", []) if isinstance(made.info, dict) else []:
        say(f"{name}: warning: {warning}")
    repeats = request.timing_repeats
    say(f"{name}: meshed in {made.seconds:.3g} s" + (f" (median of {repeats})" if repeats > 1 else ""))
    return row, Picture(name, X=made.X, history=record.get("history"))


def check_mesh_files(paths) -> list[Path]:
    """The paths as Paths; MeshgenError for the first that is missing or empty (checked before
    reading any, so that a typo in the last name fails at once)."""
    paths = [Path(p) for p in paths]
    for path in paths:
        if not path.is_file():
            raise MeshgenError(f"mesh file {path} does not exist")
        if path.stat().st_size == 0:
            raise MeshgenError(f"mesh file {path} is empty")
    return paths


def compare_files(paths, geometry=None, params: dict | None = None) -> Outcome:
    """Measure existing mesh files as ``meshgen evaluate`` does and put them side by side.

    ``geometry`` / ``params``: as for ``meshgen.quality.evaluate_file`` (None: what each file
    records). The meshing time is the one the file (or its sidecar) records, if any.
    """
    paths = check_mesh_files(paths)
    rows, pictures = [], []
    for path in paths:
        mesh = read_mesh(path)
        report = evaluate_file(path, geometry, params, mesh=mesh)
        metadata = recorded_metadata(path, mesh)
        recorded_seconds = number_or_none(metadata.get("meshing_seconds")) if metadata else None
        rows.append(
            {
                "name": str(path),
                "kind": "file",
                "file": str(path),
                "headline": headline(report, meshing_seconds=recorded_seconds),
                "meshing_seconds": recorded_seconds,
                "quality": report,
                **({"method": metadata["method"]} if metadata.get("method") else {}),
            }
        )
        points, cells, _ = cells_for_quality(mesh)
        X = as_node_array(points, cells, metadata["dims"]) if report["structured"] else None
        if X is not None:
            pictures.append(Picture(path.name, X=X))
        elif report["dim"] == 2:
            pictures.append(Picture(path.name, points=points[:, :2], cells=cells))
        else:
            pictures.append(Picture(path.name))  # an unstructured 3D mesh has no index mid-planes
    comparison = {
        "meshgen_version": __version__,
        "mode": "files",
        "geometry": getattr(geometry, "name", geometry),
        "params": dict(params or {}),
        "dims": None,
        "columns": COLUMNS_JSON,
        "best": best_rows(rows),
        "rows": rows,
        "valid_rule": VALID_RULE,
    }
    return Outcome(comparison, pictures)
