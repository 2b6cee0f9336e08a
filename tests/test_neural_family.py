"""One network for a family of shapes (``meshgen train --vary``): the ranges recorded, bad input
refused before training, members meshed with an exact boundary in one forward pass, and the mesh's
derivative in the parameters by autograd against a finite difference of the plugin-based mesh."""

import itertools
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from neural_helpers import TINY

from meshgen.cli import cli
from meshgen.formats import metadata_of
from meshgen.geometry.cube import faces
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.neural.checkpoint import CheckpointError, load_checkpoint
from meshgen.neural.config import resolve_config
from meshgen.neural.family import (
    FamilyMesher,
    family_from_checkpoint,
    make_family,
    mesh_member,
    network_from_model,
    parse_vary,
)
from meshgen.neural.family_train import FAMILY_UNUSED_KEYS, LBFGS_RESAMPLE, covering_members, train_family
from meshgen.neural.model import bubble
from meshgen.neural.models import load_model

# the tiny settings a family uses (it refuses the others)
TINY_ARGS = [arg for item in TINY if item.split("=")[0] not in FAMILY_UNUSED_KEYS for arg in ("--set", item)]
METHODS_PAGE = Path(__file__).resolve().parents[1] / "docs" / "methods.md"


def run_meshgen(capsys, *args):
    """``meshgen ARGS`` in this process: (exit status, stdout, stderr)."""
    with pytest.raises(SystemExit) as stopped:
        cli.main(list(map(str, args)))
    out = capsys.readouterr()
    return stopped.value.code, out.out, out.err


@pytest.fixture(scope="module")
def flower_run(tmp_path_factory):
    """A tiny flower family (twist 0..180, 6 Adam steps) trained through the command line."""
    import meshgen.neural.family_train as family_train

    folder = tmp_path_factory.mktemp("family") / "run"
    with pytest.raises(SystemExit) as stopped, pytest.MonkeyPatch.context() as patch:
        patch.setattr(family_train, "SUMMARY_CELLS", 8)  # the validation's meshes, polished: small to keep the fixture fast
        cli.main(
            [
                "train",
                "-g",
                "flower",
                "--vary",
                "twist=0:180",
                "--param",
                "amplitude=0.25",
                "--set",
                "boundary_layout=fixed",  # the flower's smoothed layout does not converge at twist 180
                *TINY_ARGS,
                "--steps",
                "6",
                "--out",
                str(folder),
                "--quiet",
            ]
        )
    assert stopped.value.code == 0
    return folder


def with_random_correction(checkpoint, seed=0):
    """The checkpoint with a last layer of random weights, so that the network's term is of the
    size of the geometry and depends on the parameters (a tiny run barely leaves N = 0)."""
    generator = torch.Generator().manual_seed(seed)
    model = dict(checkpoint["model"])
    state = dict(model["state_dict"])
    last = max(int(k.split(".")[1]) for k in state)
    state[f"layers.{last}.weight"] = 0.3 * torch.randn(state[f"layers.{last}.weight"].shape, generator=generator)
    state["layers.0.weight"] = state["layers.0.weight"] + torch.randn(state["layers.0.weight"].shape, generator=generator)
    return {**checkpoint, "model": {**model, "state_dict": state}}


def test_the_checkpoint_records_the_ranges_and_the_fixed_parameters(flower_run, capsys):
    checkpoint = load_checkpoint(flower_run / "checkpoint.pt")
    assert checkpoint["family"]["ranges"] == {"twist": [0.0, 180.0]}
    assert checkpoint["geometry"]["params"]["amplitude"] == 0.25
    assert checkpoint["model"]["inputs"] == 4 and checkpoint["model"]["params"] == ["twist"]
    assert checkpoint["stage"] == "done" and checkpoint["step"] == 6 + 2  # Adam, then the tiny L-BFGS stage
    summary = (flower_run / "summary.json").read_text()
    assert '"twist": 180.0' in summary and '"twist": 90.0' in summary  # the range's ends and middle
    # The ordinary model loader (runs/ discovery, compare) says what the file is and how to use it.
    with pytest.raises(CheckpointError, match="holds a family of shapes: mesh a member with"):
        load_model(flower_run / "checkpoint.pt")


def test_a_member_meshes_with_an_exact_boundary_and_the_network_evaluated_directly(flower_run, tmp_path, capsys):
    code, out, err = run_meshgen(
        capsys,
        "mesh",
        "--checkpoint",
        flower_run / "checkpoint.pt",
        "--param",
        "twist=73",
        "--dims",
        6,
        5,
        4,
        "-o",
        tmp_path / "m.vtu",
    )
    assert code == 0, err
    assert metadata_of(tmp_path / "m.vtu")["params"]["twist"] == 73.0
    checkpoint = with_random_correction(load_checkpoint(flower_run / "checkpoint.pt"))
    coords = parametric_grid((6, 5, 4))
    X = mesh_member(checkpoint, {"twist": 73.0}, coords)
    member = load_geometry("flower", {"twist": 73.0, "amplitude": 0.25})
    for face in faces(3):  # the boundary nodes: the plugin's own map at their parametric points
        expected = member.boundary(face.points(coords)).reshape(X[face.node_index].shape)
        assert np.abs(X[face.node_index] - expected).max() < 1e-12, face.name
    # Inside: TFI + S b N(xi, q) with the family network evaluated on (xi, q) itself, not through
    # the folded first-layer bias that meshing uses.
    network = network_from_model(checkpoint["model"]).double()
    nodes = torch.stack(torch.meshgrid(*[torch.from_numpy(c) for c in coords], indexing="ij"), -1).reshape(-1, 3)
    q = torch.full((len(nodes), 1), 2 * 73.0 / 180.0 - 1, dtype=torch.float64)
    with torch.no_grad():
        correction = (bubble(nodes)[:, None] * network(nodes, q)).numpy().reshape(X.shape)
    expected = tfi(member, None, coords) + checkpoint["model"]["scale"] * correction
    assert np.abs(correction).max() > 1e-2  # the network's term is not negligible here
    assert np.abs(X - expected).max() < 1e-5  # float32 inference against float64


def test_a_parameter_outside_the_trained_range_is_a_one_line_error(flower_run, tmp_path, capsys):
    for item, message in [
        ("twist=181", "outside the trained range 0..180"),
        ("amplitude=0.2", "trained with amplitude=0.25 fixed"),
        ("radius=1.5", "trained with radius=1 fixed"),
        ("twirl=3", "has no parameter 'twirl'"),
    ]:
        code, out, err = run_meshgen(
            capsys,
            "mesh",
            "--checkpoint",
            flower_run / "checkpoint.pt",
            "--param",
            item,
            "--dims",
            4,
            4,
            4,
            "-o",
            tmp_path / "m.vtu",
        )
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (item, err)
    assert not (tmp_path / "m.vtu").exists()


def test_the_range_parser_refuses_malformed_empty_and_reversed_ranges():
    assert parse_vary(["twist=0:180", "amplitude=.1:3e-1"]) == {"twist": (0.0, 180.0), "amplitude": (0.1, 0.3)}
    for item, message in [
        ("twist=0-180", "malformed"),
        ("twist=5:5", "empty"),
        ("twist=180:0", "reversed"),
        ("twist", "malformed"),
        ("twist=a:b", "malformed"),
    ]:
        with pytest.raises(Exception, match=message):
            parse_vary([item])


MIDDLE_HOLE_PLUGIN = """
import numpy as np
from meshgen.errors import GeometryError

name = "holed"
dim = 3
description = "unit box, scaled by s; rejects 0.4 < s < 0.6"
params = {"s": 1.0}


def boundary(points, s):
    if 0.4 < s < 0.6:
        raise GeometryError(f"s={s:g} is not allowed between 0.4 and 0.6")
    return s * points
"""


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["-g", "flower", "--vary", "twst=0:180"],
            "has no parameter 'twst' (parameters: radius, amplitude, length, twist); did you mean 'twist'",
        ),
        (["-g", "flower", "--vary", "twist=90:90"], "range is empty"),
        (["-g", "flower", "--vary", "twist=180:0"], "range is reversed"),
        (["-g", "flower", "--vary", "amplitude=0.1:0.4"], "rejects the member amplitude=0.4"),
        (["-g", "flower", "--vary", "amplitude=-0.1:0.2"], "rejects the member amplitude=-0.1"),
        (["-g", "HOLED", "--vary", "s=0.1:1"], "rejects the member s=0.55"),
        (["-g", "flower", "--vary", "twist=0:90", "--param", "twist=10"], "either fixed or varied"),
        (["-g", "flower", "--vary", "twist=0:90", "--preset", "default"], "exact-boundary form"),
    ],
)
def test_bad_vary_is_a_one_line_error_before_training(args, message, tmp_path, capsys):
    plugin = tmp_path / "holed.py"
    plugin.write_text(MIDDLE_HOLE_PLUGIN)
    args = [str(plugin) if a == "HOLED" else a for a in args]
    code, out, err = run_meshgen(capsys, "train", *args, "--out", tmp_path / "run", "--quiet")
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def semicylinder_family(tmp_path_factory):
    """An untrained two-parameter family (no steps), with a random correction term."""
    folder = tmp_path_factory.mktemp("semicylinder-family")
    family = make_family(load_geometry("semicylinder"), "semicylinder", {"radius": (0.5, 2.0), "length": (1.0, 4.0)})
    config = resolve_config(
        "family", None, ["model.widths=[10,10]", "adam.steps=0", "lbfgs.steps=0", "points.interior=64", "boundary_layout=fixed"]
    )
    result = train_family(config, family, folder, summary=False)
    return with_random_correction(result.checkpoint, seed=1)


def test_autograd_derivative_in_each_parameter_matches_a_finite_difference_of_the_meshed_member(semicylinder_family):
    mesher = FamilyMesher(semicylinder_family)
    assert mesher.ranges == {"radius": (0.5, 2.0), "length": (1.0, 4.0)}
    dims = (5, 4, 6)
    weights = torch.randn(6, 5, 7, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    for at in ({"radius": 1.2, "length": 2.5}, {"radius": 2.0, "length": 1.7}):  # inside, and at a range's end
        params = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in at.items()}
        X = mesher.mesh(params, dims)
        objective = (weights * X).sum()
        objective.backward()
        coords = parametric_grid(dims)
        for name, tensor in params.items():
            step = 1e-3 * (mesher.ranges[name][1] - mesher.ranges[name][0])
            ahead, behind = min(at[name] + step, mesher.ranges[name][1]), at[name] - step
            plus = mesh_member(semicylinder_family, {**at, name: ahead}, coords)
            minus = mesh_member(semicylinder_family, {**at, name: behind}, coords)
            difference = float((weights.numpy() * (plus - minus)).sum() / (ahead - behind))
            assert tensor.grad.item() == pytest.approx(difference, rel=2e-3, abs=1e-4), (at, name)
    with pytest.raises(Exception, match="outside the trained range 0.5..2"):
        mesher.mesh({"radius": 2.5}, dims)


def test_the_documented_example_runs(flower_run, tmp_path, monkeypatch):
    text = METHODS_PAGE.read_text()
    block = re.search(r"<!-- family-example -->\s*```python\n(.*?)```", text, re.S).group(1)
    assert 8 <= len(block.strip().splitlines()) <= 16
    shutil.copytree(flower_run, tmp_path / "runs" / "flower-family")
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(block, "docs/methods.md", "exec"), scope)
    twist = scope["twist"].detach()
    assert 0.0 <= float(twist) <= 180.0 and float(twist) != 60.0  # it moved, and stayed in range


def test_family_from_checkpoint_rebuilds_the_ranges(semicylinder_family):
    family = family_from_checkpoint(semicylinder_family)
    assert family.ranges == {"radius": (0.5, 2.0), "length": (1.0, 4.0)}
    assert family.check_values({"radius": 0.5}) == {"radius": 0.5, "length": 2.5}  # unset: the middle


@pytest.mark.parametrize("parameters, interior", [(1, 8), (2, 8), (3, 5)])
def test_the_lbfgs_members_cover_the_corners_the_middle_and_every_slice_of_each_range(parameters, interior):
    q = covering_members(parameters, interior, torch.Generator().manual_seed(parameters)).numpy()
    corners = 2**parameters
    assert q.shape == (corners + 1 + interior, parameters)
    assert {tuple(row) for row in q[:corners]} == set(itertools.product((-1.0, 1.0), repeat=parameters))
    assert np.array_equal(q[corners], np.zeros(parameters))
    stratified = q[corners + 1 :]
    assert np.all((stratified > -1) & (stratified < 1))
    for axis in range(parameters):  # a Latin hypercube: one sample in each of the axis's equal slices
        slices = np.floor((stratified[:, axis] + 1) / 2 * interior).astype(int)
        assert sorted(slices) == list(range(interior)), axis
    again = covering_members(parameters, interior, torch.Generator().manual_seed(parameters + 1)).numpy()
    assert not np.array_equal(again[corners + 1 :], stratified)  # drawn again, not a fixed set


@pytest.mark.parametrize("stop_at, stage", [(4, "adam"), (6 + LBFGS_RESAMPLE + 1, "lbfgs")])
def test_an_interrupted_family_run_resumes_to_the_weights_of_an_uninterrupted_one(tmp_path, stop_at, stage):
    """Interrupted in Adam, or in L-BFGS after its members were drawn again: the same weights."""
    family = make_family(load_geometry("semicylinder"), "semicylinder", {"radius": (0.5, 2.0)})
    lbfgs_steps = LBFGS_RESAMPLE + 3
    config = resolve_config(
        "family",
        None,
        [
            "model.widths=[8,8]",
            "adam.steps=6",
            f"lbfgs.steps={lbfgs_steps}",
            "lbfgs.max_iter=3",
            "points.interior=64",
            "checkpoint.every=100",
            "boundary_layout=fixed",
        ],
    )
    (tmp_path / "whole").mkdir()
    whole = train_family(config, family, tmp_path / "whole", summary=False)
    calls = []

    def stop_after():
        calls.append(1)
        return len(calls) > stop_at

    (tmp_path / "part").mkdir()
    part = train_family(config, family, tmp_path / "part", stop=stop_after, summary=False)
    assert part.interrupted and part.step == stop_at and part.checkpoint["stage"] == stage
    resumed = train_family(
        config, family, tmp_path / "part", resume=load_checkpoint(tmp_path / "part" / "checkpoint.pt"), summary=False
    )
    assert resumed.step == whole.step == 6 + lbfgs_steps
    for key, value in whole.checkpoint["model"]["state_dict"].items():
        assert torch.equal(value, resumed.checkpoint["model"]["state_dict"][key]), key
    rows = (tmp_path / "part" / "history.csv").read_text().splitlines()
    assert [row.split(",")[1] for row in rows[1:]] == [str(i) for i in range(6 + lbfgs_steps)]


def test_the_family_benchmark_measures_each_member_against_the_elliptic_mesh_on_the_trained_layout():
    """A family network trained on the fixed layout meets each member's own boundary map, so its
    reference is the elliptic mesh on that layout, not on the smoothed one (the elliptic default)."""
    import sys

    from meshgen.methods.elliptic import elliptic
    from meshgen.quality import quality_report

    sys.path.insert(0, str(METHODS_PAGE.parents[1] / "benchmarks"))
    import bench_family

    tiny = ["model.widths=[8,8]", "adam.steps=2", "lbfgs.steps=0", "points.interior=64", "boundary_layout=fixed"]
    data = bench_family.measure_case("semicylinder", {"radius": (0.5, 2.0)}, 1, 6, tiny)
    assert data["elliptic_boundary_layout"] == "fixed"
    row = data["members"][0]
    geometry = load_geometry("semicylinder").with_params(**row["params"])
    angles = {
        layout: quality_report(elliptic(geometry, (6, 6, 6), boundary_layout=layout)[0], geometry)["metrics"]["min_angle"]["mean"]
        for layout in ("fixed", "smoothed")
    }
    assert row["elliptic_min_angle_mean"] == pytest.approx(angles["fixed"], abs=1e-9)
    assert abs(angles["smoothed"] - angles["fixed"]) > 0.1  # the two references differ: the test tells them apart


@pytest.mark.parametrize(
    "items, named",
    [
        (["points.boundary=100"], "points.boundary"),
        (["method.point_weights=2", "pretrain.steps=5", "adam.lr=1e-3"], "method.point_weights, pretrain.steps"),
    ],
)
def test_configuration_keys_a_family_cannot_use_are_a_one_line_error(tmp_path, capsys, items, named):
    sets = [arg for item in items for arg in ("--set", item)]
    out = tmp_path / "run"
    code, _, err = run_meshgen(capsys, "train", "-g", "flower", "--vary", "twist=0:180", *sets, "--out", out)
    assert code == 2 and not out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"--set {named}: a family (--vary) cannot use" in lines[0], err
    assert "adam.lr" not in lines[0]  # a key the family uses is not named


def test_a_family_refuses_unused_keys_in_python_and_from_a_configuration_file(tmp_path, flower_run):
    from meshgen.errors import ParameterError
    from meshgen.neural.session import prepare_run

    with pytest.raises(ParameterError, match=r"^overrides test.interior: a family \(--vary\) cannot use it: .*fixed members"):
        prepare_run(geometry="flower", vary=["twist=0:180"], overrides=["test.interior=10"], out=tmp_path / "a")
    changed = tmp_path / "changed.yaml"
    changed.write_text("method:\n  point_weights: 2.0\nadam:\n  lr: 0.01\n")
    with pytest.raises(ParameterError, match=r"^config_file method.point_weights: .*no boundary loss"):
        prepare_run(geometry="flower", vary=["twist=0:180"], config_file=changed, out=tmp_path / "b")
    # a family run's own config.yaml repeats it: every key at the family preset's values passes
    run = prepare_run(geometry="flower", vary=["twist=0:180"], config_file=flower_run / "config.yaml", out=tmp_path / "c")
    assert run.family is not None and run.config.adam.lr == 1e-3


def test_a_non_finite_family_loss_restores_the_last_good_state_and_lowers_the_learning_rate(tmp_path, monkeypatch):
    """The family runs the single shape's loop: its divergence guard too."""
    import math

    import meshgen.neural.family_train as family_train

    real, calls = family_train.family_residual_loss, {"n": 0}

    def sometimes_nan(*args):
        calls["n"] += 1
        loss = real(*args)
        return loss * math.nan if calls["n"] == 3 else loss

    monkeypatch.setattr(family_train, "family_residual_loss", sometimes_nan)
    family = make_family(load_geometry("semicylinder"), "semicylinder", {"radius": (0.5, 2.0)})
    config = resolve_config(
        "family", None, ["model.widths=[8,8]", "adam.steps=5", "lbfgs.steps=0", "points.interior=27", "boundary_layout=fixed"]
    )
    messages = []

    class Messages:
        def stage(self, *args): ...

        def update(self, *args): ...

        def message(self, text):
            messages.append(text)

    result = train_family(config, family, tmp_path, reporter=Messages(), summary=False)
    assert result.step == 5 and result.checkpoint["guard"]["lr_reductions"] == 1
    assert len(messages) == 1 and f"learning rate lowered to {config.adam.lr * config.guard.lr_factor:.3g}" in messages[0]
    lr = [float(line.split(",")[8]) for line in (tmp_path / "history.csv").read_text().splitlines()[1:]]
    assert lr[:2] == [config.adam.lr] * 2 and lr[2:] == [config.adam.lr * config.guard.lr_factor] * 3
