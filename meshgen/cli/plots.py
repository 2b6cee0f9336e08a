"""Pictures of a comparison (needs matplotlib: ``pip install meshgen[plot]``), drawn with the Agg
backend and written atomically as PNG.

- ``sections_figure``: one column per method, coloured by a per-cell metric on one shared colour
  scale. 3D meshes: three rows, the index mid-planes i = n1//2, j = n2//2, k = n3//2 drawn in
  physical space as the faces of the cells on that node plane; each face takes the metric of the
  cell on its + side (cell index min(n//2, n-1)), computed as on the whole mesh. Each plane is
  drawn on the two physical axes along which it extends most. 2D meshes: one row, every cell.
- ``loss_curves_figure``: one panel per neural method, L1 (Winslow residual), L2 (boundary) and
  the weighted total against the step, log scale; dotted lines where a training stage begins;
  the pretraining stage (a fit to TFI, if the history has one) as a separate dashed line.

Pixel size (fixed, at 100 dpi): each panel is ``PANEL_PX`` = 400 x 360 pixels; the sections figure
adds ``COLORBAR_PX`` = 120 pixels on the right for the colour bar; both add ``TITLE_PX`` = 40 on
top. So sections are (400 columns + 120) x (360 rows + 40) px, loss curves (400 columns) x 400 px.
Faces are drawn as one PolyCollection per panel from vectorised vertex arrays.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from meshgen.cli.tables import METRIC_LABELS
from meshgen.quality import cell_metrics, cell_metrics_unstructured
from meshgen.run.atomic import atomic_write
from meshgen.run.inputs import read_input_text

__all__ = [
    "AXIS_NAMES",
    "COLORBAR_PX",
    "DPI",
    "INDEX_NAMES",
    "INSTALL_HINT",
    "LOSS_CURVES",
    "PANEL_PX",
    "TITLE_PX",
    "drawable",
    "loss_curves_figure",
    "loss_curves_size",
    "mid_section",
    "panels",
    "plotting_available",
    "quad_faces",
    "read_history",
    "sections_figure",
    "sections_size",
    "whole_mesh",
]

PANEL_PX = (400, 360)
COLORBAR_PX = 120
TITLE_PX = 40
DPI = 100
INSTALL_HINT = "pictures need matplotlib: pip install 'meshgen[plot]'"
AXIS_NAMES = ("x", "y", "z")
INDEX_NAMES = ("i", "j", "k")


def sections_size(columns: int, rows: int) -> tuple[int, int]:
    """(width, height) in pixels of the sections figure."""
    return columns * PANEL_PX[0] + COLORBAR_PX, rows * PANEL_PX[1] + TITLE_PX


def loss_curves_size(columns: int) -> tuple[int, int]:
    """(width, height) in pixels of the loss-curves figure."""
    return columns * PANEL_PX[0], PANEL_PX[1] + TITLE_PX


def plotting_available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


# ---------------------------------------------------------------------------------------------
# what is drawn: faces (polygon vertices) and their values, from plain arrays


def quad_faces(P: np.ndarray) -> np.ndarray:
    """The quads of a structured node grid ``P`` (a+1, b+1, 2) as vertices (a*b, 4, 2), in C order
    of the cells (the order of ``cell_metrics``), corners counter-clockwise in index space."""
    return np.stack([P[:-1, :-1], P[1:, :-1], P[1:, 1:], P[:-1, 1:]], axis=2).reshape(-1, 4, P.shape[-1])


def mid_section(X: np.ndarray, axis: int, metric: str):
    """The mid-plane of a 3D node array ``X`` (n1+1, n2+1, n3+1, 3) across index ``axis``.

    Returns (faces (M, 4, 2) in physical coordinates, values (M,), names of the two drawn
    physical axes, node index of the plane). Values are ``metric`` of the cells with index
    min(n//2, n-1) along ``axis``, computed on a slab of up to three cell layers around them, so
    that their face neighbours, and hence every metric, are those of the whole mesh.
    """
    n = X.shape[axis] - 1
    node = n // 2
    cell = min(node, n - 1)
    plane = np.take(X, node, axis=axis)  # (a+1, b+1, 3)
    extent = np.ptp(plane.reshape(-1, 3), axis=0)
    drawn = sorted(int(d) for d in np.argsort(extent, kind="stable")[1:])  # drop the flattest coordinate
    low, high = max(cell - 1, 0), min(cell + 2, n)  # cell layers low .. high-1
    slab = np.take(X, np.arange(low, high + 1), axis=axis)
    cell_shape = tuple(s - 1 for s in slab.shape[:-1])
    layer = np.take(cell_metrics(slab)[metric].reshape(cell_shape), cell - low, axis=axis)
    return quad_faces(plane[..., drawn]), layer.reshape(-1), [AXIS_NAMES[d] for d in drawn], node


def whole_mesh(picture, metric: str):
    """Faces and values of a 2D mesh: a node array (n1+1, n2+1, 2) or points (N, 2) with quads (M, 4)."""
    if picture.X is not None:
        return quad_faces(picture.X), cell_metrics(picture.X)[metric]
    return picture.points[picture.cells][..., :2], cell_metrics_unstructured(picture.points, picture.cells)[metric]


def drawable(picture) -> bool:
    """Whether ``picture`` holds a node array or quads (an unstructured 3D mesh has no mid-planes)."""
    return picture.X is not None or picture.cells is not None


def panels(picture, metric: str) -> list[dict] | None:
    """The panels of one column: dicts with faces, values, axis names and a row title; None when
    the mesh cannot be drawn (an unstructured 3D mesh)."""
    if picture.X is not None and picture.X.shape[-1] == 3:
        result = []
        for axis in range(3):
            faces, values, names, node = mid_section(picture.X, axis, metric)
            result.append({"faces": faces, "values": values, "axes": names, "row": f"{INDEX_NAMES[axis]} = {node}"})
        return result
    if drawable(picture):
        faces, values = whole_mesh(picture, metric)
        return [{"faces": faces, "values": values, "axes": ["x", "y"], "row": "whole mesh"}]
    return None


# ---------------------------------------------------------------------------------------------
# figures


def _figure(width_px: int, height_px: int):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI)
    FigureCanvasAgg(figure)
    return figure


def _axes(figure, size, column: int, row: int, left=58, right=14, bottom=44, top=26):
    """Axes of panel (row, column) with margins in pixels for tick labels and the panel title."""
    width, height = size
    x0 = column * PANEL_PX[0] + left
    y0 = height - TITLE_PX - (row + 1) * PANEL_PX[1] + bottom
    return figure.add_axes([x0 / width, y0 / height, (PANEL_PX[0] - left - right) / width, (PANEL_PX[1] - bottom - top) / height])


def _save(figure, path) -> Path:
    path = Path(path)
    with atomic_write(path) as temporary:
        figure.savefig(temporary, dpi=DPI, format="png")
    return path


def sections_figure(pictures, metric: str, path, heading: str = "") -> Path | None:
    """Write the sections PNG of ``pictures`` (objects with label, X or points + cells) coloured by
    ``metric``; columns of meshes that cannot be drawn are left out. Returns the path, or None
    when nothing can be drawn."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    columns = [(picture.label, panels(picture, metric)) for picture in pictures]
    columns = [(label, column) for label, column in columns if column]
    if not columns:
        return None
    rows = max(len(column) for _, column in columns)
    finite = np.concatenate([p["values"][np.isfinite(p["values"])] for _, column in columns for p in column])
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if high <= low:  # one value everywhere: a scale around it
        low, high = low - 0.5 * max(abs(low), 1.0), high + 0.5 * max(abs(high), 1.0)
    norm = Normalize(low, high)
    colormap = colormaps["viridis"].with_extremes(over="red", bad="lightgrey")

    size = sections_size(len(columns), rows)
    figure = _figure(*size)
    for c, (label, column) in enumerate(columns):
        for r, panel in enumerate(column):
            axes = _axes(figure, size, c, r)
            faces, values = panel["faces"], panel["values"]
            # Cell edges thin out as cells get smaller, so fine meshes show colour, not black lines.
            collection = PolyCollection(
                faces,
                array=values,
                cmap=colormap,
                norm=norm,
                edgecolors="black",
                linewidths=min(0.5, 15.0 / math.sqrt(len(faces))),
            )
            axes.add_collection(collection)
            axes.autoscale_view()
            axes.set_aspect("equal", adjustable="box")
            axes.set_xlabel(panel["axes"][0])
            axes.set_ylabel(panel["axes"][1])
            axes.tick_params(labelsize=8)
            axes.set_title(f"{label}: {panel['row']}" if rows > 1 else label, fontsize=10)
    width, height = size
    bar = figure.add_axes(
        [(len(columns) * PANEL_PX[0] + 20) / width, 44 / height, 22 / width, (height - TITLE_PX - 44 - 26) / height]
    )
    figure.colorbar(ScalarMappable(norm=norm, cmap=colormap), cax=bar, label=METRIC_LABELS.get(metric, metric))
    figure.suptitle(heading or METRIC_LABELS.get(metric, metric), y=1.0 - 8 / height, va="top", fontsize=12)
    return _save(figure, path)


def read_history(path) -> dict[str, np.ndarray]:
    """A training history CSV as float columns (step, L1, L2, total, ...); ``stage`` kept as
    strings. Non-numeric entries become NaN."""
    rows = list(csv.DictReader(read_input_text(path, "history").splitlines()))
    columns = {}
    for key in rows[0] if rows else ():
        if key == "stage":
            columns[key] = np.array([row[key] for row in rows])
            continue
        values = []
        for row in rows:
            try:
                values.append(float(row[key]))
            except (TypeError, ValueError):
                values.append(math.nan)
        columns[key] = np.array(values)
    return columns


LOSS_CURVES = (("L1", "L1 (Winslow)"), ("L2", "L2 (boundary)"), ("total", "weighted total"))


def loss_curves_figure(pictures, path) -> Path | None:
    """Write the loss curves of the ``pictures`` that have a ``history`` CSV; None when none has."""
    histories = [(p.label, read_history(p.history)) for p in pictures if p.history and Path(p.history).is_file()]
    histories = [(label, h) for label, h in histories if "step" in h and len(h["step"])]
    if not histories:
        return None
    size = loss_curves_size(len(histories))
    figure = _figure(*size)
    for c, (label, history) in enumerate(histories):
        axes = _axes(figure, size, c, 0, left=64)
        step = history["step"]
        # The pretraining stage fits TFI, a loss of another kind: drawn apart, not joined to L1, L2.
        pretrain = history["stage"] == "pretrain" if "stage" in history else np.zeros(len(step), dtype=bool)

        def positive(values, keep):  # a log axis shows positive values; NaN leaves a gap
            return np.where(keep & (values > 0), values, np.nan)

        for key, name in LOSS_CURVES:
            if key in history:
                axes.plot(step, positive(history[key], ~pretrain), label=name, linewidth=1.0)
        if pretrain.any() and "total" in history:
            axes.plot(
                step,
                positive(history["total"], pretrain),
                color="grey",
                linestyle="--",
                linewidth=1.0,
                label="fit to TFI (pretraining)",
            )
        if "stage" in history:
            changes = np.flatnonzero(history["stage"][1:] != history["stage"][:-1]) + 1
            for index in changes:
                axes.axvline(step[index], color="grey", linestyle=":", linewidth=0.8)
        axes.set_yscale("log")
        axes.set_xlabel("step")
        axes.set_ylabel("loss")
        axes.set_title(label, fontsize=10)
        axes.tick_params(labelsize=8)
        if c == 0:
            axes.legend(fontsize=8)
    figure.suptitle("training loss", y=1.0 - 8 / size[1], va="top", fontsize=12)
    return _save(figure, path)
