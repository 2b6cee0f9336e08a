"""One method registry for ``mesh``, ``compare`` and ``meshgen.mesh``; library errors that name
parameters (the command line names flags); the geometry of a neural mesh loaded once."""

import numpy as np
import pytest
from click.testing import CliRunner

from meshgen.cli import cli, message_for_command_line
from meshgen.cli import comparison as comparing
from meshgen.errors import MeshgenError, ParameterError, did_you_mean
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.registry import METHODS, TRAINED, get_method, make_mesh
from meshgen.neural.config import preset_paths


def test_trained_methods_are_registered_neural_methods_with_existing_presets():
    assert set(TRAINED) <= set(METHODS)
    assert set(TRAINED.values()) <= set(preset_paths())
    for name in TRAINED:
        method = get_method(name)
        assert method.function == get_method("neural").function and method.neural and method.preset == TRAINED[name]
    assert comparing.method_names() == list(METHODS)
    assert not get_method("tfi").neural and get_method("tfi").preset is None


def test_compare_neural_row_is_the_mesh_that_meshgen_mesh_makes(tmp_path, run_cli, semidisk):
    from neural_helpers import tiny_config

    from meshgen.formats import read_mesh
    from meshgen.neural.train import train

    run = tmp_path / "run"
    run.mkdir()
    train(tiny_config("adam.steps=3"), semidisk, run, summary=False)
    coords = node_coordinates((9, 5), ["eta:1:1.2"])
    outcome = comparing.compare_methods(
        semidisk,
        (9, 5),
        ["3dmeshnet"],
        clusters=["eta:1:1.2"],
        checkpoints={"3dmeshnet": run / "checkpoint.pt"},
        out_dir=tmp_path / "cmp",
    )
    rows = {row["name"]: row for row in outcome.comparison["rows"]}
    assert "error" not in rows["3dmeshnet"] and rows["3dmeshnet"]["kind"] == "neural"
    made = run_cli(
        "mesh",
        "--method",
        "neural",
        "--checkpoint",
        run / "checkpoint.pt",
        "--dims",
        9,
        5,
        "--cluster",
        "eta:1:1.2",
        "-o",
        "m.vtu",
        "-q",
    )
    assert made.returncode == 0, made.stderr
    by_mesh, by_compare = read_mesh(tmp_path / "m.vtu"), read_mesh(tmp_path / "cmp" / "3dmeshnet.vtu")
    np.testing.assert_array_equal(by_mesh.points, by_compare.points)  # the same mesh, bit for bit
    # ... whose boundary nodes lie on the geometry (meshed unsnapped they would not: the net is tiny).
    X, _ = make_mesh("neural", semidisk, coords, model=run / "checkpoint.pt")
    exact_boundary = semidisk.boundary(np.array([[1.0, t] for t in coords[1]]))
    np.testing.assert_allclose(X[-1, :, :], exact_boundary, atol=1e-12)
    assert rows["3dmeshnet"]["headline"]["boundary_deviation_max"] < 1e-12


def test_mesh_command_names_its_methods_and_refuses_trained_ones(tmp_path):
    runner = CliRunner()
    unknown = runner.invoke(cli, ["mesh", "-m", "elliptc", "--dims", "4", "4", "4", "-o", "m.vtu"])
    assert unknown.exit_code == 2
    assert "unknown method 'elliptc' (methods: auto, tfi, elliptic, neural); did you mean 'elliptic'?" in unknown.stderr
    trained = runner.invoke(cli, ["mesh", "-m", "pinn", "--dims", "4", "4", "-g", "semidisk", "-o", "m.vtu"])
    assert trained.exit_code == 2 and "meshgen train --preset pinn" in trained.stderr
    assert not (tmp_path / "m.vtu").exists()


@pytest.mark.parametrize(
    ("call", "parameter", "library", "command_line"),
    [
        (
            lambda g: make_mesh("elliptic", g, node_coordinates((4, 4)), tol=-1.0),
            "tol",
            "tol must be a positive number, got -1.0",
            "--tol must be a positive number",
        ),
        (
            lambda g: make_mesh("elliptic", g, node_coordinates((4, 4)), max_iter=0),
            "max_iter",
            "max_iter must be a positive integer, got 0",
            "--max-iter must be a positive integer",
        ),
        (
            lambda g: make_mesh("tfi", g, node_coordinates((4, 4)), tol=1e-3),
            "tol",
            "tol does not apply to method 'tfi'",
            "--tol does not apply to method 'tfi'",
        ),
        (
            lambda g: node_coordinates((4, 4), ["zeta:both:1.1"]),
            "cluster",
            "cluster axis zeta does not exist in a 2D mesh",
            "--cluster axis zeta does not exist",
        ),
        (
            lambda g: node_coordinates((4, 4), ["eta:both"]),
            "cluster",
            "malformed cluster 'eta:both'",
            "malformed --cluster 'eta:both'",
        ),
        (
            lambda g: comparing.parse_checkpoints(["pinn"]),
            "checkpoint",
            "malformed checkpoint 'pinn'",
            "malformed --checkpoint 'pinn'",
        ),
        (
            lambda g: comparing.compare_methods(g, (4, 4), ["tfi"], budget=comparing.Budget(overrides=("adam.lr=1",))),
            "overrides",
            "overrides applies to neural methods only",
            "--set applies to neural methods only",
        ),
        (
            lambda g: comparing.compare_methods(g, (4, 4), ["tfi"], method_options={"max_iter": 3}),
            "max_iter",
            "max_iter applies to none of the compared methods",
            "--max-iter applies to none",
        ),
    ],
)
def test_library_errors_name_parameters_and_the_command_line_names_flags(call, parameter, library, command_line, semidisk):
    with pytest.raises(ParameterError) as raised:
        call(semidisk)
    assert raised.value.parameter == parameter
    assert library in str(raised.value) and "--" not in str(raised.value)
    assert command_line in message_for_command_line(raised.value)


def test_the_flags_reach_the_terminal(run_cli):
    result = run_cli("mesh", "-m", "elliptic", "-g", "semidisk", "--dims", 4, 4, "--tol", "-1", "-o", "m.vtu")
    assert result.returncode == 2 and result.stderr.startswith("Error: --tol must be a positive number")


def test_one_exception_type_for_the_axes_check(semidisk):
    from meshgen.methods.elliptic import elliptic
    from meshgen.methods.tfi import tfi

    messages = []
    for method in (tfi, elliptic):
        with pytest.raises(MeshgenError) as raised:
            method(semidisk, (3, 3, 3))
        messages.append(str(raised.value))
    assert messages[0] == messages[1] == "3 axes given for the 2D geometry 'semidisk'"


def test_did_you_mean():
    assert did_you_mean("elliptc", ["tfi", "elliptic"]) == "; did you mean 'elliptic'?"
    assert did_you_mean("zzz", ["tfi", "elliptic"]) == ""


def test_a_neural_mesh_checks_its_geometry_once(monkeypatch):
    import meshgen.geometry.plugins as geometry_module

    checked = []
    original = geometry_module.check_boundary
    monkeypatch.setattr(geometry_module, "check_boundary", lambda g, *a, **k: (checked.append(g.name), original(g, *a, **k))[1])
    for args in (["mesh", "--dims", "3", "3", "3"], ["mesh", "-g", "semicylinder", "--dims", "3", "3", "3"]):
        checked.clear()
        result = CliRunner().invoke(cli, [*args, "-o", "m.vtu", "-q"])
        assert result.exit_code == 0, result.output
        assert checked == ["semicylinder"]


def test_atomic_write_keeps_the_old_file_and_says_why_in_one_line(tmp_path):
    import errno

    from meshgen.errors import FormatError
    from meshgen.run.atomic import atomic_write

    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(FormatError) as raised:
        with atomic_write(target, FormatError) as temporary:
            temporary.write_text("new")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert str(raised.value) == f"could not write {target}: No space left on device"
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]
    with atomic_write(target) as temporary:
        temporary.write_text("new")
    assert target.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]
