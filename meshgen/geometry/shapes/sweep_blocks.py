"""A CAD solid that is a sweep as a block set (``meshgen.geometry.blocks``): its cap is cut into
quadrilateral blocks, each carried from the first cap to the second by the sweep's rigid motion
(a translation, or a rotation about an axis: ``sweep_read.moved``).

``sweep_module(path)`` returns a block-set plugin module, as ``topology.topology_module`` does for
a topology file, so ``meshgen mesh -g part.step`` meshes it like ``geometries/pipe.py``:

- the cap (read in the CAD process: ``sweep_read``) is one loop of CAD curves, each a cubic
  spline through its points at arc-length fractions (1025 per curve: exact to about 1e-12 of the
  part's size for an arc);
- a loop of one smooth closed curve (or 2 or 4 curves joining smoothly): an O-grid like the pipe's
  (a core whose sides bulge by ``BULGE``, corners at ``CORE`` of the way to four points a quarter
  of the loop apart, and four ring blocks); a loop of n sharp corners: midpoint subdivision, n
  quadrilaterals around the cap's centroid, each with one corner of the cap and two half sides;
- each block's map is the Coons patch of its four sides in the cap's plane carried a share zeta
  of the way along the motion, so its outer faces are the cap outline's sweep, which is the
  linking faces (``sweep_read`` checks it), and its ends lie on the caps;
- patches: one per CAD face (its name, else face1..faceN), wall unless the name says otherwise;
  a triangulated surface's (``sweep_stl``): its sharp-edge split's patches, the outline its
  polyline, and on a bend the nodes of each block face on the outline put on the linking facets
  (``sweep_stl_turn.SideMap``: the facets are chords of the turned outline).
- ``elliptic_options`` (passed on by ``meshgen.run.meshing``): a straight sweep is solved as its
  cap's 2D mesh, extruded, whose flat sides slide, except in ring blocks at sharp corners or
  smooth joints (a filleted cap, a square tube: sliding carries nodes past the corner and folds
  cells, ``slide_section`` off); on a bend every boundary node stays.

- a loop that mixes sharp corners and smooth joints (a filleted edge): a ring of two blocks per
  curve (its halves) around a core polygon, the loop offset inwards (``sweep_ring``), midpoint-
  subdivided, so no block has a corner at a smooth joint;
- a smooth loop around one smooth hole (a pipe's wall): a ring of four blocks between them; a
  loop of n sharp corners around a hole of as many (a square tube): a ring of n blocks;
- a loop of 1 or 2 curves with one sharp corner (an airfoil's trailing edge): one block ``te``
  holds the whole corner (a spoke into it would halve its angle in two cells), the rest a ring of
  six blocks around a core of two (``_wedge_blocks``); the elliptic method keeps the TFI mesh
  (``keep_tfi``: Winslow smoothing turns the corner's sliver cells inside out).

A loft (``sweep_read``: planar parallel caps whose outlines pair curve by curve on ruled linking
faces, a circle to a square) cuts both caps alike (O-grids, or midpoint subdivision of two loops
of corners); each block is the straight blend of its two cap maps, so its outer faces are the
rulings, which lie on the linking faces.

Other caps with holes and solids that are no such sweep are one GeometryError naming what was
found and pointing to topology files.

A YAML geometry file whose ``surface`` is such a sweep is one too (``sweep_yaml``, through
``build_sweep_module``): its ``caps`` choose the pair the cap search tries, ``rename`` and
``types`` the patches written.
"""

from __future__ import annotations

import re
import types
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube
from meshgen.geometry.shapes.assemble import CAD_FORMATS, TRIANGULATED_FORMATS, content_hash, default_patch_type, file_state
from meshgen.geometry.shapes.cad_process import cad_sweep
from meshgen.geometry.shapes.sweep_read import moved
from meshgen.geometry.shapes.sweep_ring import coons, piece, ring_blocks, segment
from meshgen.geometry.shapes.sweep_stl import read_surface_sweep

__all__ = [
    "BULGE",
    "CORE",
    "WEDGE_ANGLE",
    "WEDGE_DEPTH",
    "build_sweep_module",
    "is_sweep_file",
    "read_sweep_file",
    "sweep_module",
]

CORE = 0.45 * np.sqrt(2.0)  # the O-grid core's corners: this share of the way to the loop
BULGE = np.radians(15.0)  # the core's sides leave its corners turned by this (as the pipe's)
WEDGE_ANGLE = np.radians(100.0)  # a sharp-cornered loop's te block: its angles at U and L
WEDGE_DEPTH = 0.5  # and the rest's core corners: this share of half the distance U to L in
WEDGE_ELLIPTIC = (
    "{name}: elliptic: the TFI mesh is kept (Winslow smoothing pulls the sliver cells at the sharp corner "
    "inside out: 2628 of the 3600 cells of a NACA 0012 wing at 10 5 6)"
)
OFFSET_ELLIPTIC = (
    "{name}: elliptic: the TFI mesh is kept (Winslow smoothing of an offset ring-and-core cap folds cells: "
    "1224 of the 1820 of a 3 x 1 filleted box at 7 3 4)"
)
_READ: dict = {}
_MODULES: dict = {}
TOPOLOGY_HINT = "describe its blocks in a topology file (docs/topologies.md)"


def read_sweep_file(path: Path, caps=None, feature_angle=None) -> dict:
    """The sweep reader's answer for the file ``path`` (``caps``: the pair of names to try as the
    caps; ``feature_angle``: a triangulated surface's split), kept per file state and arguments."""
    caps = None if caps is None else tuple(caps)
    key = (*file_state(path), caps, feature_angle)
    if key not in _READ:
        if path.suffix.lower() in TRIANGULATED_FORMATS:
            _READ[key] = read_surface_sweep(path, caps, feature_angle)
        else:
            _READ[key] = cad_sweep(path, content_hash([path], {} if caps is None else {"caps": caps}), caps)
    return _READ[key]


def is_sweep_file(spec) -> bool:
    """Whether ``spec`` names a readable CAD file whose solid is not six four-cornered faces (it is
    then meshed as a block set, or refused with a pointer to topology files), or a triangulated
    surface that is a sweep (``sweep_stl``) or has two planar caps that every other patch touches
    (refused here, saying why they are no sweep's). A YAML geometry file naming one:
    ``sweep_yaml.is_sweep_geometry``."""
    suffix = Path(str(spec)).suffix.lower() if isinstance(spec, (str, Path)) else ""
    if suffix not in CAD_FORMATS + TRIANGULATED_FORMATS:
        return False
    path = Path(str(spec))
    if not path.is_file():
        return False
    try:  # a triangulated surface only when a sweep: else its own reader says what it is
        found = read_sweep_file(path)
        if suffix in TRIANGULATED_FORMATS:
            return found["kind"] == "sweep" or bool(found.get("caps_found"))
        return found["kind"] != "six"
    except GeometryError:
        return False  # the single-block reader reports what is wrong with the file


def _spline(fractions: np.ndarray, points: np.ndarray, linear: bool = False):
    """The curve t -> (N, 2) through ``points`` at ``fractions`` (cubic spline; ``linear``: the
    polyline, a triangulated outline's own edges), t in [0, 1]."""
    if linear:
        return lambda t: np.stack([np.interp(np.asarray(t, dtype=float), fractions, p) for p in points.T], axis=1)
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(fractions, points, axis=0)
    return lambda t: spline(np.clip(np.asarray(t, dtype=float), 0.0, 1.0))


def _midpoint_blocks(curves, faces):
    """n quadrilaterals around the centroid (the frame's origin): block k has the corner at the
    start of curve k, half of curve k - 1 (xi = 1) and half of curve k (eta = 1)."""
    n, centre = len(curves), np.zeros(2)
    middle = [curve(np.array([0.5]))[0] for curve in curves]
    blocks, patches, interfaces = {}, {}, []
    for k in range(n):
        name = f"quad{k}"
        blocks[name] = (
            segment(centre, middle[k]),
            piece(curves[k - 1], 0.5, 1.0),
            segment(centre, middle[k - 1]),
            piece(curves[k], 0.5, 0.0),
        )
        patches[name] = {"xi1": faces[k - 1], "eta1": faces[k]}
        interfaces.append((name, "eta0", f"quad{(k - 1) % n}", "xi0"))
    return blocks, patches, interfaces


def _ogrid_blocks(curves, faces, corners=None):
    """A core and four ring blocks (``ring0`` .. ``ring3`` counterclockwise, xi from the core
    outwards), the loop cut at four points a quarter of it apart (at the curves' ends); the core's
    corners ``corners`` (4, 2), else ``CORE`` of the way from the origin to the cuts."""
    pieces = _quarters(curves)
    outer = [piece(curves[c], a, b) for c, a, b in pieces]
    if corners is None:
        corners = [CORE * w(np.zeros(1))[0] for w in outer]
    core_sides = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        half = 0.5 * (b - a)
        normal = np.array([half[1], -half[0]])  # outwards: the loop runs counterclockwise

        def side(t, a=a, half=half, normal=normal):
            s = 2.0 * np.asarray(t, dtype=float)[:, None] - 1.0
            return a + half + s * half + 0.5 * np.tan(BULGE) * (1.0 - s**2) * normal

        core_sides.append(side)
    blocks = {
        "core": (
            piece(core_sides[2], 1.0, 0.0),
            core_sides[0],
            core_sides[3],
            piece(core_sides[1], 1.0, 0.0),
        )
    }
    patches, interfaces = {}, []
    for k in range(4):
        name = f"ring{k}"
        start, stop = outer[k](np.zeros(1))[0], outer[k](np.ones(1))[0]
        blocks[name] = (core_sides[k], outer[k], segment(corners[k], start), segment(corners[(k + 1) % 4], stop))
        patches[name] = {"xi1": faces[pieces[k][0]]}
        interfaces.append((name, "eta1", f"ring{(k + 1) % 4}", "eta0"))
    interfaces += [("core", face, f"ring{k}", "xi0") for k, face in enumerate(("xi1", "eta1", "xi0", "eta0"))]
    return blocks, patches, interfaces


def _quarters(curves):
    """The loop of 1, 2 or 4 curves cut into four pieces: (curve index, start, stop) each."""
    per = 4 // len(curves)
    return [(k // per, (k % per) / per, (k % per + 1) / per) for k in range(4)]


def _sides(curves, smooth: bool):
    """A loop's sides for a ring: (piece, curve index) per quarter of a smooth loop of 1, 2 or 4
    curves, else per curve (a loop of sharp corners)."""
    if smooth:
        return [(piece(curves[c], a, b), c) for c, a, b in _quarters(curves)]
    return [(curve, k) for k, curve in enumerate(curves)]


def _annulus_blocks(curves, faces, hole, hole_faces, smooth: bool):
    """A ring of blocks (``ring0``.., xi from the hole outwards, eta counterclockwise) between the
    outer loop and the hole's, both smooth (cut into quarters) or both of n sharp corners (one
    block per side); the hole's cuts turned to face the outer ones (a single smooth closed curve is
    cut anywhere, else at its curves' ends)."""
    outer = _sides(curves, smooth)
    n = len(outer)
    cuts = np.array([w(np.zeros(1))[0] for w, _ in outer])
    if smooth and len(hole) == 1:  # the hole's point in the direction of the first outer cut
        centre = np.mean(hole[0](np.linspace(0.0, 1.0, 65)[:-1]), axis=0)
        s = np.linspace(0.0, 1.0, 4097)
        along = hole[0](s) - centre
        toward = (cuts[0] - centre) / np.linalg.norm(cuts[0] - centre)
        start = float(s[int(np.argmax(along @ toward / np.linalg.norm(along, axis=1)))])
        closed = hole[0]
        inner = [(lambda t, a=start + k / 4: closed(np.mod(a + 0.25 * np.asarray(t, dtype=float), 1.0)), 0) for k in range(4)]
    else:  # the turn of the hole's sides that puts their corners nearest the outer ones
        pieces = _sides(hole, smooth)
        firsts = np.array([w(np.zeros(1))[0] for w, _ in pieces])
        gaps = [np.linalg.norm(np.roll(firsts, -shift, axis=0) - cuts, axis=1).sum() for shift in range(n)]
        shift = int(np.argmin(gaps))
        inner = [pieces[(k + shift) % n] for k in range(n)]
    blocks, patches, interfaces = {}, {}, []
    for k in range(n):
        name, (side, curve) = f"ring{k}", inner[k]
        a0, a1 = side(np.zeros(1))[0], side(np.ones(1))[0]
        blocks[name] = (side, outer[k][0], segment(a0, cuts[k]), segment(a1, cuts[(k + 1) % n]))
        patches[name] = {"xi0": hole_faces[curve], "xi1": faces[outer[k][1]]}
        interfaces.append((name, "eta1", f"ring{(k + 1) % n}", "eta0"))
    return blocks, patches, interfaces


def _loop_curve(curves, lengths):
    """The loop as one curve s -> (N, 2), s in [0, 1] by the curves' lengths ``lengths`` from the
    start of curve 0 (s = 1 is s = 0 again); (the curve, each curve's start s (n + 1,))."""
    starts = np.concatenate([[0.0], np.cumsum(lengths)]) / float(np.sum(lengths))

    def along(s):
        s = np.mod(np.asarray(s, dtype=float), 1.0)
        k = np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(curves) - 1)
        out = np.empty((len(s), 2))
        for j, curve in enumerate(curves):  # one call per CAD curve
            mask = k == j
            out[mask] = curve((s[mask] - starts[j]) / (starts[j + 1] - starts[j]))
        return out

    return along, starts


def _wedge_blocks(curves, faces, lengths):
    """A loop of 1 or 2 curves with one sharp corner T at the start of curve 0 (a trailing edge)
    and otherwise smooth: one block ``te`` holds the whole corner (T; U and L half way to the nose
    P either way; Q where lines from U and L at ``WEDGE_ANGLE`` to the loop meet); the rest, a
    D-shaped loop U P L Q, a ring of six blocks (ring0..ring5: U-P1, P1-P, P-P2, P2-L along the
    loop, L-Q and Q-U against ``te``) around a core of two quadrilaterals (core0 above, core1
    below the line from Q's core corner to P's). The ring is ``WEDGE_DEPTH`` of half the distance
    U to L deep: its core corners lie that far in along the corners' bisectors, P's along the
    chord P-T; P1 and P2 are the loop's points nearest the core corners half as far off the chord."""
    along, starts = _loop_curve(curves, lengths)
    nose = float(starts[1]) if len(curves) == 2 else 0.5
    s_u, s_l = 0.5 * nose, 0.5 * (1.0 + nose)
    tangent = {}
    for s in (s_u, s_l):  # unit tangents, counterclockwise
        step = np.diff(along(np.array([s - 1e-6, s + 1e-6])), axis=0)[0]
        tangent[s] = step / np.linalg.norm(step)
    T, U, P, L = along(np.array([0.0, s_u, nose, s_l]))
    to_q = [_turned(-tangent[s_u], -WEDGE_ANGLE), _turned(tangent[s_l], WEDGE_ANGLE)]
    steps = np.linalg.lstsq(np.stack([to_q[0], -to_q[1]], axis=1), L - U, rcond=None)[0]
    Q = 0.5 * (U + steps[0] * to_q[0] + L + steps[1] * to_q[1])
    depth = WEDGE_DEPTH * 0.5 * np.linalg.norm(U - L)
    chord = (T - P) / np.linalg.norm(T - P)
    up = _turned(chord, np.pi / 2)  # towards U's side
    core_p = P + depth * chord
    core_1, core_2 = core_p + 0.5 * depth * up, core_p - 0.5 * depth * up
    s = np.linspace(0.0, 1.0, 8193)
    dense = along(s)
    s_1 = float(s[np.argmin(np.where((s > s_u) & (s < nose), np.linalg.norm(dense - core_1, axis=1), np.inf))])
    s_2 = float(s[np.argmin(np.where((s > nose) & (s < s_l), np.linalg.norm(dense - core_2, axis=1), np.inf))])
    core_u = U + depth * _unit(tangent[s_u] + to_q[0])
    core_l = L + depth * _unit(-tangent[s_l] + to_q[1])
    core_q = Q - depth * chord
    cuts = [U, along(np.array([s_1]))[0], P, along(np.array([s_2]))[0], L, Q]
    corners = [core_u, core_1, core_p, core_2, core_l, core_q]
    span = [(s_u, s_1), (s_1, nose), (nose, s_2), (s_2, s_l)]
    outer = [(lambda t, a=a, b=b: along(a + np.asarray(t, dtype=float) * (b - a))) for a, b in span]
    outer += [segment(L, Q), segment(Q, U)]
    blocks, patches, interfaces = {}, {}, []
    for k in range(6):
        name, after = f"ring{k}", (k + 1) % 6
        blocks[name] = (
            segment(corners[k], corners[after]),
            outer[k],
            segment(corners[k], cuts[k]),
            segment(corners[after], cuts[after]),
        )
        interfaces.append((name, "eta1", f"ring{after}", "eta0"))
        if k < 4:
            patches[name] = {"xi1": faces[0] if k < 2 else faces[-1]}
    blocks["core0"] = _quad(core_q, core_u, core_1, core_p)
    blocks["core1"] = _quad(core_p, core_2, core_l, core_q)
    blocks["te"] = (lambda t: along(1.0 - np.asarray(t, dtype=float) * (1.0 - s_l)), segment(U, Q),
                    lambda t: along(np.asarray(t, dtype=float) * s_u), segment(L, Q))  # fmt: skip
    patches["te"] = {"xi0": faces[-1], "eta0": faces[0]}
    interfaces += [
        ("core0", "eta0", "ring5", "xi0"), ("core0", "xi1", "ring0", "xi0"), ("core0", "eta1", "ring1", "xi0"),
        ("core0", "xi0", "core1", "xi0"), ("core1", "eta0", "ring2", "xi0"), ("core1", "xi1", "ring3", "xi0"),
        ("core1", "eta1", "ring4", "xi0"), ("te", "xi1", "ring5", "xi1"), ("te", "eta1", "ring4", "xi1"),
    ]  # fmt: skip
    return blocks, patches, interfaces


def _quad(a, b, c, d):
    """The straight sides of the quadrilateral a (xi, eta = 0, 0), b (1, 0), c (1, 1), d (0, 1)."""
    return segment(a, d), segment(b, c), segment(a, b), segment(d, c)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _turned(v: np.ndarray, angle: float) -> np.ndarray:
    """(2,) ``v`` turned counterclockwise by ``angle`` (radians)."""
    return np.array([np.cos(angle) * v[0] - np.sin(angle) * v[1], np.sin(angle) * v[0] + np.cos(angle) * v[1]])


def _folded(blocks) -> list[str]:
    """The blocks whose cap map folds: a cell of its 16 x 16 sample grid with no positive area."""
    t = np.linspace(0.0, 1.0, 17)
    xi, eta = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    folded = []
    for name, sides in blocks.items():
        p = coons(sides, xi, eta).reshape(17, 17, 2)
        d1, d2 = p[1:, 1:] - p[:-1, :-1], p[:-1, 1:] - p[1:, :-1]  # the cells' diagonals
        if not (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0] > 0).all():
            folded.append(name)
    return folded


def _cut_cap(who: str, found: dict, summary: str):
    """The first cap's blocks by the scheme its loop takes (module docstring), and the second cap's
    for a loft: (blocks, second cap's blocks or None, block sides on CAD faces, interfaces, what
    was done, the --dims meaning, per block the --dims axes it counts, elliptic options, lines)."""
    names = found["names"]
    loft = found["kind"] == "loft"
    loop = found["loops"][0] if loft else found["curves"]
    curves = [_spline(c["fractions"], c["points"], found.get("linear", False)) for c in loop]
    faces = [c["face"] for c in loop]
    sharp = [not c["smooth"] for c in loop]
    first = found["caps"][0]
    second_blocks = None
    options, lines_extra, fixed = {}, (), True
    holes = found.get("holes", [])
    hole_sharp = [not c["smooth"] for c in holes[0]] if holes else []
    both_smooth = not any(sharp) and not any(hole_sharp) and len(loop) in (1, 2, 4) and len(hole_sharp) in (1, 2, 4)
    both_sharp = all(sharp) and all(hole_sharp) and len(loop) == len(hole_sharp)
    if holes and not (both_smooth or both_sharp):
        raise GeometryError(
            f"{summary}; a sweep whose cap ({names[first]}) has a hole: only a smooth loop of 1, 2 or 4 curves "
            f"around a smooth hole of 1, 2 or 4 curves, or loops of as many sharp corners, are cut into blocks yet: "
            f"{TOPOLOGY_HINT}"
        )
    if loft:  # both caps cut alike: an O-grid each, or midpoint subdivision if both have only corners
        other = found["loops"][1]
        cut = _ogrid_blocks if len(loop) in (1, 2, 4) else _midpoint_blocks
        if cut is _midpoint_blocks and not (all(sharp) and not any(c["smooth"] for c in other)):
            raise GeometryError(
                f"{summary}; a loft whose caps are no O-grid's (1, 2 or 4 curves) nor all corners: {TOPOLOGY_HINT}"
            )
        blocks, sides_of, interfaces = cut(curves, faces)
        second_blocks = cut([_spline(c["fractions"], c["points"], found.get("linear", False)) for c in other], faces)[0]
        how = (
            f"lofted to cap {names[found['caps'][1]]}: both cut alike, "
            + (
                "an O-grid of 5 blocks (core, ring0..ring3)"
                if cut is _ogrid_blocks
                else f"midpoint subdivision into {len(loop)} blocks"
            )
            + ", the block corners on the outlines joined by the linking faces' rulings"
        )
        meaning = "N M A: cells along a quarter of each cap's boundary (and across the core), across the ring, from cap to cap"
        counts = {name: ((1, 0, 2) if name.startswith("ring") else (0, 0, 2)) for name in blocks}
        fixed = False
    elif holes:
        hole = [_spline(c["fractions"], c["points"], found.get("linear", False)) for c in holes[0]]
        blocks, sides_of, interfaces = _annulus_blocks(curves, faces, hole, [c["face"] for c in holes[0]], both_smooth)
        if both_smooth:
            how = "a smooth loop around one smooth hole: a ring of 4 blocks (ring0..ring3) between them"
            meaning = "N M A: cells along a quarter of the cap's boundary, across the ring, along the sweep"
        else:
            how = f"a loop of {len(loop)} sharp corners around a hole of as many: a ring of {len(loop)} blocks, one per side"
            meaning = "N M A: cells along a side of the cap, across the ring, along the sweep"
        counts = {name: (1, 0, 2) for name in blocks}
        fixed = not both_smooth
    elif not any(sharp) and len(loop) in (1, 2, 4):
        blocks, sides_of, interfaces = _ogrid_blocks(curves, faces)
        how = f"a loop of {len(loop)} curve(s) joining smoothly: an O-grid of 5 blocks (core, ring0..ring3) like the pipe's"
        meaning = "N M A: cells along a quarter of the cap's boundary (and across the core), across the ring, along the sweep"
        counts = {"core": (0, 0, 2), **{f"ring{k}": (1, 0, 2) for k in range(4)}}
        fixed = False
    elif len(loop) in (1, 2) and sum(sharp) == 1:
        turn = sharp.index(True)
        loop, curves, faces = loop[turn:] + loop[:turn], curves[turn:] + curves[:turn], faces[turn:] + faces[:turn]
        lengths = [np.linalg.norm(np.diff(c["points"], axis=0), axis=1).sum() for c in loop]
        blocks, sides_of, interfaces = _wedge_blocks(curves, faces, lengths)
        how = (
            f"{len(loop)} curve(s) joining smoothly but at one sharp corner (a trailing edge): one block (te) holds the "
            "corner, the rest a ring of 6 blocks (ring0..ring5) around a core of 2 (core0, core1)"
        )
        meaning = (
            "N M A: cells along a quarter of the cap's boundary (and across the core and te), across the ring, along the sweep"
        )
        counts = {name: ((1, 0, 2) if name.startswith("ring") else (0, 0, 2)) for name in blocks}
        options = {"keep_tfi": True}
        lines_extra = (WEDGE_ELLIPTIC.format(name=who),)
    elif all(sharp):
        blocks, sides_of, interfaces = _midpoint_blocks(curves, faces)
        how = f"{len(loop)} sharp corners: midpoint subdivision into {len(loop)} blocks (quad0..) around its centroid"
        meaning = "N M A: cells along half a side of the cap (and from its centroid to a side), not used, along the sweep"
        counts = {name: (0, 0, 2) for name in blocks}
        fixed = False
    else:
        blocks, sides_of, interfaces, offset = ring_blocks(curves, faces, sharp)
        turns = sum(not s for s in sharp)
        how = (
            f"{len(loop)} curves, {len(loop) - turns} sharp corners and {turns} smooth joint(s): a ring of "
            f"{2 * len(loop)} blocks (a0, b0, ..: two per curve) around a core cut into {len(loop)} (quad0..)"
            + (", the loop offset inwards for the core (an elongated cap or a large fillet)" if offset else "")
        )
        meaning = "N M A: cells along half a curve of the cap (and across the core's blocks), across the ring, along the sweep"
        counts = {name: ((1, 0, 2) if name[0] in "ab" else (0, 0, 2)) for name in blocks}
        if offset:
            options = {"keep_tfi": True}
            lines_extra = (OFFSET_ELLIPTIC.format(name=who),)
    if fixed and not options:  # ring blocks at sharp corners or smooth joints
        options = {"slide_section": False}
        lines_extra = (
            f"{who}: elliptic: the cap's boundary nodes stay where the TFI puts them (nodes sliding along a "
            "flat side pass a corner or a smooth joint of its ring blocks and fold cells)",
        )
    return blocks, second_blocks, sides_of, interfaces, how, meaning, counts, options, lines_extra


def sweep_module(path) -> types.ModuleType:
    """The block-set plugin module of the swept CAD solid in ``path`` (module docstring); kept per
    (path, size, modification time). GeometryError (one line) when the solid is no sweep
    this meshes. A YAML geometry file naming one: ``sweep_yaml.sweep_geometry_module``."""
    path = Path(path)
    key = file_state(path)
    if key not in _MODULES:
        _MODULES[key] = build_sweep_module(path, read_sweep_file(path))
    return _MODULES[key]


def build_sweep_module(path: Path, found: dict, named: dict | None = None) -> types.ModuleType:
    """The module of the sweep ``found`` (``read_sweep_file``'s answer for ``path``). ``named``: a geometry
    file's (``sweep_yaml``): "file" (its path), "where" (how an error names the surface), per
    patch found its name written ("rename") and type ("kinds"), and "caps" (it named them)."""
    named = named or {}
    who, what = (named["file"].name, f"{path.name}: ") if named else (path.name, "")
    summary = f"{named.get('where', path)}: the solid has {found['summary']}"
    if found["kind"] == "six":
        raise GeometryError(f"{summary}: one block, not a sweep")
    if found["kind"] not in ("sweep", "loft"):
        raise GeometryError(f"{summary}; it is no sweep meshgen cuts into blocks ({found['reason']}): {TOPOLOGY_HINT}")
    names, loft = found["names"], found["kind"] == "loft"
    first, second = found["caps"]
    blocks, second_blocks, sides_of, interfaces, how, meaning, counts, options, lines_extra = _cut_cap(who, found, summary)
    folded = _folded(blocks) + (_folded(second_blocks) if loft else [])
    if folded:
        raise GeometryError(
            f"{summary}; its cap {names[first]} ({how}) folds in block(s) {', '.join(folded)} (a concave cap?): {TOPOLOGY_HINT}"
        )
    origin, frame, sides = found["origin"], found["frame"], found.get("sides")
    motion = {"kind": "loft", "gap": found["gap"]} if loft else found["motion"]
    if loft:
        path_words = "a loft: planar, parallel caps, ruled linking faces"
        cap_words = "planar, parallel, each linking face ruled between a curve of each"
    elif motion["kind"] == "translation":
        path_words = f"a straight sweep along ({', '.join(f'{v:.6g}' for v in motion['vector'])})"
        cap_words = "planar, parallel, one shape"
    else:
        path_words = (
            f"a sweep turning by {np.degrees(motion['angle']):.6g} deg about the axis through "
            f"({', '.join(f'{v:.6g}' for v in motion['point'])}) along ({', '.join(f'{v:.6g}' for v in motion['axis'])})"
        )
        cap_words = "planar, one shape turned onto the other"
    if motion["kind"] == "rotation" and not options.get("keep_tfi"):
        options = {"slide": False}
        lines_extra = (
            f"{who}: elliptic: every boundary node stays where the TFI puts it (on a bend, nodes sliding along "
            "the line where two flat faces meet can pass a corner)",
        )
    written = named.get("rename") or {name: name for name in names}
    kinds = named.get("kinds") or {name: default_patch_type(name) for name in names}
    shown = {name: name if written[name] == name else f"{name} as {written[name]}" for name in names}
    patch = {index: (written[name], kinds[name]) for index, name in enumerate(names)}
    block_patches = {}
    for name in blocks:
        block_patches[name] = {face: patch[index] for face, index in sides_of.get(name, {}).items()}
        block_patches[name]["zeta0"], block_patches[name]["zeta1"] = patch[first], patch[second]
    size = float(np.linalg.norm(np.subtract(*found["box"][::-1])))
    stem = re.sub(r"[^A-Za-z0-9_-]", "_", (named["file"] if named else path).stem)[:64].lstrip("_-") or "sweep"
    face, plural, faces = (
        ("patch", "patches", found["patch_words"]) if found.get("linear") else ("face", "faces", "one per CAD face")
    )
    listed = [shown[name] + (f" ({kinds[name]})" if named else "") for name in names]
    lines = (
        f"{who}: {what}{found['summary']}: {path_words}; "
        f"caps {shown[names[first]]} (zeta0) and {shown[names[second]]} (zeta1)"
        + (f", named in {who}" if named.get("caps") else "")
        + f": {cap_words}, every other {face} touches both; "
        f"{'the rulings lie' if loft else 'the outline carried along lies'} on the linking {plural} to "
        f"{motion['gap']:.1e} of the part's size"
        + (f" (their facets' chords within {motion['sag']:.1e} of it)" if "sag" in motion else ""),
        f"{who}: cap {shown[names[first]]}: {how}",
        f"{who}: patches {', '.join(listed)}: {faces} (the linking {plural} on the blocks' outer sides"
        + (", their nodes on the facets" if found.get("linear") else "")
        + ")",
        *lines_extra,
    )

    module = types.ModuleType(f"meshgen_sweep_{stem}")
    module.__file__ = str(named["file"] if named else path)
    module.name, module.dim = stem, 3
    described = f"CAD solid {path.name}: a sweep of its cap {written[names[first]]} ({len(blocks)} blocks)"
    module.description = f"geometry file {who}: {described}" if named else described
    module.params = {}
    module.blocks = tuple(blocks)
    module.dims_meaning = meaning
    module.interfaces = interfaces
    module.block_patches = block_patches
    module.volume = found["volume"]
    module.face_tags = found["face_tags"]
    module.decisions = lines
    module.elliptic_options = options

    def characteristic_length():
        return size

    def block_coords(dims):
        """Per block, uniform node coordinates per axis: the --dims numbers its axes count."""
        axes = [np.linspace(0.0, 1.0, int(n) + 1) for n in dims]
        return {name: [axes[a] for a in counts[name]] for name in blocks}

    def boundary(block, points):
        """(N, 3) points of the unit cube -> (N, 3) points of block ``block``."""
        points = np.asarray(points, dtype=float)
        xy = coons(blocks[block], points[:, 0], points[:, 1])
        if loft:  # along the rulings: the straight lines between the caps' maps
            far = found["origins"][1] + coons(second_blocks[block], points[:, 0], points[:, 1]) @ frame
            return (1.0 - points[:, 2:]) * (origin + xy @ frame) + points[:, 2:] * far
        mapped = moved(motion, origin + xy @ frame, points[:, 2])
        for face_name, index in sides_of.get(block, {}).items() if sides is not None else ():
            face = cube.face_named(face_name, 3)  # an outline face of a triangulated bend: on its facets
            on = points[:, face.axis] == face.side
            if on.any():
                mapped[on] = sides.evaluate(index, xy[on], points[on, 2])
        return mapped

    def notes(block_set):
        return list(lines)

    module.characteristic_length = characteristic_length
    module.block_coords = block_coords
    module.boundary = boundary
    module.notes = notes
    return module
