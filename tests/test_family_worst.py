"""The family summary's worst member: inverted cells first, then the mean minimum angle."""

from __future__ import annotations

import numpy as np

from meshgen.neural.family_train import worst_member
from meshgen.quality import quality_report


def _box(dims=(3, 3, 3)) -> np.ndarray:
    axes = [np.arange(n + 1, dtype=float) for n in dims]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def test_an_inverted_member_is_worse_than_a_valid_one_with_lower_angles():
    box = _box()
    sheared = box.copy()
    sheared[..., 0] += 0.6 * sheared[..., 1]  # valid, lower mean minimum angle than the box
    folded = box.copy()
    folded[2, ..., 0] = 0.5  # node layer 2 moved behind layer 1: cells inverted, angles still 90
    members = [{"network": quality_report(X)} for X in (box, sheared, folded)]
    assert members[2]["network"]["inverted"]["count"] > 0
    angles = [m["network"]["metrics"]["min_angle"]["mean"] for m in members]
    assert angles[1] < angles[2]  # by angle alone the sheared member would be the worst
    assert worst_member(members) == 2
    assert worst_member(members[:2]) == 1
