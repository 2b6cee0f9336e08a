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
