"""Quality gates for CI: ``--fail-if "min_angle.mean<70"`` trips when the expression is true.

A gate is ``QUANTITY OP VALUE``: QUANTITY names a figure of the quality report (``gate_names()``),
OP is one of ``< <= > >= == !=``, VALUE a number (``true``/``false`` for ``valid``). A quantity
the report does not have a value for (e.g. all cells degenerate) trips the gate: a CI gate fails
closed.
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass

from meshgen.errors import MeshgenError, did_you_mean
from meshgen.quality import METRICS, STATS
from meshgen.run.limits import parse_finite

__all__ = [
    "DEVIATION_FIELDS",
    "OPERATORS",
    "OTHER_NAMES",
    "Gate",
    "GateError",
    "check_gates",
    "gate_names",
    "gate_value",
    "parse_gate",
    "valid_names_text",
]

OPERATORS = {"<=": operator.le, ">=": operator.ge, "==": operator.eq, "!=": operator.ne, "<": operator.lt, ">": operator.gt}
_GATE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)?)\s*(<=|>=|==|!=|<|>)\s*([^\s<>=!]+)\s*$")
DEVIATION_FIELDS = ("max", "mean", "max_rel", "mean_rel")
# The solver figures of a structured mesh (``meshgen.quality.report.solver_figures``).
SOLVER_FIGURES = {
    "expansion_ratio": ("max", "mean", "p99"),
    "grid_smoothness": ("max", "mean", "p99"),
    "non_orthogonality_internal": ("max", "average"),
    "non_orthogonality_boundary": ("max", "average"),
}
OTHER_NAMES = (
    "inverted.count",
    "inverted.fraction",
    "inverted.percent",
    "valid",
    "cells",
    *(f"boundary_deviation.{field}" for field in DEVIATION_FIELDS),
    *(f"{name}.{field}" for name, fields in SOLVER_FIGURES.items() for field in fields),
)


class GateError(MeshgenError):
    """A malformed gate or an unknown quantity (a usage error: exit status 2)."""


def gate_names() -> list[str]:
    return [f"{metric}.{stat}" for metric in METRICS for stat in STATS] + list(OTHER_NAMES)


def valid_names_text() -> str:
    return (
        f"METRIC.STAT with METRIC one of {', '.join(METRICS)} and STAT one of {', '.join(STATS)}; "
        f"or one of {', '.join(OTHER_NAMES)}"
    )


@dataclass(frozen=True)
class Gate:
    text: str
    name: str
    op: str
    threshold: float

    def trips(self, value) -> bool:
        """True when the fail-if expression holds, or the value is unknown (fail closed)."""
        return value is None or bool(OPERATORS[self.op](float(value), self.threshold))


def parse_gate(text: str) -> Gate:
    match = _GATE.match(text)
    if not match:
        raise GateError(
            f"malformed --fail-if {text!r}: expected QUANTITY OP VALUE such as 'min_angle.mean<70' "
            f"(OP one of {' '.join(sorted(OPERATORS, key=len))}); quantities: {valid_names_text()}"
        )
    name, op, raw = match.groups()
    names = gate_names()
    if name not in names:
        raise GateError(f"unknown quantity {name!r} in --fail-if {text!r}{did_you_mean(name, names)} Valid: {valid_names_text()}")
    lowered = raw.lower()
    if lowered in ("true", "false"):
        threshold = 1.0 if lowered == "true" else 0.0
    else:
        try:
            threshold = parse_finite(raw, f"malformed --fail-if {text!r}")
        except MeshgenError as exc:
            raise GateError(str(exc)) from None
    return Gate(text.strip(), name, op, threshold)


def gate_value(report: dict, name: str):
    """The value of quantity ``name`` in a quality report (None if unknown); GateError if the report
    cannot have it (boundary deviation without a geometry)."""
    head, _, field = name.partition(".")
    if head in METRICS:
        return report["metrics"][head][field]
    if head == "inverted":
        inverted = report["inverted"]
        return 100.0 * inverted["fraction"] if field == "percent" else inverted[field]
    if head == "valid":
        return 1.0 if report["valid"] else 0.0
    if head == "cells":
        return report["cells"]
    if head == "boundary_deviation":
        deviation = report.get("boundary_deviation")
        if deviation is None:
            raise GateError(
                f"--fail-if on {name} needs the geometry: {report.get('file', 'the mesh')} records none; "
                "pass --geometry NAME [--param k=v]"
            )
        return deviation[field]
    if head in SOLVER_FIGURES:
        figures = report.get("solver_figures")
        if figures is None:
            raise GateError(
                f"--fail-if on {name} needs a structured mesh: {report.get('file', 'the mesh')} is not meshgen's grid"
            )
        return figures[head][field]
    raise GateError(f"unknown quantity {name!r}")


def check_gates(report: dict, gates) -> list[dict]:
    """[{gate, quantity, value, tripped}] for each gate on one report."""
    results = []
    for gate in gates:
        value = gate_value(report, gate.name)
        results.append({"gate": gate.text, "quantity": gate.name, "value": value, "tripped": gate.trips(value)})
    return results
