"""Extruded block sets (``meshgen.geometry.extrusion``): which sets are extrusions (closed forms: the
pipe's sweep is (0, 0, L)), the section and the extrusion checked against independent 3D
computations (the 3D TFI, the 3D multi-block elliptic solver), and the section model of a pipe
trained, meshed and refused where it does not fit."""

import textwrap

import numpy as np
import pytest
from neural_helpers import tiny_config

import meshgen
from meshgen.errors import MeshgenError
from meshgen.geometry.block_nodes import face_index
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.extrusion import extrude, extrusion_of, section_of
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.inference import check_start_model, network_blocks, neural_blocks
from meshgen.neural.train import train

TINY_BLOCKS = ("pretrain.steps=20", "pretrain.points=300", "lbfgs.max_iter=10", "adam.steps=20", "model.widths=[16,16]")


def _variant(tmp_path, name: str, body: str) -> str:
    """A plugin file: the pipe with its boundary map changed by ``body`` (``xyz`` the pipe's
    images of ``points``, returned changed)."""
    source = f'''
        import numpy as np
        from meshgen.geometry.plugins import plugin_module

        _pipe, _ = plugin_module("pipe")
        name = "{name}"
        dim = 3
        description = "the pipe, changed"
        params = {{"radius": 0.5, "length": 4.0}}
        dims_meaning = _pipe.dims_meaning
        blocks = _pipe.blocks
        interfaces = _pipe.interfaces
        block_patches = _pipe.block_patches
        block_coords = _pipe.block_coords


        def boundary(block, points, radius, length):
            xyz = _pipe.boundary(block, points, radius, length)
            zeta = points[:, 2]
            {body}
            return xyz
    '''
    path = tmp_path / f"{name}.py"
    path.write_text(textwrap.dedent(source))
    return str(path)


def test_the_pipe_and_the_3d_channel_are_extrusions_along_z():
    pipe = extrusion_of(load_block_set("pipe", {"length": 2.5}, (4, 2, 3)))
    np.testing.assert_allclose(pipe.direction, [0.0, 0.0, 2.5], atol=1e-15)
    np.testing.assert_allclose(pipe.frame, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(pipe.origin, 0.0, atol=1e-15)
    channel = extrusion_of(load_block_set("dfg-cylinder-3d", None, (2, 2, 2)))
    np.testing.assert_allclose(channel.direction, [0.0, 0.0, 0.41], atol=1e-15)
    assert extrusion_of(load_block_set("dfg-cylinder", None, (2, 2))) is None  # 2D


@pytest.mark.parametrize(
    "body, why",
    [
        ("xyz[:, :2] *= (1.0 + 0.2 * zeta)[:, None]", "a cone: the section grows along the axis"),
        (
            "c, s = np.cos(0.3 * zeta), np.sin(0.3 * zeta); xyz[:, 0], xyz[:, 1] = c * xyz[:, 0] - s * xyz[:, 1], s * xyz[:, 0] + c * xyz[:, 1]",
            "twisted",
        ),
        ("xyz[:, 0] += 0.1 * xyz[:, 2]", "sheared: the caps are not square to the sweep"),
        ("xyz[:, 2] += 0.3 * zeta * (1.0 - zeta)", "z not linear in zeta"),
    ],
)
def test_sets_that_are_not_extrusions_are_not_taken_for_one(tmp_path, body, why):
    block_set = load_block_set(_variant(tmp_path, "changed", body), None, (4, 2, 3))
    assert extrusion_of(block_set) is None, why


def test_a_pipe_along_x_gets_a_right_handed_frame(tmp_path):
    spec = _variant(tmp_path, "along_x", "xyz = xyz[:, [2, 0, 1]]")
    extrusion = extrusion_of(load_block_set(spec, None, (4, 2, 3)))
    np.testing.assert_allclose(extrusion.direction, [4.0, 0.0, 0.0], atol=1e-15)
    e1, e2 = extrusion.frame
    np.testing.assert_allclose(np.cross(e1, e2), [1.0, 0.0, 0.0], atol=1e-15)
    block_set = load_block_set(spec, None, (4, 2, 3))
    section = section_of(block_set, extrusion)
    np.testing.assert_allclose(
        np.concatenate(extrude(extrusion, tfi_blocks(section), block_set.coords[0][2])).ravel(),
        np.concatenate(tfi_blocks(block_set)).ravel(),
        atol=1e-14,
    )


def test_the_extruded_section_tfi_is_the_3d_tfi():
    block_set = load_block_set("pipe", None, (6, 3, 4))
    extrusion = extrusion_of(block_set)
    section = section_of(block_set, extrusion)
    assert section.dim == 2 and section.names == block_set.names and len(section.interfaces) == len(block_set.interfaces)
    assert sorted(set(section.patches.values())) == [("wall", "wall")]  # the caps are not the section's
    for made, expected in zip(extrude(extrusion, tfi_blocks(section), block_set.coords[0][2]), tfi_blocks(block_set)):
        np.testing.assert_allclose(made, expected, atol=1e-15)


@pytest.mark.parametrize("name, dims", [("pipe", (8, 4, 3)), ("dfg-cylinder-3d", (4, 2, 3))])
def test_the_3d_elliptic_mesh_is_the_extrusion_of_its_section_mesh(name, dims):
    """The design notes' reason to train the section and to solve an extruded set's elliptic mesh
    as its section's: the 3D multi-block solver, which knows nothing of extrusions, finds the
    extrusion of the 2D solver's section mesh. The channel's
    inlet and outlet edges with its front and back slide along their lines, as the section's
    inlet and outlet nodes slide along theirs."""
    block_set = load_block_set(name, None, dims)
    extrusion = extrusion_of(block_set)
    solid, info3 = elliptic_blocks(block_set, tol=1e-9, as_extrusion=False)
    plane, info2 = elliptic_blocks(section_of(block_set, extrusion), tol=1e-9)
    assert info3["converged"] and info2["converged"]
    for made, expected in zip(extrude(extrusion, plane, block_set.coords[0][2]), solid):
        np.testing.assert_allclose(made, expected, atol=1e-7 * block_set.length)
    shortcut, info = elliptic_blocks(block_set, tol=1e-9)  # the default: solved as the section, extruded
    assert info["extruded"] and info["converged"]
    for made, expected in zip(shortcut, solid):
        np.testing.assert_allclose(made, expected, atol=1e-7 * block_set.length)


@pytest.fixture(scope="module")
def section_model(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("pipe-section")
    result = train(tiny_config(*TINY_BLOCKS), load_block_set("pipe", None, (4, 2, 4)), run_dir, geometry_spec="pipe")
    return result.checkpoint_path, load_checkpoint(result.checkpoint_path)


def test_the_pipe_trains_its_section_and_meshes_an_exact_extrusion(section_model):
    path, checkpoint = section_model
    model = checkpoint["model"]
    assert model["dim"] == 2 and checkpoint["geometry"]["dim"] == 3
    np.testing.assert_allclose(model["extruded"]["direction"], [0.0, 0.0, 4.0])
    for dims in [(4, 2, 3), (6, 3, 7)]:
        block_set = load_block_set("pipe", None, dims)
        Xs, info = neural_blocks(block_set, model)
        assert info["extruded"] and info["interface_gap_before"] > 0
        zeta = block_set.coords[0][2]
        for X in Xs:
            assert X.shape[2] == len(zeta)
            assert np.array_equal(X[..., :2], np.broadcast_to(X[:, :, :1, :2], X[..., :2].shape))  # every layer the same
            np.testing.assert_allclose(X[..., 2], np.broadcast_to(4.0 * zeta, X.shape[:3]), rtol=1e-15, atol=0)
        for interface in block_set.interfaces:
            index_a, index_b = face_index(block_set, interface)
            assert np.array_equal(Xs[interface.a].reshape(-1, 3)[index_a], Xs[interface.b].reshape(-1, 3)[index_b])
        for X in Xs[1:]:
            np.testing.assert_allclose(np.hypot(X[-1, ..., 0], X[-1, ..., 1]), 0.5, rtol=1e-13)  # on the wall
        raw = network_blocks(model, block_set)
        assert all(np.array_equal(R[..., :2], np.broadcast_to(R[:, :, :1, :2], R[..., :2].shape)) for R in raw)
    made = meshgen.mesh("pipe", (4, 2, 3), method="neural", model=str(path))  # the request path
    assert made.info["correction"]["extruded"]
    np.testing.assert_array_equal(
        np.concatenate(made.blocks).ravel(), np.concatenate(neural_blocks(made.geometry, model)[0]).ravel()
    )


def test_a_section_model_is_refused_for_another_extrusion_and_a_3d_model_for_the_section(section_model):
    model = section_model[1]["model"]
    longer = load_block_set("pipe", {"length": 3.0}, (4, 2, 3))
    with pytest.raises(MeshgenError, match="is not that extrusion"):
        neural_blocks(longer, model)
    old = {k: v for k, v in model.items() if k != "extruded"} | {"dim": 3}
    with pytest.raises(MeshgenError, match="holds 3D networks, and 'pipe' is extruded"):
        check_start_model(old, load_block_set("pipe", None, (4, 2, 3)), "--init")
    with pytest.raises(MeshgenError, match="'dfg-cylinder' is not extruded"):
        check_start_model(model, load_block_set("dfg-cylinder", None, (2, 2)), "--resume")


def test_channel_edge_nodes_slide_along_their_line_and_stay_on_both_planes():
    """dfg-cylinder-3d: nodes where the inlet (x = 0) meets the front (z = 0) keep x = 0 and z = 0
    exactly and move along y from where the TFI put them; the corner nodes (three planes) stay."""
    block_set = load_block_set("dfg-cylinder-3d", None, (4, 2, 3))
    start = tfi_blocks(block_set)
    solved, _ = elliptic_blocks(block_set)
    moved = 0.0
    for (block, _face), (patch, _) in block_set.patches.items():
        if patch != "inlet":
            continue
        for X, X0 in ((solved[block][0, :, 0], start[block][0, :, 0]), (solved[block][0, :, -1], start[block][0, :, -1])):
            assert np.all(X[:, 0] == 0.0) and np.all(X[:, 2] == X0[:, 2])  # on the inlet and on the front / back
            moved = max(moved, float(np.abs(X[1:-1, 1] - X0[1:-1, 1]).max()))
    assert moved > 1e-4  # the edge nodes did slide along the edge


def test_a_set_that_is_not_an_extrusion_trains_3d_networks_and_meshes_conforming(tmp_path):
    """The path of 3D networks, kept for sets that are not extrusions: a cone (the pipe's section
    growing along the axis) trains one 3D network per block and meshes with identical interface
    nodes, the wall on the cone and the inlet and outlet in their planes."""
    spec = _variant(tmp_path, "cone", "xyz[:, :2] *= (1.0 + 0.2 * zeta)[:, None]")
    block_set = load_block_set(spec, None, (4, 2, 4))
    run_dir = tmp_path / "run"
    run_dir.mkdir()  # the command line claims the folder; train writes into it
    result = train(tiny_config(*TINY_BLOCKS), block_set, run_dir, summary=False, geometry_spec=spec)
    model = load_checkpoint(result.checkpoint_path)["model"]
    assert model["dim"] == 3 and "extruded" not in model
    block_set = load_block_set(spec, None, (6, 3, 5))
    Xs, info = neural_blocks(block_set, model)
    assert "extruded" not in info
    for interface in block_set.interfaces:
        index_a, index_b = face_index(block_set, interface)
        assert np.array_equal(Xs[interface.a].reshape(-1, 3)[index_a], Xs[interface.b].reshape(-1, 3)[index_b])
    zeta = block_set.coords[1][2]
    for X in Xs[1:]:  # the wall: radius 0.5 (1 + 0.2 zeta) at z = 4 zeta
        radius = np.hypot(X[-1, ..., 0], X[-1, ..., 1])
        np.testing.assert_allclose(radius, np.broadcast_to(0.5 * (1.0 + 0.2 * zeta), radius.shape), rtol=1e-12)
    for X in Xs:
        np.testing.assert_allclose(X[..., 0, 2], 0.0, atol=1e-12)
        np.testing.assert_allclose(X[..., -1, 2], 4.0, rtol=1e-12)
