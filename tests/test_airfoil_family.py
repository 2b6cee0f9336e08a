"""One wall-layer network for a family of sections (``meshgen.neural.wall_family``): the airfoil's
C-grid over a range of thickness, trained with the ``tiny`` preset on a few members (seconds).

Checked against independent computations: the asked first cell from Schlichting's formula
(``first_cell_height``), the wall normal from the wall nodes' own central differences, the cells'
Jacobians at every corner, the parameter derivatives against central differences of the meshes
themselves, and the continuous 4-digit section against the designation's own formula."""

import json

import meshio
import numpy as np
import pytest
from mesh_checks import corner_jacobians

import meshgen
from meshgen.errors import MeshgenError
from meshgen.geometry.airfoil_curve import leading_edge_arc, points_at
from meshgen.geometry.airfoils import naca4_section, naca_section
from meshgen.geometry.blocks import load_block_set
from meshgen.geometry.plugins import plugin_module
from meshgen.geometry.wall_spacing import first_cell_height
from meshgen.neural.checkpoint import load_checkpoint, save_checkpoint
from meshgen.neural.config import resolve_config, set_key
from meshgen.neural.inference import check_model
from meshgen.neural.models import MODELS_DIR
from meshgen.neural.train import train
from meshgen.neural.wall_derivatives import member_derivatives
from meshgen.neural.wall_map import neural_wall_blocks

RANGES = {"thickness": (0.10, 0.14)}
MIDDLE = {"thickness": 0.12}
DIMS = (448, 128)  # the airfoil's train_dims
BUNDLED = MODELS_DIR / "families" / "airfoil" / "checkpoint.pt"


@pytest.fixture(scope="module")
def family_checkpoint(tmp_path_factory):
    """A family over thickness 0.10..0.14 (tiny preset; the corners, the middle and one drawn member)."""
    config = resolve_config("tiny")
    set_key(config, "points.members", 1)
    block_set = load_block_set("airfoil", MIDDLE, DIMS)
    run_dir = tmp_path_factory.mktemp("airfoil-family")
    result = train(config, block_set, run_dir, geometry_spec="airfoil", ranges=RANGES, dims=DIMS)
    return result.checkpoint_path, result.summary


def wall_lines(X):
    """Per interior wall node of the section block: the first cell's height and the angle (degrees)
    of the first grid line off the wall normal (the wall nodes' own central differences)."""
    wall, step = X[:, 0], X[:, 1] - X[:, 0]
    tangent = wall[2:] - wall[:-2]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    height = np.linalg.norm(step, axis=1)
    angle = np.degrees(np.arccos(np.clip((step[1:-1] * normal).sum(1) / height[1:-1], -1.0, 1.0)))
    return height, angle


def test_the_continuous_section_is_the_designations_own():
    for designation, (m, p, t) in {"2412": (0.02, 0.4, 0.12), "0015": (0.0, 0.4, 0.15), "4415": (0.04, 0.4, 0.15)}.items():
        ours, theirs = naca4_section(m, p, t), naca_section(designation, closed_te=True)
        s = np.linspace(0.0, theirs.length, 200)
        assert ours.length == pytest.approx(theirs.length, rel=1e-12)
        np.testing.assert_allclose(points_at(ours, s), points_at(theirs, s), atol=1e-12)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"thickness": 0.5}, "thickness 0.5: a section's thickness must lie in (0, 0.4]"),
        ({"thickness": 0.12, "camber": 0.2}, "camber 0.2: the camber must lie in [0, 0.095]"),
        ({"thickness": 0.12, "camber": 0.02, "camber_position": 0.99}, "camber_position 0.99"),
        ({"camber": 0.02}, "camber and camber_position shape a section of --param thickness=T"),
    ],
)
def test_a_bad_continuous_section_is_one_line(params, message):
    with pytest.raises(
        MeshgenError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]")
    ):
        load_block_set("airfoil", params, DIMS)


def test_a_thin_strongly_cambered_section_turns_its_lines_about_another_point():
    """NACA 6208 is not star-shaped about its mean line's mid-chord point: the directions turn about
    the nearest point of the mean line about which it is, and its elliptic mesh is valid; NACA
    2412's centre stays the mid-chord one."""
    module = plugin_module("airfoil")[0]
    thin = module._setup(module._key({**module.params, "camber": 0.06, "camber_position": 0.2, "thickness": 0.08}))
    usual = module._setup(module._key({**module.params, "camber": 0.02, "camber_position": 0.4, "thickness": 0.12}))
    section, le = usual.section, leading_edge_arc(usual.section)
    mid = 0.5 * (points_at(section, [0.5 * le])[0] + points_at(section, [0.5 * (le + section.length)])[0])
    np.testing.assert_allclose(usual.centre, mid, atol=1e-15)
    assert abs(thin.centre[0] - 0.5) > 0.05
    made = meshgen.mesh(
        "airfoil", (320, 128), method="elliptic", params={"camber": 0.06, "camber_position": 0.2, "thickness": 0.08}
    )
    assert all((corner_jacobians(X) > 0).all() for X in made.blocks)


def test_the_family_checks_its_grid_of_members_and_records_the_ranges(family_checkpoint):
    path, summary = family_checkpoint
    check = summary["family"]
    assert [m["params"]["thickness"] for m in check["members"]] == pytest.approx([0.10, 0.12, 0.14])
    assert check["dims"] == list(DIMS) and check["points"] == 3
    thin = check["members"][0]  # thickness 0.10: its elliptic mesh as meshgen mesh makes it
    made = meshgen.mesh("airfoil", DIMS, method="elliptic", params=thin["params"])
    assert thin["elliptic_mean_min_angle"] == pytest.approx(made.report()["metrics"]["min_angle"]["mean"], abs=1e-9)
    angles = [m["elliptic_mean_min_angle"] for m in check["members"]]
    assert len(set(angles)) == 3  # each member measured against its own elliptic mesh, not one shared
    model = load_checkpoint(path)["model"]
    assert model["family"]["ranges"] == {"thickness": [0.10, 0.14]} and model["family"]["train_dims"] == list(DIMS)
    assert "yplus" in model["family"]["free"] and "farfield" not in model["family"]["free"]
    assert model["state_dict"]["layers.0.weight"].shape[1] == 3  # (2q - 1, 2 tau - 1, thickness)


@pytest.mark.parametrize(
    ("member", "dims", "yplus"),
    [
        ({"thickness": 0.12}, DIMS, 1.0),  # NACA 0012, closed
        ({"thickness": 0.15, "camber": 0.04}, (300, 140), 0.5),  # NACA 4415
        ({"thickness": 0.113, "camber": 0.031, "camber_position": 0.27}, (600, 160), 1.0),
    ],
)
def test_a_member_of_the_bundled_family_has_the_asked_wall_spacing_normal_lines_and_no_inverted_cell(member, dims, yplus):
    """The bundled family meshes members it was not fitted to (``--method neural`` finds it for the
    parameters), at other --dims and y+, without a checkpoint named."""
    made = meshgen.mesh("airfoil", dims, method="neural", params={**member, "yplus": yplus})
    assert made.info["model"]["source"] == "bundled" and "families/airfoil" in made.info["model"]["checkpoint"]
    thickness = member["thickness"]
    asked = first_cell_height(yplus, 6e6).height
    height, angle = wall_lines(made.blocks[made.geometry.names.index("section")])
    assert np.abs(height / asked - 1.0).max() < 0.03
    assert angle.max() < 3.0
    assert all((corner_jacobians(X) > 0).all() for X in made.blocks)
    # the section is the member's: its wall nodes on the continuous 4-digit section
    section = naca4_section(member.get("camber", 0.0), member.get("camber_position", 0.4), thickness)
    wall = made.blocks[1][:, 0]
    s = np.linspace(0.0, section.length, 20001)
    curve = points_at(section, s)
    nearest = np.min(np.linalg.norm(wall[:, None, :] - curve[None, ::1, :], axis=-1), axis=1)
    assert nearest.max() < 2e-4  # within the dense sampling's chord (the nodes lie on the formula itself)


@pytest.mark.parametrize("parameter", ["thickness", "camber", "camber_position"])
def test_the_derivatives_match_central_differences_of_the_meshes(parameter):
    """d nodes / d p of the bundled family (the network's by forward mode, the frame's by
    differences of step 1e-4 of the range) against central differences of the meshes themselves,
    with a step 30 times larger."""
    dims, member = (224, 128), {"thickness": 0.121, "camber": 0.023, "camber_position": 0.37}
    nodes, derivatives = member_derivatives(BUNDLED, member, dims)
    model = load_checkpoint(BUNDLED)["model"]
    step = 3e-3 * np.diff(model["family"]["ranges"][parameter])[0]

    def mesh(change):
        return neural_wall_blocks(load_block_set("airfoil", {**member, parameter: member[parameter] + change}, dims), model)[0]

    for ours, theirs in zip(nodes, mesh(0.0)):
        np.testing.assert_array_equal(ours, theirs)
    differences = [(a - b) / (2 * step) for a, b in zip(mesh(step), mesh(-step))]
    largest = max(np.abs(d).max() for d in differences)
    assert largest > 0.05  # the parameter moves the nodes
    for ours, theirs in zip(derivatives[parameter], differences):
        near = np.linalg.norm(ours - theirs, axis=-1)
        assert np.percentile(near, 99) < 1e-3 * largest
        assert near.max() < 2e-2 * largest


def test_a_member_outside_the_ranges_or_with_another_fixed_parameter_is_one_line_exit_2(run_cli, family_checkpoint, tmp_path):
    path, _ = family_checkpoint
    for params, message in (
        (["thickness=0.15"], "thickness=0.15 is outside the trained range 0.1..0.14"),
        ([], "thickness=0 is outside the trained range"),  # a parameter not given is the geometry's default
        (["thickness=0.12", "farfield=50"], "was trained with farfield=100 fixed (varied: thickness=0.1:0.14"),
        (["thickness=0.12", "naca=2412"], "was trained with naca=12 fixed"),
    ):
        args = [a for p in params for a in ("--param", p)]
        done = run_cli(
            "mesh", "-g", "airfoil", "--method", "neural", "--checkpoint", path, *args, "--dims", "224", "128", "-o", "a.vtu"
        )
        assert done.returncode == 2 and message in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "a.vtu").exists()


def test_the_bundled_family_names_its_ranges_for_a_member_outside_them(run_cli, tmp_path):
    """Without a checkpoint: a member of the bundled family's sections outside its ranges is refused
    with the ranges and a training command that holds it; another section (sharp=1) is not the
    family's business: no trained model for it."""
    for params, message in (
        (["thickness=0.3"], "thickness=0.3 is outside the trained range 0.08..0.18 of the bundled family"),
        (["thickness=0.3"], "--vary thickness=0.08:0.3`) or pick --method elliptic"),
        (["thickness=0.12", "camber=0.05"], "--vary camber=0:0.05 --vary camber_position=0.2:0.6 --vary thickness=0.08:0.18"),
        (["sharp=1"], "no trained model for airfoil with sharp=1"),
    ):
        args = [a for p in params for a in ("--param", p)]
        done = run_cli("mesh", "-g", "airfoil", "--method", "neural", *args, "--dims", "224", "128", "-o", "a.vtu")
        assert done.returncode == 2 and message in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "a.vtu").exists()


def test_yplus_with_a_checkpoint_and_no_geometry_meshes_the_checkpoints_geometry(run_cli, tmp_path):
    """--yplus is checked against the geometry the --checkpoint was trained on (the one the command
    meshes without -g), not the default semicylinder: the smallest edge of the mesh is the asked first cell."""
    done = run_cli("mesh", "--method", "neural", "--checkpoint", str(BUNDLED), "--param", "thickness=0.12",
                   "--yplus", "2", "--dims", "224", "128", "-o", "a.vtu")  # fmt: skip
    assert done.returncode == 0, done.stderr
    mesh = meshio.read(tmp_path / "a.vtu")
    quads = mesh.points[mesh.cells_dict["quad"]][..., :2]
    edges = np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=-1)
    assert edges.min() == pytest.approx(first_cell_height(2.0, 6e6).height, rel=0.03)


def test_a_damaged_family_is_refused(family_checkpoint, tmp_path):
    checkpoint = load_checkpoint(family_checkpoint[0])
    checkpoint["model"]["family"]["ranges"]["thickness"] = [0.14, 0.10]
    with pytest.raises(MeshgenError, match="wall-layer model is damaged"):
        check_model(checkpoint["model"])
    save_checkpoint(tmp_path / "damaged.pt", checkpoint)
    with pytest.raises(MeshgenError, match="wall-layer model is damaged"):
        meshgen.mesh("airfoil", (224, 128), method="neural", params={"thickness": 0.12}, model=str(tmp_path / "damaged.pt"))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "thickness=0:0.1"], "the member thickness=0 is not a valid section (thickness 0 is no section"),
        (["--vary", "yplus=0.5:2"], "every member sets yplus at will"),
        (["--vary", "thikness=0.1:0.2"], "has no parameter 'thikness'"),
        (["--vary", "thickness=0.1:0.2", "--param", "thickness=0.1"], "a parameter is either fixed or varied"),
    ],
)
def test_bad_family_ranges_are_one_line_exit_2_and_leave_no_run(run_cli, tmp_path, args, message):
    done = run_cli("train", "-g", "airfoil", "-p", "tiny", *args, "--out", "run", "-q")
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "run").exists()


def test_points_members_is_refused_where_no_family_of_sections_reads_it(run_cli, tmp_path):
    done = run_cli("train", "-g", "semicylinder", "-p", "tiny", "--set", "points.members=5", "--out", "run", "-q")
    assert done.returncode == 2 and "points.members=5 applies to a family of sections round a wall" in done.stderr
    assert not (tmp_path / "run").exists()


def test_train_a_family_through_the_cli_and_mesh_the_member_it_names(run_cli, tmp_path):
    """The tiny preset (seconds; too small to fit a family without folds): the check names every
    member that folds, and meshing the member the run suggests succeeds or fails in one line as
    the check said of it."""
    done = run_cli(
        "train", "-g", "airfoil", "-p", "tiny", "--vary", "camber=0:0.01", "--param", "thickness=0.12", "--out", "run", "-q",
        "--set", "points.members=0",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Trained airfoil over camber=0:0.01 for 28 steps" in done.stdout
    assert "Checked 3 members (3, the corners included) at 448 x 128" in done.stdout
    check = json.loads((tmp_path / "run" / "summary.json").read_text())["family"]
    for member in check["members"]:
        named = f"FAILED member camber={member['params']['camber']:g}:" in done.stdout
        assert named == (member["inverted"] > 0 or member["gap"] > 1.0)
    hint = next(line for line in done.stdout.splitlines() if line.startswith("Mesh a member with: "))
    assert "--param camber=0.005" in hint
    meshed = run_cli(*hint.removeprefix("Mesh a member with: meshgen ").split())
    folded = next(m for m in check["members"] if m["params"]["camber"] == pytest.approx(0.005))["inverted"] > 0
    if folded:
        assert meshed.returncode == 2 and "cells of the mesh are inverted" in meshed.stderr
        assert len(meshed.stderr.strip().splitlines()) == 1 and not (tmp_path / "mesh.vtu").exists()
    else:
        assert meshed.returncode == 0 and "inverted cells: 0" in meshed.stdout


@pytest.mark.parametrize("closed", [False, True])
def test_the_grid_forward_pass_is_the_plain_one(closed):
    """``forward_grid`` (the first layer split into a q part and a tau part) against ``forward`` on
    ``network_inputs``: the same network, to float32's rounding."""
    from meshgen.neural.wall_map import forward, forward_grid, network_inputs

    rng = np.random.default_rng(3)
    sizes = [3 if closed else 2, 24, 24, 2]
    layers = [
        (rng.standard_normal((b, a)).astype(np.float32), rng.standard_normal(b).astype(np.float32))
        for a, b in zip(sizes, sizes[1:])
    ]
    scales = {"first_height": 1e-6, "distance": 100.0, "closed": closed}
    q, d = np.sort(rng.random(37)), np.concatenate([[0.0], np.geomspace(1e-6, 100.0, 20)])
    plain = forward(layers, network_inputs(q, d, scales)).reshape(len(q), len(d), 2)
    grid = forward_grid(layers, q, d, scales)
    assert grid.shape == plain.shape and grid.dtype == np.float32
    np.testing.assert_allclose(grid, plain, atol=2e-5 * np.abs(plain).max())
