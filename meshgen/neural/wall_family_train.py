"""Training a family of wall-layer sections (``meshgen.neural.wall_family``): one network fitted to
the teachers (the plugin's ``wall_teacher``: the airfoil's marched layers) of many members at once.

The members are the box's 2^k corners, its middle and ``points.members`` more drawn by a Latin
hypercube (seeded: every member of the box is near a drawn one in each parameter). Each member's
rows are those of a single section (``meshgen.neural.wall_train.wall_rows``: its own frame, its own
xi nodes for q) with its normalised parameters appended; the stages, the held-out share and the
checkpoint are those of a single section. The summary meshes a grid of ``VALIDATION_POINTS`` values
per parameter (corners included) with the model and with the elliptic method, and names the
members whose mesh has inverted cells or whose mean minimum angle lies more than
``ANGLE_TOLERANCE`` below the elliptic mesh's.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import BlockSet, load_block_set
from meshgen.geometry.plugins import plugin_module
from meshgen.neural import wall_family, wall_map
from meshgen.quality import quality_report

__all__ = [
    "ANGLE_TOLERANCE",
    "VALIDATION_POINTS",
    "check_family_ranges",
    "describe_family",
    "family_members",
    "family_rows",
    "member_check",
    "validate_family",
]

VALIDATION_POINTS = 3  # values per varied parameter of the summary's grid of members (ends included)
ANGLE_TOLERANCE = 1.0  # degrees: a member whose mean min angle is further below its elliptic mesh's fails


def family_members(ranges: dict, count: int, seed: int) -> list[dict]:
    """The members fitted: the 2^k corners of ``ranges`` (name -> (lo, hi)), the middle, and
    ``count`` Latin-hypercube members (each parameter's range cut in ``count`` equal strata, one
    member in each, the strata paired at random with ``seed``)."""
    ends = [[(n, float(lo)), (n, float(hi))] for n, (lo, hi) in ranges.items()]
    members = [dict(c) for c in itertools.product(*ends)] + [{n: 0.5 * (lo + hi) for n, (lo, hi) in ranges.items()}]
    rng = np.random.default_rng(seed)
    if count:
        strata = [(rng.permutation(count) + rng.random(count)) / count for _ in ranges]
        for row in zip(*strata):
            members.append({n: float(lo + t * (hi - lo)) for t, (n, (lo, hi)) in zip(row, ranges.items())})
    return members


def _member_set(name: str, base: dict, member: dict, dims) -> BlockSet:
    check = getattr(plugin_module(name)[0], "check_family_member", None)
    try:
        if check is not None:
            check({**base, **member}, tuple(member))
        return load_block_set(name, {**base, **member}, dims)
    except MeshgenError as exc:
        at = ", ".join(f"{k}={v:g}" for k, v in member.items())
        raise type(exc)(f"--vary: the member {at} is not a valid section ({exc})") from None


def check_family_ranges(name: str, base: dict, ranges: dict, dims) -> None:
    """MeshgenError (one line) naming the first corner of ``ranges`` that is no valid member (a
    section of thickness 0, a camber the plugin refuses), or a member of another topology (the
    corners must all be C-grids or all O-grids), before any training."""
    kinds = {}
    for member in family_members(ranges, 0, 0):
        block_set = _member_set(name, base, member, dims)
        hooks = wall_map.wall_hooks(block_set)
        kinds[bool(hooks.wall_layout(block_set.values)["closed"])] = member
    if len(kinds) > 1:
        ring = ", ".join(f"{k}={v:g}" for k, v in kinds[True].items())
        row = ", ".join(f"{k}={v:g}" for k, v in kinds[False].items())
        raise GeometryError(f"--vary: the members {row} and {ring} have different topologies (a row and a ring of blocks)")


def family_rows(block_set: BlockSet, ranges: dict, dims, scales: dict, count: int, seed: int, wall_rows) -> tuple:
    """The fit's rows (inputs, targets, weights) of every member of :func:`family_members`, each
    the middle member ``block_set``'s parameters with its own varied ones, meshed at ``dims``:
    ``wall_rows(member_set, scales, extra)`` (``meshgen.neural.wall_train``'s) of each."""
    family = {"ranges": ranges}
    parts = []
    for member in family_members(ranges, count, seed):
        member_set = _member_set(block_set.name, block_set.values, member, dims)
        try:
            parts.append(wall_rows(member_set, scales, wall_family.normalised(family, member)))
        except MeshgenError as exc:
            at = ", ".join(f"{k}={v:g}" for k, v in member.items())
            raise type(exc)(f"--vary: the member {at} has no elliptic mesh to learn ({exc})") from None
    return tuple(np.concatenate(column) for column in zip(*parts))


def describe_family(block_set: BlockSet, ranges: dict, dims) -> dict:
    """``model["family"]`` of a family trained about the middle member ``block_set`` at ``dims``."""
    module = plugin_module(block_set.name)[0]
    return {
        "ranges": {n: [float(lo), float(hi)] for n, (lo, hi) in ranges.items()},
        "base": {k: float(v) for k, v in block_set.values.items()},
        "free": sorted(getattr(module, "wall_free", ())),
        "train_dims": [int(n) for n in dims],
    }


def member_check(model: dict, block_set: BlockSet) -> tuple[list, dict]:
    """The member ``block_set`` meshed by the family ``model`` (not checked: inverted cells
    counted) and by the elliptic method: (the network's node arrays, {"inverted", "mean_min_angle",
    "elliptic_mean_min_angle", "gap": elliptic - network, "seconds": the network's mesh})."""
    start = time.perf_counter()
    neural, _ = wall_map.neural_wall_blocks(block_set, model, check=False)
    seconds = time.perf_counter() - start
    report = quality_report(merged_mesh(block_set, neural)[:2])
    angle = float(report["metrics"]["min_angle"]["mean"])
    elliptic = wall_map.elliptic_reference(block_set)
    reference = float(quality_report(merged_mesh(block_set, elliptic)[:2])["metrics"]["min_angle"]["mean"])
    return neural, {
        "inverted": int(report["inverted"]["count"]),
        "mean_min_angle": angle,
        "elliptic_mean_min_angle": reference,
        "gap": reference - angle,
        "seconds": seconds,
    }


def validate_family(model: dict, name: str, points: int = VALIDATION_POINTS) -> dict:
    """The grid of ``points`` values per varied parameter (the corners included), each member
    meshed at the family's ``train_dims`` by the model (not checked: inverted cells counted) and by
    the elliptic method: per member its values, inverted cells, both mean min angles and the
    gap (elliptic - network); ``failed``: the members with inverted cells or a gap above
    ``ANGLE_TOLERANCE``; ``seconds``: the median time of the model's meshes."""
    family = model["family"]
    axes = [[(n, float(v)) for v in np.linspace(lo, hi, points)] for n, (lo, hi) in family["ranges"].items()]
    rows, times = [], []
    for member in (dict(m) for m in itertools.product(*axes)):
        block_set = load_block_set(name, {**family["base"], **member}, tuple(family["train_dims"]))
        _, row = member_check(model, block_set)
        times.append(row.pop("seconds"))
        rows.append({"params": member, **row})
    failed = [r for r in rows if r["inverted"] or r["gap"] > ANGLE_TOLERANCE]
    return {
        "points": points,
        "dims": list(family["train_dims"]),
        "members": rows,
        "failed": failed,
        "worst_gap": max(r["gap"] for r in rows),
        "seconds": float(np.median(times)),
    }
