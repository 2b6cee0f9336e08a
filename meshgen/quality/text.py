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
        lines.append(
            f"  expansion ratio max {_format(figures['expansion_ratio']['max'], 3)} "
            f"(cell {tuple(figures['expansion_ratio']['worst_cell'])}), grid smoothness max "
            f"{_format(figures['grid_smoothness']['max'], 3)} (cell {tuple(figures['grid_smoothness']['worst_cell'])}; by axis "
            f"{', '.join(_format(v, 2) for v in figures['grid_smoothness']['max_by_axis'])}), "
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
