"""The airfoil's neural mesh (``meshgen.neural.wall_map``): a wall-layer network trained on the
C-grid's marched mesh with the ``tiny`` preset (seconds), meshed at its --dims and at others.

Checked against independent computations: the asked first cell from Schlichting's formula
(``first_cell_height``), the wall normal from the wall nodes' own central differences, the cells'
Jacobians at every corner (``mesh_checks.corner_jacobians``), the wake cut's nodes compared between
the two blocks that hold it, and the elliptic (marched) mesh's mean minimum angle."""

import numpy as np
import pytest
from mesh_checks import corner_jacobians

import meshgen
from meshgen.geometry.blocks import load_block_set
from meshgen.geometry.wall_spacing import first_cell_height
from meshgen.neural.checkpoint import load_checkpoint, save_checkpoint
from meshgen.neural.config import resolve_config
from meshgen.neural.train import train
from meshgen.neural.wall_map import neural_wall_blocks

ASKED = first_cell_height(1.0, 6e6).height  # the airfoil's defaults: y+ 1 at Re 6e6
C_GRID = {"sharp": 1.0}
TRAINED_DIMS = (448, 128)


@pytest.fixture(scope="module")
def c_grid_checkpoint(tmp_path_factory):
    """A wall-layer model of the NACA 0012 C-grid, the tiny preset on the 448 x 128 elliptic mesh."""
    run_dir = tmp_path_factory.mktemp("airfoil-run")
    block_set = load_block_set("airfoil", C_GRID, TRAINED_DIMS)
    result = train(resolve_config("tiny"), block_set, run_dir, summary=False, geometry_spec="airfoil")
    return result.checkpoint_path


TMR = (0.298222773, -0.127125232, -0.357907906, 0.291984971, -0.105174606)  # NASA TMR's NACA 0012, scaled by 0.594689181


def tmr_normals(wall):
    """The outward unit normals (n, 2) of NASA TMR's closed NACA 0012 y = +-f(x) at wall points
    (n, 2), from the closed form f'(x) (the points' side from the sign of y; x <= 0: the nose)."""
    x = np.clip(wall[:, 0], 0.0, 1.0)
    a0, a1, a2, a3, a4 = TMR
    root = np.sqrt(x)
    # sqrt(x) f'(x), finite at the nose: (-sqrt(x) f', sqrt(x)) is along (-f', 1)
    slope_root = 0.594689181 * (0.5 * a0 + root * (a1 + 2 * a2 * x + 3 * a3 * x**2 + 4 * a4 * x**3))
    side = np.where(wall[:, 1] >= 0, 1.0, -1.0)
    normal = np.stack([-slope_root, side * root], axis=1)
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def wall_first_cells(made):
    """Per wall node of the section: the first cell's height (its length) and the angle (degrees)
    of the first grid line off the closed form's normal (``tmr_normals``), the ends (the trailing
    edge, a corner) left out of the angles."""
    X = made.blocks[made.geometry.names.index("section")]
    wall, step = X[:, 0], X[:, 1] - X[:, 0]
    height = np.linalg.norm(step, axis=1)
    angle = np.degrees(np.arccos(np.clip((step * tmr_normals(wall)).sum(1) / height, -1.0, 1.0)))
    return height, angle[1:-1]


@pytest.mark.parametrize("dims", [TRAINED_DIMS, (320, 150), (600, 180)])
def test_neural_c_grid_has_the_asked_wall_spacing_normal_lines_and_no_inverted_cell(c_grid_checkpoint, dims):
    made = meshgen.mesh("airfoil", dims, method="neural", params=C_GRID, model=str(c_grid_checkpoint))
    assert made.method == "neural" and made.blocks[0].dtype == np.float64
    assert sum(np.prod([n - 1 for n in X.shape[:-1]]) for X in made.blocks) == dims[0] * dims[1]
    height, angle = wall_first_cells(made)
    assert np.abs(height / ASKED - 1.0).max() < 0.02
    assert angle.max() < 2.0
    for X in made.blocks:
        assert (corner_jacobians(X) > 0).all()


def test_wake_cut_and_block_ends_coincide(c_grid_checkpoint):
    made = meshgen.mesh("airfoil", (320, 150), method="neural", params=C_GRID, model=str(c_grid_checkpoint))
    lower, section, upper = made.blocks
    np.testing.assert_array_equal(lower[::-1, 0], upper[:, 0])  # the cut: lower.eta0 = upper.eta0
    np.testing.assert_array_equal(lower[-1], section[0])  # the grid lines off the trailing edge
    np.testing.assert_array_equal(section[-1], upper[0])
    assert np.abs(upper[:, 0, 1] - upper[0, 0, 1]).max() < 1e-12  # the cut is straight (alpha 0)
    far = np.concatenate([lower[:, -1], section[:, -1], upper[:, -1]])
    assert np.abs(far[:, 1]).max() == pytest.approx(100.0, rel=1e-4)  # the far field 100 chords off (w + D e: 100.004 at most)


def test_neural_mean_min_angle_is_near_the_elliptic_meshs_and_far_above_tfi(c_grid_checkpoint):
    dims = (320, 150)
    angles = {
        method: meshgen.mesh("airfoil", dims, method=method, params=C_GRID, **options).report()["metrics"]["min_angle"]["mean"]
        for method, options in (("neural", {"model": str(c_grid_checkpoint)}), ("elliptic", {}), ("tfi", {}))
    }
    assert abs(angles["neural"] - angles["elliptic"]) < 2.0  # the tiny preset; the default's figure: the benchmark
    assert angles["elliptic"] - angles["tfi"] > 5.0


def test_the_first_cell_needs_float64_and_gets_it(c_grid_checkpoint):
    """Coordinates of 100 chords in float32 are 8e-6 apart near x = 100 and 6e-8 near the section:
    the first cell of 4.5e-6 would be off by percent. The mesh assembled in float64 is within 1e-3."""
    made = meshgen.mesh("airfoil", (320, 150), method="neural", params=C_GRID, model=str(c_grid_checkpoint))
    height, _ = wall_first_cells(made)
    assert np.abs(height / ASKED - 1.0).max() < 1e-3
    X32 = (made.blocks[1] + 100.0).astype(np.float32).astype(np.float64)  # the section where the wake cut ends, in float32
    rounded = np.linalg.norm(X32[:, 1] - X32[:, 0], axis=1)
    assert np.abs(rounded / ASKED - 1.0).max() > 0.02


def test_o_grid_of_the_blunt_trailing_edge_is_valid_with_the_asked_first_cells(tmp_path):
    """The default NACA 0012 (blunt trailing edge): an O-grid, a ring of three blocks."""
    block_set = load_block_set("airfoil", {}, (224, 120))
    result = train(resolve_config("tiny"), block_set, tmp_path, summary=False, geometry_spec="airfoil")
    model = load_checkpoint(result.checkpoint_path)["model"]
    Xs, _ = neural_wall_blocks(load_block_set("airfoil", {}, (300, 140)), model)
    lower, section, upper = Xs
    np.testing.assert_array_equal(upper[-1], lower[0])  # the ring closes at the base's middle
    for X in Xs:
        height = np.linalg.norm(X[:, 1] - X[:, 0], axis=1)
        assert np.abs(height / ASKED - 1.0).max() < 0.02
        assert (corner_jacobians(X) > 0).all()


def test_a_model_of_another_geometry_is_one_line_exit_2(run_cli, c_grid_checkpoint, tmp_path):
    bundled = meshgen.__file__.replace("__init__.py", "_models/semicylinder/checkpoint.pt")
    done = run_cli("mesh", "-g", "airfoil", "--method", "neural", "--checkpoint", bundled, "--dims", "224", "120", "-o", "a.vtu")
    assert done.returncode == 2 and "trained on 'semicylinder', not on 'airfoil'" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "a.vtu").exists()
    # the C-grid's model for the O-grid (the blunt trailing edge): another block set
    done = run_cli(
        "mesh",
        "-g",
        "airfoil",
        "--param",
        "sharp=0",
        "--method",
        "neural",
        "--checkpoint",
        c_grid_checkpoint,
        "--dims",
        "224",
        "120",
        "-o",
        "b.vtu",
    )
    assert done.returncode == 2 and "was trained with sharp=1, not sharp=0" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_a_damaged_wall_model_is_one_line_exit_2(run_cli, c_grid_checkpoint, tmp_path):
    checkpoint = load_checkpoint(c_grid_checkpoint)
    checkpoint["model"]["tables"][1] = checkpoint["model"]["tables"][1][::-1]  # xi no longer increasing
    save_checkpoint(tmp_path / "damaged.pt", checkpoint)
    done = run_cli("mesh", "--checkpoint", tmp_path / "damaged.pt", "--dims", "224", "120", "-o", "a.vtu")
    assert done.returncode == 2 and "wall-layer model is damaged" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "a.vtu").exists()


def test_train_the_airfoil_through_the_cli(run_cli):
    steps = ("pretrain.steps=1", "adam.steps=2", "lbfgs.steps=1")
    done = run_cli(
        "train", "-g", "airfoil", "-p", "tiny", "--param", "sharp=1", "--out", "run", "-q", *[f"--set={s}" for s in steps]
    )
    assert done.returncode == 0, done.stderr
    assert "Trained airfoil for 4 steps" in done.stdout and "held-out misfit" in done.stdout
    assert "Elliptic (the marched mesh the network learned), 448 x 128 mesh" in done.stdout
