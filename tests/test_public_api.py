"""The README's Python example runs as written, and what it makes is what ``meshgen mesh`` makes,
with quality arrays that agree with VTK's quality filter."""

import re

import numpy as np
from conftest import REPO


def readme_python_example() -> str:
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), re.S)
    return next(block for block in blocks if "meshgen.mesh(" in block)


def test_readme_python_example(tmp_path, run_cli, capsys):
    from test_quality import vtk_quality

    from meshgen.formats import read_mesh

    namespace = {}
    exec(compile(readme_python_example(), "README.md", "exec"), namespace)  # in tmp_path (conftest)
    result = namespace["result"]
    assert result.X.shape == (21, 21, 21, 3)
    printed = capsys.readouterr().out.split()
    assert float(printed[0]) == result.quality["scaled_jacobian"].min() and printed[1] == "True"

    written = read_mesh(tmp_path / "semicylinder-elliptic.vtu")
    cells = written.cells_dict["hexahedron"]
    vtk_sj = vtk_quality(written.points, cells, "SetHexQualityMeasureToScaledJacobian")
    np.testing.assert_allclose(written.cell_data_dict["scaled_jacobian"]["hexahedron"], vtk_sj, atol=1e-10)
    np.testing.assert_allclose(result.quality["scaled_jacobian"], vtk_sj, atol=1e-10)

    # The same request on the command line: the same nodes.
    made = run_cli(
        "mesh", "-m", "elliptic", "-g", "semicylinder", "--dims", 20, 20, 20, "--cluster", "zeta:both:1.1", "-o", "cli.vtu", "-q"
    )
    assert made.returncode == 0, made.stderr
    np.testing.assert_array_equal(read_mesh(tmp_path / "cli.vtu").points, written.points)
    assert (tmp_path / "semicylinder-elliptic.vtu.quality.json").is_file()  # beside it, as the README says


def test_mesh_takes_loaded_geometries_and_params(semidisk):
    import meshgen
    from meshgen.errors import ParameterError

    by_name = meshgen.mesh("semidisk", (6, 4), params={"radius": 2.0})
    by_object = meshgen.mesh(semidisk, (6, 4), params={"radius": 2.0})
    np.testing.assert_array_equal(by_name.X, by_object.X)
    assert np.isclose(np.abs(by_name.X).max(), 2.0)  # the radius-2 half disk
    try:
        meshgen.mesh("semidisk", (6, 0))
    except ParameterError as exc:
        assert exc.parameter == "dims" and str(exc) == "dims must be positive cell counts, got 6 0"
    else:
        raise AssertionError("no error for a zero cell count")


# ---------------------------------------------------------------------------------------------
# the top level: the names a user needs, one return convention

PUBLIC = {
    "__version__",
    "mesh",
    "Mesh",
    "load_geometry",
    "read",
    "write",
    "evaluate",
    "tfi",
    "elliptic",
    "MeshgenError",
    "ParameterError",
    "GeometryError",
}


def test_the_top_level_holds_the_public_names_only_and_stays_cheap():
    import subprocess
    import sys

    import meshgen

    assert set(meshgen.__all__) == PUBLIC
    for removed in ("make_mesh", "write_mesh", "read_mesh", "transfinite", "node_coordinates", "quality_report"):
        assert not hasattr(meshgen, removed), removed  # they live in their modules
    # Importing the modules named like the functions keeps the functions at the top level.
    from meshgen.methods.elliptic import build_elliptic
    from meshgen.methods.tfi import transfinite

    assert callable(transfinite) and callable(build_elliptic)
    assert meshgen.tfi.__module__ == "meshgen.api" and meshgen.elliptic.__module__ == "meshgen.api"
    code = (
        "import sys, meshgen\n"
        "[getattr(meshgen, name) for name in meshgen.__all__]\n"
        "print(sorted(m for m in ('torch', 'dask', 'meshio', 'trimesh', 'matplotlib', 'gmsh') if m in sys.modules))"
    )
    heavy = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert heavy.stdout.strip() == "[]", heavy.stdout + heavy.stderr


def test_mesh_tfi_elliptic_and_read_return_a_mesh_write_and_evaluate_a_report(tmp_path, semidisk):
    from test_quality import vtk_quality

    import meshgen
    from meshgen.geometry.grid import cell_connectivity

    dims = (6, 4)
    made = {"tfi": meshgen.tfi(semidisk, dims), "elliptic": meshgen.elliptic(semidisk, dims, tol=1e-8)}
    made["mesh"] = meshgen.mesh(semidisk, dims, method="tfi")
    for name, mesh in made.items():
        assert isinstance(mesh, meshgen.Mesh) and mesh.X.shape == (7, 5, 2) and mesh.dims == dims, name
    np.testing.assert_array_equal(made["mesh"].X, made["tfi"].X)
    # TFI interpolates the boundary: the xi = 0 and xi = 1 node rows lie on the geometry's map.
    eta = np.linspace(0.0, 1.0, dims[1] + 1)
    for side in (0, 1):
        exact = semidisk.boundary(np.column_stack([np.full_like(eta, side), eta]))
        np.testing.assert_allclose(made["tfi"].X[-side], exact, atol=1e-12)

    report = meshgen.write(tmp_path / "e.vtu", made["elliptic"])
    assert isinstance(report, dict) and (tmp_path / "e.vtu.quality.json").is_file()
    back = meshgen.read(tmp_path / "e.vtu")
    assert isinstance(back, meshgen.Mesh) and back.method == "elliptic" and back.dims == dims
    assert back.geometry.name == "semidisk"
    np.testing.assert_array_equal(back.X, made["elliptic"].X)

    # evaluate: the same report of the Mesh, its node array and its file; VTK's minimum scaled Jacobian.
    points = made["elliptic"].X.reshape(-1, 2)
    cells = cell_connectivity((7, 5))
    vtk_sj = vtk_quality(np.column_stack([points, np.zeros(len(points))]), cells, "SetQuadQualityMeasureToScaledJacobian")
    for subject in (made["elliptic"], made["elliptic"].X, tmp_path / "e.vtu"):
        assert np.isclose(meshgen.evaluate(subject)["metrics"]["scaled_jacobian"]["min"], vtk_sj.min(), atol=1e-10)


def test_python_default_method_is_the_command_lines(run_cli, tmp_path):
    import meshgen
    from meshgen.formats import read_mesh

    # semicylinder has a bundled model: both mesh with it.
    by_python = meshgen.mesh("semicylinder", (4, 4, 4))
    assert by_python.method == "neural" and by_python.notes[0].startswith("model: ") and "bundled" in by_python.notes[0]
    made = run_cli("mesh", "--dims", 4, 4, 4, "-o", "m.vtu", "-q")
    assert made.returncode == 0, made.stderr
    np.testing.assert_array_equal(read_mesh(tmp_path / "m.vtu").points, by_python.X.reshape(-1, 3))
    # semidisk has none: both fall back to elliptic, the library with a note instead of a print.
    fallback = meshgen.mesh("semidisk", (6, 4))
    assert fallback.method == "elliptic" and fallback.notes == (
        "note: no trained model for 'semidisk': meshing with elliptic (meshgen train -g semidisk trains one)",
    )
    np.testing.assert_array_equal(fallback.X, meshgen.elliptic("semidisk", (6, 4)).X)
