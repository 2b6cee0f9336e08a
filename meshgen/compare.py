"""Meshing methods side by side (``meshgen compare``): one row per method or mesh file, the headline
columns of design notes §7, the best value per column, and the files a comparison leaves behind.

A comparison is plain data (what ``compare.json`` holds)::

    {"mode": "methods" | "files", "geometry", "params", "dims", "timing_repeats",
     "columns": [{"key", "label", "best"}], "best": {column key: [row names]},
     "rows": [row, ...], "valid_rule", "notes": [...]}

and a row is ``{"name", "kind": "classical" | "neural" | "file", "headline": {...}, "quality":
<the meshgen evaluate report>, "meshing_seconds", "meshing_timings", ...}`` (``"error"`` instead of
figures when the method failed). ``headline`` holds the table's figures at full precision:

- ``min_angle`` ... ``non_orthogonality``: the means of the per-cell metrics (degrees for angles
  and non-orthogonality);
- ``inverted_count``, ``inverted_percent``, ``valid`` (inverted cells <= 0.5% of all cells);
- ``boundary_deviation_max``, ``_max_rel`` (relative to the characteristic length), ``_mean``,
  ``_mean_rel``: distance of the boundary nodes from the true boundary (None without a geometry);
- ``test_loss``: the trained network's loss on the held-out points (neural methods);
- ``training_seconds``; ``meshing_seconds``: the median of ``timing_repeats`` runs (files: what
  the file records).

Best per column: the smallest value, except the angles, where the mean closest to 90 degrees is
best (the largest mean min angle, the smallest mean max angle); inverted cells rank by percentage
and boundary deviation by its relative maximum, so meshes of different sizes and geometries rank
fairly. Values equal up to round-off (relative 1e-9; boundary deviation below 1e-12 of the
characteristic length) tie, and every tied row is marked. A column needs two rows with a value to
have a best one. ``valid`` has no best.

Every row is meshed by ``meshgen.methods.make_mesh``, as ``meshgen mesh`` meshes. The trained
methods (``3dmeshnet``, ``exact``, ``pinn`` ...: registered methods with a training preset) first
get their network through one adapter, ``neural_method`` (trained here, or a given checkpoint),
and then mesh like ``meshgen mesh --method neural --checkpoint`` of that network.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import statistics
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError, ParameterError
from meshgen.methods import TRAINED

DEFAULT_METHODS = ("tfi", "elliptic")


@dataclass(frozen=True)
class Column:
    key: str  # the headline figure that ranks the column
    label: str  # in Markdown and JSON
    short: str  # in the terminal, where 13 columns must fit
    best: str | None  # "min", "near90" (closest to 90 degrees) or None
    zero: float = 0.0  # values below this are round-off: they tie with zero


COLUMNS = (
    Column("min_angle", "min angle (deg)", "min angle", "near90"),
    Column("max_angle", "max angle (deg)", "max angle", "near90"),
    Column("equiangle_skewness", "equiangle skewness", "equiangle skew", "min"),
    Column("aspect_ratio", "aspect ratio", "aspect ratio", "min"),
    Column("centroid_skewness", "centroid skewness", "centroid skew", "min"),
    Column("non_orthogonality", "non-orthogonality (deg)", "non-orth", "min"),
    Column("inverted_percent", "inverted cells", "inverted", "min"),
    Column("valid", "valid", "valid", None),
    Column("boundary_deviation_max_rel", "boundary deviation max (of L)", "boundary dev", "min", zero=1e-12),
    Column("test_loss", "test-set loss", "test loss", "min"),
    Column("training_seconds", "training (s)", "train (s)", "min"),
    Column("meshing_seconds", "meshing (s)", "mesh (s)", "min"),
)
COLUMNS_JSON = [{"key": c.key, "label": c.label, "best": c.best} for c in COLUMNS]
HEADLINE_METRICS = ("min_angle", "max_angle", "equiangle_skewness", "aspect_ratio", "centroid_skewness", "non_orthogonality")
TIE_RELATIVE = 1e-9


def method_names() -> list[str]:
    """Every method compare knows: the registered ones (``meshgen.methods``)."""
    from meshgen.methods import METHODS

    return list(METHODS)


def parse_methods(text: str) -> list[str]:
    """``"tfi,elliptic"`` -> ["tfi", "elliptic"] (repeats dropped); MeshgenError naming the valid
    ones for an unknown name."""
    from meshgen.methods import get_method

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

    Checks everything that can be checked cheaply now (the neural package, the preset and the
    overrides, the device, the checkpoint and its geometry), so that bad input fails before any
    method runs. Returns ``run(run_dir) -> (model, record)``: it trains in ``run_dir`` (or loads the
    checkpoint); ``model`` is the ``TrainedModel`` to give ``make_mesh(name, ..., model=model)``,
    and ``record`` holds ``training_seconds``, ``test_loss`` (float or None), ``checkpoint`` and
    ``history`` (path of the loss history CSV, or None). ``reporter``: a function of the training
    configuration that returns a training reporter (``meshgen.neural.progress.reporter_for``), or None.
    """
    try:
        from meshgen.neural.config import resolve_config
        from meshgen.neural.inference import inference_device
        from meshgen.neural.models import load_model
        from meshgen.neural.train import train
    except ImportError as exc:
        raise MeshgenError(
            f"neural methods need meshgen.neural, which this installation lacks ({exc}); "
            f"compare {', '.join(DEFAULT_METHODS)} meanwhile"
        ) from None
    from meshgen.methods import get_method

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
    from meshgen.neural.session import check_training_size

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


# ---------------------------------------------------------------------------------------------
# rows and their figures


def headline(report: dict | None, **figures) -> dict:
    """The table's figures of a quality report (``meshgen evaluate``'s schema) plus ``figures``
    (test_loss, training_seconds, meshing_seconds; missing ones None)."""
    values = {key: None for key in (*HEADLINE_METRICS, "inverted_count", "inverted_percent", "valid")}
    values.update({f"boundary_deviation_{s}": None for s in ("max", "max_rel", "mean", "mean_rel")})
    if report is not None:
        for name in HEADLINE_METRICS:
            values[name] = report["metrics"][name]["mean"]
        values["inverted_count"] = report["inverted"]["count"]
        values["inverted_percent"] = 100.0 * report["inverted"]["fraction"]
        values["valid"] = report["valid"]
        deviation = report.get("boundary_deviation") or {}
        for stat in ("max", "max_rel", "mean", "mean_rel"):
            values[f"boundary_deviation_{stat}"] = deviation.get(stat)
    for key in ("test_loss", "training_seconds", "meshing_seconds"):
        values[key] = figures.get(key)
    return values


def _number_or_none(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def best_rows(rows) -> dict[str, list[str]]:
    """Column key -> names of the rows with the best value (see the module's docstring)."""
    best = {}
    for column in COLUMNS:
        if column.best is None:
            continue
        scored = []
        for row in rows:
            value = _number_or_none(row.get("headline", {}).get(column.key))
            if value is None:
                continue
            score = abs(value - 90.0) if column.best == "near90" else value
            scored.append((max(score, column.zero) if column.best == "min" else score, row["name"]))
        if len(scored) < 2:
            continue
        top = min(score for score, _ in scored)
        tolerance = TIE_RELATIVE * abs(top)
        best[column.key] = [name for score, name in scored if score - top <= tolerance]
    return best


def cell_text(column: Column, values: dict, short: bool = False) -> str:
    """How a headline figure reads in the tables (``short``: the terminal's, boundary deviation
    without its relative value)."""
    from meshgen.tables import number

    if column.key == "inverted_percent":
        if values["inverted_count"] is None:
            return "n/a"
        return f"{values['inverted_count']} ({values['inverted_percent']:.3g}%)"
    if column.key == "boundary_deviation_max_rel":
        if values["boundary_deviation_max"] is None:
            return "n/a"
        if short:
            return number(values["boundary_deviation_max"])
        return f"{number(values['boundary_deviation_max'])} ({number(values['boundary_deviation_max_rel'])})"
    if column.key == "test_loss" and values["test_loss"] is not None:
        return f"{values['test_loss']:.3e}"
    if column.key.endswith("_seconds") and values[column.key] is not None:
        return f"{values[column.key]:.3g}"
    return number(values[column.key])


def table(comparison: dict, short: bool = False) -> tuple[list[str], list[list[str]], set[tuple[int, int]]]:
    """(header, rows, highlighted (row, column) cells) of a comparison; failed rows read 'failed'.
    ``short``: the terminal's compact headers and cells."""
    header = ["method" if comparison["mode"] == "methods" else "mesh", *(c.short if short else c.label for c in COLUMNS)]
    rows, highlight = [], set()
    for r, row in enumerate(comparison["rows"]):
        if "error" in row:
            rows.append([row["name"], *(["failed"] + [""] * (len(COLUMNS) - 1))])
            continue
        rows.append([row["name"], *(cell_text(c, row["headline"], short) for c in COLUMNS)])
        for c, column in enumerate(COLUMNS, start=1):
            if row["name"] in comparison["best"].get(column.key, ()):
                highlight.add((r, c))
    return header, rows, highlight


def title(comparison: dict) -> str:
    if comparison["mode"] == "files":
        text = f"comparison of {len(comparison['rows'])} meshes"
    else:
        text = f"comparison on {comparison['geometry']}, {' x '.join(map(str, comparison['dims']))} cells"
    repeats = comparison.get("timing_repeats", 1)
    if comparison["mode"] == "methods" and repeats > 1:
        text += f" (meshing time: median of {repeats} runs)"
    return text


CAPTION = (
    "Means over the cells; angles and non-orth(ogonality) in degrees; boundary dev: largest distance of a "
    "boundary node from the true boundary; best per column in bold green (angles: closest to 90)."
)


def notes(comparison: dict) -> list[str]:
    """The rules behind the table, for the Markdown report."""
    from meshgen.quality import VALID_RULE

    lines = [
        "Best value per column in bold: the mean closest to 90 degrees for the angles, the smallest "
        "value for the others (inverted cells by percentage, boundary deviation relative to the "
        "characteristic length L).",
        "Angles, skewnesses, aspect ratio and non-orthogonality are means over the cells; angles "
        "and non-orthogonality in degrees. Boundary deviation: largest distance of a boundary node "
        "from the true boundary, with its fraction of L in brackets.",
        f"Valid: {VALID_RULE}.",
    ]
    if comparison["mode"] == "methods":
        repeats = comparison.get("timing_repeats", 1)
        lines.append(
            f"Meshing time: {'median of ' + str(repeats) + ' runs' if repeats > 1 else 'one run'}; "
            "neural methods: evaluating the trained network (training time separately)."
        )
    else:
        lines.append("Meshing time: as the file records it (n/a where it does not).")
    return lines + list(comparison.get("notes", []))


def markdown(comparison: dict) -> str:
    """The comparison as Markdown: the table (best values bold), failures, the rules."""
    from meshgen.tables import markdown_table

    header, rows, highlight = table(comparison)
    lines = [f"## {title(comparison)[0].upper()}{title(comparison)[1:]}", ""]
    lines += markdown_table(header, rows, highlight)
    lines.append("")
    for row in comparison["rows"]:
        if "error" in row:
            lines.append(f"- `{row['name']}` failed: {row['error']}")
    lines += [f"- {line}" for line in notes(comparison)]
    return "\n".join(lines) + "\n"


CSV_FIELDS = (
    "name",
    "kind",
    *HEADLINE_METRICS,
    "inverted_count",
    "inverted_percent",
    "valid",
    "boundary_deviation_max",
    "boundary_deviation_max_rel",
    "boundary_deviation_mean",
    "boundary_deviation_mean_rel",
    "test_loss",
    "training_seconds",
    "meshing_seconds",
    "meshing_timings",
    "error",
)


def csv_text(comparison: dict) -> str:
    """One line per row, figures at full precision (repr), empty where undefined; timings joined by ';'."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    for row in comparison["rows"]:
        values = {"name": row["name"], "kind": row["kind"], "error": row.get("error", "")}
        for key, value in row.get("headline", {}).items():
            if key in CSV_FIELDS:
                values[key] = "" if value is None else value
        values["meshing_timings"] = ";".join(repr(t) for t in row.get("meshing_timings", []))
        writer.writerow(values)
    return buffer.getvalue()


# ---------------------------------------------------------------------------------------------
# running a comparison


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


def timed(mesh, repeats: int):
    """Run ``mesh()`` ``repeats`` times; (its last result, the wall-clock seconds of each run)."""
    timings, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = mesh()
        timings.append(time.perf_counter() - start)
    return result, timings


def compare_methods(
    geometry,
    coords,
    methods,
    *,
    method_options: dict | None = None,
    budget: Budget | None = None,
    checkpoints: dict | None = None,
    timing_repeats: int = 1,
    out_dir=None,
    mesh_format: str = ".vtu",
    say=lambda text: None,
    reporter=None,
) -> Outcome:
    """Mesh ``geometry`` at parametric node coordinates ``coords`` (one 1D array per axis) with each
    method of ``methods`` and measure the meshes.

    ``method_options``: options of classical methods (e.g. ``tol``, ``max_iter``), each given to
    the methods that take it; an option no chosen method takes is an error. ``budget`` and
    ``checkpoints`` ({method: path}) concern the neural methods (see ``neural_method``).
    ``out_dir``: where meshes (``<method><mesh_format>`` with their quality sidecars) and the
    neural methods' run folders (``runs/<method>/``) go, created after the checks of the input
    and before any method runs; None keeps nothing. ``say`` receives a line per step. A method
    that fails with a MeshgenError gets a row with its ``error``; the others still run.
    ``reporter``: how training shows its progress (see ``neural_method``).
    """
    from meshgen import __version__
    from meshgen.methods import get_method, make_mesh
    from meshgen.quality import VALID_RULE, quality_report, write_mesh_with_quality

    budget = budget or Budget()
    checkpoints = dict(checkpoints or {})
    method_options = {k: v for k, v in (method_options or {}).items() if v is not None}
    dims = [len(c) - 1 for c in coords]

    # Everything that can be checked is checked before anything runs.
    if len(coords) != geometry.dim:
        raise MeshgenError(
            f"geometry '{geometry.name}' is {geometry.dim}D: it needs {geometry.dim} coordinate axes, got {len(coords)}"
        )
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
    prepared = {name: neural_method(name, geometry, budget, checkpoints.get(name), reporter) for name in neural}

    out_dir = prepare_out_dir(out_dir) if out_dir is not None else None
    scratch = tempfile.TemporaryDirectory(prefix="meshgen-compare-") if neural and out_dir is None else None
    rows, pictures = [], []
    try:
        for name in methods:
            row = {"name": name, "kind": "neural" if get_method(name).neural else "classical"}
            record = {}
            try:
                options = {k: v for k, v in method_options.items() if k in get_method(name).options}
                if name in prepared:
                    run_dir = (out_dir if out_dir is not None else Path(scratch.name)) / "runs" / name
                    say(f"{name}: {'loading ' + str(checkpoints[name]) if name in checkpoints else 'training'} ...")
                    options["model"], record = prepared[name](run_dir)
                    row.update({k: v for k, v in record.items() if k != "history"})

                def mesh(name=name, options=options):
                    return make_mesh(name, geometry, coords, **options)

                (X, info), timings = timed(mesh, timing_repeats)
            except MeshgenError as exc:
                row["error"] = str(exc)
                rows.append(row)
                say(f"{name}: failed: {exc}")
                continue
            seconds = statistics.median(timings)
            figures = {
                "meshing_seconds": seconds,
                "training_seconds": record.get("training_seconds"),
                "test_loss": record.get("test_loss"),
            }
            if out_dir is not None:
                metadata = {
                    "meshgen_version": __version__,
                    "method": name,
                    "geometry": geometry.name,
                    "params": geometry.values,
                    "dims": dims,
                    "meshing_seconds": seconds,
                    **({"method_info": info} if info else {}),
                    **({"checkpoint": record["checkpoint"]} if record.get("checkpoint") else {}),
                }
                path = out_dir / f"{name}{mesh_format}"
                report = write_mesh_with_quality(path, X, geometry, metadata)
                report.pop("quality_seconds", None)
                row["file"] = str(path)
            else:
                report = quality_report(X, geometry)
            row.update(
                headline=headline(report, **figures),
                meshing_seconds=seconds,
                meshing_timings=timings,
                quality=report,
                **({"method_info": info} if info else {}),
            )
            for warning in info.get("warnings", []) if isinstance(info, dict) else []:
                say(f"{name}: warning: {warning}")
            say(f"{name}: meshed in {seconds:.3g} s" + (f" (median of {timing_repeats})" if timing_repeats > 1 else ""))
            rows.append(row)
            pictures.append(Picture(name, X=X, history=record.get("history")))
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
    return Outcome(comparison, pictures)


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
    from meshgen import __version__
    from meshgen.formats import read_mesh
    from meshgen.quality import VALID_RULE, as_node_array, cells_for_quality, evaluate_file, recorded_metadata

    paths = check_mesh_files(paths)
    rows, pictures = [], []
    for path in paths:
        mesh = read_mesh(path)
        report = evaluate_file(path, geometry, params, mesh=mesh)
        metadata = recorded_metadata(path, mesh)
        recorded_seconds = _number_or_none(metadata.get("meshing_seconds")) if metadata else None
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


# ---------------------------------------------------------------------------------------------
# writing


def prepare_out_dir(out_dir) -> Path:
    """Create ``out_dir`` (its parent must exist) or check the existing folder is writable."""
    import os

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ParameterError("out", f"{{name}} {out_dir} is a file, not a folder")
    if not out_dir.exists():
        if not out_dir.parent.is_dir():
            raise ParameterError("out", f"{{name}} {out_dir}: folder {out_dir.parent} does not exist")
        try:
            out_dir.mkdir()
        except OSError as exc:
            raise MeshgenError(f"could not create {out_dir}: {exc.strerror or exc}") from exc
    if not os.access(out_dir, os.W_OK | os.X_OK):
        raise ParameterError("out", f"{{name}} {out_dir} is not writable")
    return out_dir


def write_tables(comparison: dict, out_dir) -> list[Path]:
    """``compare.json``, ``compare.md`` and ``compare.csv`` in ``out_dir``, each written atomically."""
    from meshgen.atomic import atomic_write
    from meshgen.quality import write_json

    out_dir = Path(out_dir)
    written = [write_json(out_dir / "compare.json", comparison)]
    for name, text in (("compare.md", markdown(comparison)), ("compare.csv", csv_text(comparison))):
        with atomic_write(out_dir / name) as temporary:
            temporary.write_text(text)
        written.append(out_dir / name)
    return written
