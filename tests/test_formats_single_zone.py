"""A single-block mesh made through the request path (``meshgen.mesh`` then ``Mesh.write``) is
written byte for byte as the in-memory writer writes the same node array, computed here by TFI,
with the metadata and patches written out by hand: the request path adds nothing to a one-block
file. (The branch's outputs were also compared with 0.2's for the same request: byte-equal.)"""

from pathlib import Path

import numpy as np
import pytest

import meshgen
from meshgen import __version__
from meshgen.formats import write_mesh
from meshgen.geometry.patches import geometry_patches
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality import cell_metrics

DIMS = (6, 5, 4)


def _files(path: Path) -> dict[str, bytes]:
    if path.is_dir():
        return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}
    return {path.name: path.read_bytes()}


@pytest.fixture(scope="module")
def made():
    return meshgen.mesh("semicylinder", DIMS, method="tfi")


@pytest.mark.parametrize(
    "name, fmt", [("m.vts", None), ("m.cgns", None), ("m.vtu", None), ("m.su2", None), ("m.msh", None), ("case", "openfoam")]
)
@pytest.mark.parametrize("quality", [False, True])
def test_single_zone_write_is_the_in_memory_writers(tmp_path, made, name, fmt, quality):
    geometry = load_geometry("semicylinder")
    X = tfi(geometry, DIMS)
    assert np.array_equal(made.X, X)
    patches = geometry_patches(geometry)
    metadata = {
        "meshgen_version": __version__,
        "method": "tfi",
        "geometry": "semicylinder",
        "params": dict(geometry.values),
        "dims": list(DIMS),
        "method_info": {"boundary_layout": "fixed"},  # the mesh's timing is left out of mesh files
    }
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    made.write(tmp_path / "a" / name, fmt, quality=quality)
    options = {"format": fmt} if fmt else {}
    write_mesh(
        tmp_path / "b" / name, X, cell_data=cell_metrics(X) if quality else None, metadata=metadata, patches=patches, **options
    )
    written, expected = _files(tmp_path / "a" / name), _files(tmp_path / "b" / name)
    assert written.keys() == expected.keys()
    for file in written:
        assert written[file] == expected[file], file
