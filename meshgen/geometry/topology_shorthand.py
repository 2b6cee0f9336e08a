"""The shorthands of a topology file, each expanded into the file's vertices, blocks, edges,
counts, ratios and patches before the file is checked: ``pipe`` (``expand_pipe``: one round pipe
of 5-block O-grid sections, straight or bent) and ``joint`` (``expand_joint``): round pipes of
one radius whose axes meet at one point in one plane (a T, a cross, a Y)::

    joint:
      center: [5, 5, 0]                  # where the axes meet
      radius: 2
      arms:                              # each arm's far end: the centre of its end face, its patch
        - {end: [0, 0, 0], patch: inlet}
        - {end: [10, 0, 0], patch: outlet_1}
      wall: walls                        # the pipes' wall patch (default: walls)
      core: 0.5                          # the section's core half-width over the radius (default 0.5)
      cells: {core: 8, radial: 5, along: 14}     # half a core side, core to wall, along an arm
      grading: {radial: 0.1, along: 0.2}         # last cell over first: core -> wall, end -> centre

Each arm is an O-grid pipe of 8 blocks per section (two core rectangles side by side, split by the
diameter along the joint's normal, and 6 wall blocks round them) from its end face to the mitre
faces: the half-planes through the joint's axis (the line through ``center`` along the arms'
plane normal) that bisect the angle to the next arm on either side. Two arms' mitres are one
plane, so their blocks share the faces there; a pipe cut obliquely meets the mitre in an ellipse
(spline edges through 15 of its points). The vertices are named ``<arm>.<point>`` (``j.<point>`` on the axis, ``m<arm>.<point>`` on
the mitre towards the next arm counterclockwise about the normal).
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError, did_you_mean

__all__ = ["checked_keys", "expand_joint", "expand_pipe", "JOINT_KEYS", "PIPE_KEYS", "topology_error"]

JOINT_KEYS = ("center", "radius", "arms", "wall", "core", "cells", "grading", "normal")
PIPE_KEYS = ("start", "end", "bend", "length", "wall", "core", "cells", "grading")
_PIPE_CORNERS = (225.0, 315.0, 45.0, 135.0)  # the 5-block section's k0..k3 / w0..w3, degrees from e1 towards e2
_ARM_KEYS = ("end", "patch")
# The section in (side, up) coordinates over the radius: core points k*, wall points w* at 45-degree
# steps; side > 0 faces the next arm counterclockwise, up is the joint's normal.
_RING = ("br", "tr", "t", "tl", "bl", "b")  # counterclockwise from -45 degrees
_ANGLES = {"br": -45.0, "tr": 45.0, "t": 90.0, "tl": 135.0, "bl": 225.0, "b": 270.0}
_MIRROR = {"tl": "tr", "bl": "br", "t": "t", "b": "b"}  # a point on an arm's side < 0: the previous arm's name
_OWN = {("br", "tr"): (-45.0, 45.0), ("tr", "t"): (45.0, 90.0), ("b", "br"): (-90.0, -45.0)}
_SAMPLES = 15  # points inside each mitre ellipse arc (its spline)


def topology_error(path, text: str):
    """Raise the one-line error of topology file ``path`` (or "f.yaml: joint": the file and its
    shorthand's key)."""
    raise GeometryError(f"topology file {path}: {text}")


def _vector(path, where, value, dim=3) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.shape != (dim,) or not np.all(np.isfinite(array)):
        topology_error(path, f"{where} must be {dim} numbers")
    return array


def _positive(path, where, value, whole=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        topology_error(path, f"{where} must be a positive number, got {value!r}"[:160])
    if whole and (not isinstance(value, int) or value < 1):
        topology_error(path, f"{where} must be a positive whole number, got {value!r}"[:160])
    return value


def checked_keys(path, where: str, value, allowed) -> dict:
    """``value`` as a mapping whose keys are all in ``allowed`` (the nearest one named otherwise)."""
    if not isinstance(value, dict):
        topology_error(path, f"{where} must be a mapping (keys: {', '.join(allowed)})")
    for key in value:
        if str(key) not in allowed:
            topology_error(path, f"unknown key '{key}' in {where} (keys: {', '.join(allowed)}){did_you_mean(str(key), allowed)}")
    return value


def expand_joint(path, data: dict) -> dict:
    """``data`` (a topology file's mapping) with its ``joint`` entry expanded into vertices,
    blocks, edges, cells, grading and patches (added to any the file gives); GeometryError (one
    line) for a bad entry: arms not in one plane, two arms in one direction, an arm shorter than
    its mitre."""
    path = f"{path}: joint"
    joint = checked_keys(path, "the entry", data["joint"], JOINT_KEYS)
    for key in ("center", "radius", "arms"):
        if key not in joint:
            topology_error(path, f"needs '{key}'")
    center = _vector(path, "center", joint["center"])
    radius = float(_positive(path, "radius", joint["radius"]))
    core = float(_positive(path, "core", joint.get("core", 0.5)))
    if core >= np.sqrt(0.5):
        topology_error(path, f"core must be below 0.707 (the core's corners inside the pipe), got {core:g}")
    ends, patches = _arms(path, joint["arms"])
    directions = np.array([e - center for e in ends])
    lengths = np.linalg.norm(directions, axis=1)
    if np.any(lengths <= 1e-12 * radius):
        topology_error(path, "an arm's end is at the center")
    directions /= lengths[:, None]
    normal = _normal(path, joint, directions)
    # Arms counterclockwise about the normal from the first arm's direction.
    side0 = np.cross(normal, directions[0])
    angles = np.arctan2(directions @ side0, directions @ directions[0]) % (2 * np.pi)
    angles[angles > 2 * np.pi - 1e-12] = 0.0  # the first arm itself, a rounding below zero
    order = np.argsort(angles, kind="stable")
    gaps = np.diff(np.append(angles[order], 2 * np.pi))
    if np.any(gaps < 1e-6):
        topology_error(path, "two arms point the same way")
    if np.any(gaps > np.pi + 1e-9):
        topology_error(path, "the arms leave a gap of more than 180 degrees between two of them: the mitre would fold back")
    cells = checked_keys(path, "cells", joint.get("cells") or {}, ("core", "radial", "along"))
    grading = checked_keys(path, "grading", joint.get("grading") or {}, ("radial", "along"))
    counts = {
        k: _positive(path, f"cells: {k}", cells.get(k, d), whole=True) for k, d in (("core", 8), ("radial", 5), ("along", 10))
    }

    vertices, blocks, edges = {}, [], []
    ring = {name: np.array([np.cos(np.radians(a)), np.sin(np.radians(a))]) for name, a in _ANGLES.items()}
    section = {f"k{name}": core * np.sign(np.round(p, 12)) if name not in ("t", "b") else np.array([0.0, core * np.sign(p[1])])
               for name, p in ring.items()}  # fmt: skip
    section.update({f"w{name}": p for name, p in ring.items()})
    for position, arm in enumerate(order):
        previous, following = order[position - 1], order[(position + 1) % len(order)]
        d = directions[arm]
        side = np.cross(normal, d)
        # The mitre towards the next arm (side > 0) and the previous one (side < 0): s along d per unit side.
        slope = {+1: _mitre_slope(normal, d, angles[following] - angles[arm], +1),
                 -1: _mitre_slope(normal, d, angles[arm] - angles[previous], -1)}  # fmt: skip
        reach = max(abs(slope[+1]), abs(slope[-1])) * radius * np.sqrt(2.0)
        if lengths[arm] <= reach * (1 + 1e-9):
            topology_error(
                path,
                f"arm {arm} ({patches[arm]}) is shorter than its mitre ({lengths[arm]:.4g} <= {reach:.4g}): move its end out",
            )

        def at_mitre(y, z, d=d, side=side, slope=slope):
            s = slope[1] * y if y > 0 else slope[-1] * y
            return center + radius * (s * d + y * side + z * normal)

        def name_at_mitre(point, arm=arm, previous=previous):
            label = point[1:]
            if label in ("t", "b"):
                return f"j.{point}"
            if label in ("tr", "br"):
                return f"m{arm}.{point}"
            return f"m{previous}.{point[0]}{_MIRROR[label]}"

        end = {}
        for point, (y, z) in section.items():
            end[point] = f"{arm}.{point}"
            vertices[end[point]] = (ends[arm] + radius * (y * side + z * normal)).tolist()
            vertices.setdefault(name_at_mitre(point), at_mitre(y, z).tolist())
        mitre = {point: name_at_mitre(point) for point in section}
        # Blocks: bottom face on the end section, top on the mitre; counterclockwise seen from the mitre.
        faces = [("kbl", "kb", "kt", "ktl"), ("kb", "kbr", "ktr", "kt")]
        faces += [(f"w{a}", f"w{b}", f"k{b}", f"k{a}") for a, b in zip(_RING, _RING[1:] + _RING[:1])]
        for face in faces:
            bottom, top = [end[p] for p in face], [mitre[p] for p in face]
            blocks.append((bottom[::-1] + top[::-1]) if _left_handed(vertices, bottom, top) else bottom + top)
        for a, b in zip(_RING, _RING[1:] + _RING[:1]):
            edges.append({"arc": [end[f"w{a}"], end[f"w{b}"]], "center": ends[arm].tolist()})
            if (a, b) in _OWN:  # side >= 0: this arm's mitre (the previous arm's side < 0 is the same)
                t0, t1 = np.radians(_OWN[a, b])
                inner = np.linspace(t0, t1, _SAMPLES + 2)[1:-1]
                edges.append(
                    {
                        "spline": [mitre[f"w{a}"], mitre[f"w{b}"]],
                        "points": [at_mitre(np.cos(t), np.sin(t)).tolist() for t in inner],
                    }
                )
        a = str(arm)
        data = _merge(data, patches[arm], [[end[p] for p in face] for face in faces])
        data.setdefault("cells", {}).setdefault("counts", [])
        data["cells"]["counts"] += [[f"{a}.kb", f"{a}.kbr", counts["core"]], [f"{a}.kbr", f"{a}.wbr", counts["radial"]],
                                    [f"{a}.kb", mitre["kb"], counts["along"]], [f"{a}.kbr", f"{a}.ktr", 2 * counts["core"]]]  # fmt: skip
        data.setdefault("grading", {}).setdefault("ratios", [])
        if "along" in grading:
            data["grading"]["ratios"].append([f"{a}.kb", mitre["kb"], _positive(path, "grading: along", grading["along"])])
        if "radial" in grading:
            data["grading"]["ratios"].append([f"{a}.kbr", f"{a}.wbr", _positive(path, "grading: radial", grading["radial"])])
    data = {k: v for k, v in data.items() if k != "joint"}
    data["vertices"] = {**(data.get("vertices") or {}), **vertices}
    data["blocks"] = list(data.get("blocks") or []) + blocks
    data["edges"] = list(data.get("edges") or []) + edges
    data.setdefault("default_patch", {"name": str(joint.get("wall", "walls")), "type": "wall"})
    return data


def _arms(path, arms) -> tuple[list, list]:
    """(end centres (3,), end patch names) of the ``arms`` list."""
    if not isinstance(arms, list) or len(arms) < 2:
        topology_error(path, "arms must list at least two arms, each {end: [x, y, z], patch: name}")
    ends, patches = [], []
    for number, arm in enumerate(arms):
        arm = checked_keys(path, f"arms[{number}]", arm, _ARM_KEYS)
        ends.append(_vector(path, f"arms[{number}]: end", arm.get("end")))
        patches.append(str(arm.get("patch", f"end{number}")))
    return ends, patches


def _merge(data: dict, patch: str, faces: list) -> dict:
    data = dict(data)
    patches = dict(data.get("patches") or {})
    entry = dict(patches.get(patch) or {"type": "patch", "faces": []})
    entry["faces"] = list(entry.get("faces") or []) + faces
    patches[patch] = entry
    data["patches"] = patches
    return data


def _normal(path, joint: dict, directions: np.ndarray) -> np.ndarray:
    """The unit normal of the arms' plane: ``normal`` if given, else from the arms' directions."""
    if "normal" in joint:
        normal = _vector(path, "normal", joint["normal"])
    else:
        crosses = [np.cross(directions[0], d) for d in directions[1:]]
        normal = max(crosses, key=np.linalg.norm)
    size = np.linalg.norm(normal)
    if size < 1e-9:
        topology_error(path, "the arms are on one line: give 'normal', the joint's axis")
    normal = normal / size
    if np.any(np.abs(directions @ normal) > 1e-9):
        topology_error(path, "the arms' axes are not in one plane with the center (all must be normal to 'normal')")
    return normal


def _mitre_slope(normal, d, angle, sign: int) -> float:
    """s along ``d`` per unit side offset (side: normal x d) where the arm along ``d`` meets the
    half-plane bisecting the ``angle`` (radians) to the next arm on its ``sign`` side (+1:
    counterclockwise about the normal)."""
    half = 0.5 * (angle % (2 * np.pi))
    side = np.cross(normal, d)
    bisector = np.cos(half) * d + sign * np.sin(half) * side
    m = np.cross(bisector, normal)  # the mitre plane's normal, in the arms' plane
    return -float(side @ m) / float(d @ m)


def _left_handed(vertices: dict, bottom: list, top: list) -> bool:
    """Whether the hex bottom + top (blockMesh order) is left-handed, by its centroid Jacobian."""
    P = np.array([vertices[v] for v in bottom + top])
    xi = (P[1] + P[2] + P[5] + P[6] - P[0] - P[3] - P[4] - P[7]) / 4
    eta = (P[2] + P[3] + P[6] + P[7] - P[0] - P[1] - P[4] - P[5]) / 4
    zeta = (P[4:].sum(axis=0) - P[:4].sum(axis=0)) / 4
    return float(np.cross(xi, eta) @ zeta) < 0


def expand_pipe(path, data: dict) -> dict:
    """``data`` with its ``pipe`` entry expanded: a round pipe of 5-block O-grid sections (a square
    core, corners k0..k3, and 4 wall blocks to w0..w3 at 45 degrees) from its start section to its
    end section, straight (``length``) or bent about an axis (``bend``: center, axis, angle in
    degrees), its radius changing linearly; vertices ``a.k0`` .. ``b.w3`` (a: start, b: end)."""
    path = f"{path}: pipe"
    pipe = checked_keys(path, "the entry", data["pipe"], PIPE_KEYS)
    start = checked_keys(path, "start", pipe.get("start"), ("center", "normal", "radius", "patch"))
    end = checked_keys(path, "end", pipe.get("end") or {}, ("radius", "patch"))
    if ("bend" in pipe) == ("length" in pipe):
        topology_error(path, "needs one of 'bend' ({center, axis, angle}) and 'length' (a straight pipe)")
    center = _vector(path, "start: center", start.get("center"))
    normal = _vector(path, "start: normal", start.get("normal"))
    if np.linalg.norm(normal) < 1e-12:
        topology_error(path, "start: normal must not be zero")
    normal = normal / np.linalg.norm(normal)
    radii = (float(_positive(path, "start: radius", start.get("radius"))), 0.0)
    radii = (radii[0], float(_positive(path, "end: radius", end.get("radius", radii[0]))))
    core = float(_positive(path, "core", pipe.get("core", 0.4)))
    if core >= np.sqrt(0.5):
        topology_error(path, f"core must be below 0.707 (the core's corners inside the pipe), got {core:g}")
    if "bend" in pipe:
        bend = checked_keys(path, "bend", pipe["bend"], ("center", "axis", "angle"))
        pivot, axis = _vector(path, "bend: center", bend.get("center")), _vector(path, "bend: axis", bend.get("axis"))
        angle = bend.get("angle")
        if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not 0 < abs(angle) < 360:
            topology_error(path, f"bend: angle must be a number of degrees between -360 and 360, not 0, got {angle!r}"[:160])
        axis = axis / max(np.linalg.norm(axis), 1e-300)
        arm = center - pivot - ((center - pivot) @ axis) * axis  # from the bend's axis to the start centre
        if abs(normal @ axis) > 1e-9 or abs(normal @ arm) > 1e-9 * max(np.linalg.norm(arm), 1.0):
            topology_error(path, "start: normal must be tangent to the bend (normal to its axis and to the line from its center)")
        if np.linalg.norm(arm) <= max(radii) * (1 + 1e-9):
            topology_error(
                path,
                f"bend: its axis is within the pipe's radius of the start centre ({np.linalg.norm(arm):.4g}): the sections would fold",
            )
        e1 = -arm / np.linalg.norm(arm)  # towards the bend's axis

        def place(point, fraction):
            return _rotate(point, pivot, axis, np.radians(angle) * fraction)
    else:
        length = float(_positive(path, "length", pipe["length"]))
        e1 = np.eye(3)[int(np.argmin(np.abs(normal)))]
        e1 = e1 - (e1 @ normal) * normal
        e1 /= np.linalg.norm(e1)

        def place(point, fraction):
            return point + fraction * length * normal

    e2 = np.cross(normal, e1)

    def point(corner: float, scale: float, fraction: float) -> np.ndarray:
        radius = (1 - fraction) * radii[0] + fraction * radii[1]
        t = np.radians(corner)
        return place(center + radius * scale * (np.cos(t) * e1 + np.sin(t) * e2), fraction)

    vertices, edges = {}, []
    corner_scale = core * np.sqrt(2.0)  # the core's corners on the 45-degree lines
    for section, fraction in (("a", 0.0), ("b", 1.0)):
        middle = place(center, fraction) if "bend" in pipe else center + fraction * length * normal
        for i, corner in enumerate(_PIPE_CORNERS):
            vertices[f"{section}.k{i}"] = point(corner, corner_scale, fraction).tolist()
            vertices[f"{section}.w{i}"] = point(corner, 1.0, fraction).tolist()
        for i in range(4):
            edges.append({"arc": [f"{section}.w{i}", f"{section}.w{(i + 1) % 4}"], "center": middle.tolist()})
    if "bend" in pipe:
        for i, corner in enumerate(_PIPE_CORNERS):
            for kind, scale in (("k", corner_scale), ("w", 1.0)):
                edges.append({"arc": [f"a.{kind}{i}", f"b.{kind}{i}"], "through": point(corner, scale, 0.5).tolist()})
    faces = [[f"k{i}" for i in range(4)]] + [[f"w{i}", f"w{(i + 1) % 4}", f"k{(i + 1) % 4}", f"k{i}"] for i in range(4)]
    blocks = []
    for face in faces:
        bottom, top = [f"a.{p}" for p in face], [f"b.{p}" for p in face]
        blocks.append((bottom[::-1] + top[::-1]) if _left_handed(vertices, bottom, top) else bottom + top)
    cells = checked_keys(path, "cells", pipe.get("cells") or {}, ("tangential", "radial", "along"))
    grading = checked_keys(path, "grading", pipe.get("grading") or {}, ("radial", "along"))
    counts = {
        k: _positive(path, f"cells: {k}", cells.get(k, d), whole=True)
        for k, d in (("tangential", 10), ("radial", 5), ("along", 10))
    }
    data = {k: v for k, v in data.items() if k != "pipe"}
    data["vertices"] = {**(data.get("vertices") or {}), **vertices}
    data["blocks"] = list(data.get("blocks") or []) + blocks
    data["edges"] = list(data.get("edges") or []) + edges
    data["cells"] = dict(data.get("cells") or {})
    data["cells"]["counts"] = list(data["cells"].get("counts") or []) + [
        ["a.k0", "a.k1", counts["tangential"]], ["a.k0", "a.k3", counts["tangential"]],
        ["a.w0", "a.k0", counts["radial"]], ["a.k0", "b.k0", counts["along"]],
    ]  # fmt: skip
    data["grading"] = dict(data.get("grading") or {})
    ratios = list(data["grading"].get("ratios") or [])
    if "radial" in grading:
        ratios.append(["a.k0", "a.w0", _positive(path, "grading: radial", grading["radial"])])
    if "along" in grading:
        ratios.append(["a.k0", "b.k0", _positive(path, "grading: along", grading["along"])])
    data["grading"]["ratios"] = ratios
    data = _merge(data, str(start.get("patch", "inlet")), [[f"a.{p}" for p in face] for face in faces])
    data = _merge(data, str(end.get("patch", "outlet")), [[f"b.{p}" for p in face] for face in faces])
    data.setdefault("default_patch", {"name": str(pipe.get("wall", "walls")), "type": "wall"})
    return data


def _rotate(point: np.ndarray, pivot: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``point`` turned by ``angle`` (radians, right-handed) about the line through ``pivot`` along the unit ``axis``."""
    offset = point - pivot
    return pivot + (
        offset * np.cos(angle) + np.cross(axis, offset) * np.sin(angle) + axis * (axis @ offset) * (1 - np.cos(angle))
    )
