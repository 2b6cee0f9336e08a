"""The smoothed layout of a family (``meshgen.geometry.layout_family``): solved on a grid over the parameter
box and interpolated in between. Checked against layouts solved directly (``compute_layout``) at
the grid's members and between them, against the flower's closed-form surface, and through a tiny
family trained on it."""

import numpy as np
import pytest

from meshgen.errors import GeometryError
from meshgen.geometry.cube import face_samples
from meshgen.geometry.layout import Layout, compute_layout, layout_of, relax_faces, smoothed
from meshgen.geometry.layout_family import FamilyLayout, interpolated_member, solve_family_layout
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import parametric_grid

CELLS = 4  # the layouts' fine grid: coarse, so that each solve takes a fraction of a second
RANGES = {"twist": (0.0, 40.0)}


def flat(layout) -> np.ndarray:
    return np.concatenate([np.ravel(v) for v in [*layout.edge_values.values(), *layout.face_values.values()]])


@pytest.fixture(scope="module")
def flower():
    return load_geometry("flower").with_params(amplitude=0.1)


@pytest.fixture(scope="module")
def family_layout(flower):
    return solve_family_layout(flower, RANGES, points=3, cells=CELLS)


def test_the_interpolated_layout_is_the_solved_one_at_the_grid_members_and_close_between(flower, family_layout):
    for twist in (0.0, 20.0, 40.0):
        solved = layout_of(flower.with_params(twist=twist), CELLS)  # the solve the grid made, remembered
        assert np.array_equal(flat(family_layout.at({"twist": twist})), flat(solved))
    ends = [flat(layout_of(flower.with_params(twist=t), CELLS)) for t in (0.0, 20.0)]
    solved = flat(compute_layout(flower.with_params(twist=10.0), CELLS))
    interpolated = flat(family_layout.at({"twist": 10.0}))
    linear = (ends[0] + ends[1]) / 2  # what a straight line between the two neighbours gives
    assert np.abs(solved - ends[0]).max() > 1e-4  # the layout does change with the twist
    assert np.abs(interpolated - solved).max() < 0.5 * np.abs(linear - solved).max()
    assert np.abs(interpolated - solved).max() < 2e-4  # of the face parameter (0..1)


def test_a_member_on_the_interpolated_layout_stays_on_the_flower_surface(flower, family_layout):
    member = interpolated_member(flower.with_params(twist=13.0), family_layout)
    assert smoothed(member) is member  # already smoothed: meshgen.geometry.layout leaves it as it is
    points = face_samples(3, 9)
    on_side = np.isclose(points[:, 2], 0.0) | np.isclose(points[:, 2], 1.0)
    wall = member.boundary(points[~on_side])
    # the wall is r = R (1 + a cos 5t) about the section's rotated frame: r(t) at the point's own angle
    x, y, z = wall.T
    turn = np.radians(13.0) * z / 2.0
    angle = np.arctan2(y, x) - turn
    assert np.allclose(np.hypot(x, y), 1.0 + 0.1 * np.cos(5 * angle), atol=1e-9)
    assert not np.allclose(wall, flower.with_params(twist=13.0).boundary(points[~on_side]))  # the nodes did move


def test_relaxing_a_members_faces_starts_from_its_interpolated_layout(flower, family_layout, monkeypatch):
    import meshgen.geometry.layout as layout_module

    member = interpolated_member(flower.with_params(twist=30.0), family_layout)

    def no_solve(*args, **kwargs):
        raise AssertionError("relax_faces solved the member's own layout")

    monkeypatch.setattr(layout_module, "layout_of", no_solve)
    coords = parametric_grid((4, 4, 4))
    X = np.zeros((5, 5, 5, 3))
    assert set(relax_faces(member, coords, X)) == {"xi0", "xi1", "eta0", "eta1", "zeta0", "zeta1"}


def test_the_record_round_trips_and_an_unsolvable_member_is_named(family_layout, flower, monkeypatch):
    record = family_layout.record()  # a checkpoint holds the arrays as tensors: tests/test_family_validation.py
    copied = {
        k: [np.array(v) if isinstance(v, np.ndarray) else v for v in value] if isinstance(value, list) else value
        for k, value in record.items()
    }
    again = FamilyLayout.from_record(copied)
    assert np.array_equal(flat(again.at({"twist": 7.0})), flat(family_layout.at({"twist": 7.0})))
    import meshgen.geometry.layout_family as layout_family

    solved = layout_of(flower.with_params(twist=0.0), CELLS)
    stuck = Layout(
        3, solved.edge_values, solved.face_values, {**solved.face_info, "xi1": {"iterations": 200, "final_update": 0.09}}
    )

    def failing(geometry, cells):
        if geometry.values["twist"] == 40.0:
            raise GeometryError("boundary layout: a face's surface grid degenerated (zero-area cell)")
        return stuck if geometry.values["twist"] == 20.0 else solved

    monkeypatch.setattr(layout_family, "layout_of", failing)
    with pytest.raises(
        GeometryError, match=r"^the smoothed layout of the member twist=20 does not converge \(face xi1: update 9.0e-02"
    ):
        solve_family_layout(flower, RANGES, points=3, cells=CELLS)
    with pytest.raises(
        GeometryError, match=r"^the smoothed layout of the member twist=40 cannot be solved \(boundary layout: a face"
    ):
        solve_family_layout(flower, {"twist": (30.0, 40.0)}, points=2, cells=CELLS)
