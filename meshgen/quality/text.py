"""Terminal text of a quality report: the few lines ``mesh``, ``train`` and ``compare`` print."""

from __future__ import annotations

__all__ = ["summary_lines"]


def _format(value, digits=4) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}g}"


def summary_lines(report: dict) -> list[str]:
    """A few lines for the terminal: the headline means, the worst cells, the verdict, the
    boundary deviation (what ``mesh``, ``train`` and ``compare`` print)."""
    m = report["metrics"]
    inv = report["inverted"]
    lines = [
        f"quality of {report['cells']} {report['cell_type']} cells: "
        f"min angle {_format(m['min_angle']['mean'], 3)} deg (worst {_format(m['min_angle']['min'], 3)}), "
        f"max angle {_format(m['max_angle']['mean'], 4)} deg (worst {_format(m['max_angle']['max'], 4)}), "
        f"equiangle skewness {_format(m['equiangle_skewness']['mean'], 3)}, "
        f"aspect ratio {_format(m['aspect_ratio']['mean'], 3)}",
        f"  centroid skewness {_format(m['centroid_skewness']['mean'], 3)}, "
        f"cell non-orthogonality (boundary faces included) {_format(m['non_orthogonality']['mean'], 3)} deg (worst {_format(m['non_orthogonality']['max'], 3)}), "
        f"scaled Jacobian min {_format(m['scaled_jacobian']['min'], 3)}",
        f"  inverted cells: {inv['count']} ({100 * inv['fraction']:.2f}%): "
        + ("valid" if report["valid"] else "NOT VALID")
        + " (valid: no inverted cell)",
    ]
    figures = report.get("solver_figures")
    if figures:
        internal, boundary = figures["non_orthogonality_internal"], figures["non_orthogonality_boundary"]
        expansion, smoothness = figures["expansion_ratio"], figures["grid_smoothness"]
        if "max_by_axis" in smoothness:
            where = f"; by axis {', '.join(_format(v, 2) for v in smoothness['max_by_axis'])}"
        else:  # a block set's merged mesh: the worst cell's block
            where = f" of block {smoothness.get('worst_block')}"
        lines.append(
            f"  expansion ratio max {_format(expansion['max'], 3)} (cell {tuple(expansion['worst_cell'])}"
            + (f" of block {expansion['worst_block']}" if "worst_block" in expansion else "")
            + f"), grid smoothness max {_format(smoothness['max'], 3)} (cell {tuple(smoothness['worst_cell'])}{where}), "
            f"checkMesh non-orthogonality max {_format(internal['max'], 3)} average {_format(internal['average'], 3)} deg "
            f"(boundary faces max {_format(boundary['max'], 3)})"
        )
    deviation = report.get("boundary_deviation")
    if deviation:
        if deviation["max"] is None:
            lines.append("  boundary deviation: undefined (non-finite boundary nodes)")
        else:
            lines.append(
                f"  boundary deviation from '{deviation['geometry']}': max {deviation['max']:.3g} "
                f"({deviation['max_rel']:.3g} of L = {deviation['characteristic_length']:.4g}), mean {deviation['mean']:.3g}"
            )
    for warning in report.get("warnings", []):
        lines.append(f"  warning: {warning}")
    return lines
