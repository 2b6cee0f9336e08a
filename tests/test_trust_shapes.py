"""Hostile shape and mesh files through the command line: each is one line on stderr
naming the problem, exit status 2, nothing written, no hang and no stray process. The files are
made here, small: an alias bomb, 5000 nested brackets, a geometry file naming a FIFO, NaN and
infinite STL vertices, a truncated binary STL and one whose triangle count lies, a PLY face
naming a vertex that is not there, a STEP that crashes OpenCASCADE, a .vts whose points stream
inflates 270 000 times, a compressed .cgns claiming 1001^3 nodes over no data."""

import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from shape_helpers import duct_surface, write_ascii_stl

REPO = Path(__file__).resolve().parents[1]

# A STEP whose oriented edge is itself: OpenCASCADE recurses, allocating until it crashes (20 GB
# and counting without a bound on its memory).
SELF_EDGE_STEP = """ISO-10303-21;
HEADER;
FILE_DESCRIPTION((''),'2;1');
FILE_NAME('','',(''),(''),'','','');
FILE_SCHEMA(('AUTOMOTIVE_DESIGN'));
ENDSEC;
DATA;
#1=CARTESIAN_POINT('',(0.,0.,0.));
#2=VERTEX_POINT('',#1);
#4=ORIENTED_EDGE('',*,*,#4,.T.);
#5=EDGE_LOOP('',(#4));
#6=FACE_OUTER_BOUND('',#5,.T.);
#7=DIRECTION('',(0.,0.,1.));
#8=DIRECTION('',(1.,0.,0.));
#9=AXIS2_PLACEMENT_3D('',#1,#7,#8);
#10=PLANE('',#9);
#11=ADVANCED_FACE('',(#6),#10,.T.);
#12=CLOSED_SHELL('',(#11));
#13=MANIFOLD_SOLID_BREP('',#12);
ENDSEC;
END-ISO-10303-21;
"""


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else p.is_dir() for p in sorted(folder.rglob("*"))}


def children(pid: int) -> set[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                found.add(int(entry.name))
    return found


def one_line(result, *fragments) -> str:
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2, result.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr[-2000:]
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def duct_text() -> str:
    vertices, triangles, labels = duct_surface(n_bend=6, n_width=2, n_height=2)
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"duct-{os.getpid()}.stl"
    write_ascii_stl(path, vertices, triangles, labels)
    text = path.read_text()
    path.unlink()
    return text


def binary_stl(triangles: int) -> bytes:
    """A binary STL of ``triangles`` triangles (their corners 0, 1, 2 along x, y, z)."""
    record = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"\0" * 80 + struct.pack("<I", triangles) + record * triangles


def make(row: str, folder: Path, duct_text: str):
    """(the shape file's name, the words its one line must hold) for ``row``."""
    if row == "alias-bomb":
        bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
            f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}] \n" for i in range(9)
        )
        (folder / "g.yaml").write_text(bomb + "surface: d.stl\n")
        return "g.yaml", ("geometry file g.yaml", "anchor or alias at line 1")
    if row == "deep":
        (folder / "g.yaml").write_text("surface: " + "[" * 5000 + "]" * 5000 + "\n")
        return "g.yaml", ("geometry file g.yaml", "nests deeper than 32 levels")
    if row == "large":
        (folder / "g.yaml").write_text("surface: d.stl\n#" + "x" * 2**20 + "\n")
        return "g.yaml", ("geometry file g.yaml", "larger than 1048576 bytes")
    if row == "fifo":
        os.mkfifo(folder / "d.stl")
        (folder / "g.yaml").write_text("surface: d.stl\n")
        return "g.yaml", ("the file d.stl named for 'surface' is a FIFO",)
    if row in ("nan", "inf"):
        at = duct_text.index("vertex ") + len("vertex ")
        (folder / "d.stl").write_text(duct_text[:at] + f"{row} " + duct_text[at:])
        return "d.stl", ("d.stl: solid 1, vertex 1 is not finite", f"({row},")
    if row == "truncated":
        (folder / "d.stl").write_bytes(binary_stl(4)[:-20])
        return "d.stl", ("truncated binary STL", "30 bytes into triangle 4")
    if row == "count":
        data = bytearray(binary_stl(4))
        data[80:84] = struct.pack("<I", 10**9)
        (folder / "d.stl").write_bytes(bytes(data))
        return "d.stl", ("triangle count (1000000000", "disagrees with the file's size", "4 triangles")
    if row == "ply":
        rows = ["ply", "format ascii 1.0", "element vertex 4", "property float x", "property float y", "property float z"]
        rows += ["element face 4", "property list uchar int vertex_indices", "end_header"]
        rows += ["0 0 0", "1 0 0", "0 1 0", "0 0 1", "3 0 2 1", "3 0 1 3", "3 0 3 2", "3 1 2 99999"]
        (folder / "d.ply").write_text("\n".join(rows) + "\n")
        return "d.ply", ("face 4 names vertex 99999", "4 vertices")
    raise AssertionError(row)


ROWS = ["alias-bomb", "deep", "large", "fifo", "nan", "inf", "truncated", "count", "ply"]


@pytest.mark.parametrize("row", ROWS)
def test_a_hostile_shape_file_is_one_line(row, tmp_path, run_cli, duct_text):
    name, words = make(row, tmp_path, duct_text)
    before, kept = snapshot(tmp_path), children(os.getpid())
    command = ["mesh", "-g", name, "--method", "tfi", "--dims", 2, 2, 2, "-o", "m.vtu"]
    if row in ("fifo", "truncated", "ply"):  # the other command that reads shape files
        command = ["geometries", "show", name, "-o", "faces.vtu"]
    one_line(run_cli(*command), *words)
    assert snapshot(tmp_path) == before
    assert children(os.getpid()) <= kept


def test_a_step_that_crashes_the_cad_reader_is_one_line_and_the_next_file_reads(tmp_path, run_cli):
    """OpenCASCADE crashes (its memory bounded) in meshgen's CAD process, not in meshgen: one
    line naming the file and the signal, nothing written, the process reaped; the next CAD file
    gets a fresh CAD process and meshes."""
    pytest.importorskip("gmsh", reason="CAD files need gmsh")
    from shape_helpers import write_twisted_loft

    write_twisted_loft(tmp_path / "loft.step")
    (tmp_path / "bad.step").write_text(SELF_EDGE_STEP)
    before, kept = snapshot(tmp_path), children(os.getpid())
    result = run_cli("mesh", "-g", "bad.step", "--method", "tfi", "--dims", 2, 2, 2, "-o", "m.vtu")
    one_line(result, "bad.step: the CAD reader (gmsh, OpenCASCADE) crashed on it", "signal")
    assert snapshot(tmp_path) == before
    assert children(os.getpid()) <= kept
    result = run_cli("mesh", "-g", "loft.step", "--method", "tfi", "--dims", 3, 3, 3, "-o", "m.vtu", "-q")
    assert result.returncode == 0, result.stderr
    import meshio

    assert meshio.read(tmp_path / "m.vtu").points.shape == (64, 3)


def test_an_obj_naming_a_fifo_as_its_material_library_is_read_without_opening_it(tmp_path, run_cli_process):
    """trimesh reads the OBJ's bytes with a resolver that opens nothing: the FIFO its ``mtllib``
    names is never opened (that would wait for a writer forever) and the surface is read whole."""
    vertices, triangles, _ = duct_surface(n_bend=6, n_width=2, n_height=2)
    text = "mtllib m.mtl\n" + "".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in vertices) + "usemtl a\n"
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in triangles)
    (tmp_path / "t.obj").write_text(text)
    os.mkfifo(tmp_path / "m.mtl")
    result = run_cli_process("geometries", "show", "t.obj", "-o", "faces.vtu", timeout=60)
    assert result.returncode == 0, result.stderr
    import meshio

    shown = meshio.read(tmp_path / "faces.vtu")
    assert len(shown.cells_dict["triangle"]) == len(triangles)
    assert np.allclose(np.sort(shown.points, axis=0), np.sort(vertices, axis=0))


def vts_bomb(path: Path, declared: int, inflated: int = 2**25) -> None:
    """A .vts of one hexahedron (extent 0 1 0 1 0 1: 8 nodes, 192 bytes of points) whose points
    stream inflates to ``inflated`` bytes while its header declares ``declared``."""
    stream = zlib.compress(b"\0" * inflated, 9)
    header = struct.pack("<4Q", 1, declared, declared, len(stream))
    head = (
        '<?xml version="1.0"?>\n<VTKFile type="StructuredGrid" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64" compressor="vtkZLibDataCompressor">\n<StructuredGrid WholeExtent="0 1 0 1 0 1">\n'
        '<Piece Extent="0 1 0 1 0 1">\n<Points>\n<DataArray type="Float64" Name="Points" NumberOfComponents="3" '
        'format="appended" offset="0"/>\n</Points>\n</Piece>\n</StructuredGrid>\n<AppendedData encoding="raw">\n_'
    )
    path.write_bytes(head.encode() + header + stream + b"\n</AppendedData>\n</VTKFile>\n")


@pytest.mark.parametrize("level", [1, 6, 9])
def test_inflate_gives_zlibs_bytes_and_zlibs_refusals(level):
    """``inputs.inflate`` inflates by ISA-L: zlib's bytes; a stream that is no zlib data, or whose
    checksum is wrong, is refused with zlib's own words; the declared size still bounds it."""
    from meshgen.run.inputs import InputError, inflate

    raw = np.cumsum(np.random.default_rng(level).normal(size=50_000)).tobytes()
    stream = zlib.compress(raw, level)
    assert inflate(stream, len(raw), "the block") == raw
    assert inflate(memoryview(stream + b"tail")[: len(stream)], len(raw), "the block") == raw
    corrupt = bytearray(stream)
    corrupt[-1] ^= 1  # the Adler-32 checksum
    for bad, words in ((b"not zlib data at all", "incorrect header check"), (bytes(corrupt), "incorrect data check")):
        with pytest.raises(InputError, match=f"the block is not a zlib stream .*{words}"):
            inflate(bad, len(raw), "the block")
    with pytest.raises(InputError, match="inflates to more than"):
        inflate(stream, len(raw) - 1, "the block")
    with pytest.raises(InputError, match="inflates to 400000 bytes, not the 400001"):
        inflate(stream, len(raw) + 1, "the block")


def claiming_cgns(path: Path, n: int) -> None:
    """A .cgns whose one zone claims n^3 nodes over compressed coordinate arrays with no chunk
    written (HDF5 would read fill values)."""
    h5py = pytest.importorskip("h5py")
    from meshgen.formats._cgns import write

    t = np.linspace(0.0, 1.0, 2)
    write(path, np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1), {}, {})
    with h5py.File(path, "r+") as root:
        zone = root["Base/Zone"]
        sizes = np.array([[n] * 3, [n - 1] * 3, [0] * 3], dtype=zone[" data"].dtype)
        del zone[" data"]
        zone.create_dataset(" data", data=sizes)
        for axis in "XYZ":
            group = zone[f"GridCoordinates/Coordinate{axis}"]
            del group[" data"]
            group.create_dataset(" data", shape=(n, n, n), dtype="f8", chunks=(1, 64, n), compression="gzip")


@pytest.mark.parametrize("row", ["vts-declared", "vts-lying", "cgns"])
def test_a_mesh_file_that_lies_about_its_size_is_refused_before_it_is_inflated(row, tmp_path, run_cli):
    if row == "vts-declared":  # the header says 32 MB: compared with the extent's 192 bytes first
        vts_bomb(tmp_path / "m.vts", 2**25)
        name, words = "m.vts", ("the points array declares 33554432 bytes", "extent implies 192")
    elif row == "vts-lying":  # the header says 192 bytes: the stream is inflated to no more than that
        vts_bomb(tmp_path / "m.vts", 192)
        name, words = "m.vts", ("the points array, block 1 inflates to more than the 192 bytes",)
    else:
        claiming_cgns(tmp_path / "m.cgns", 1001)
        name, words = "m.cgns", ("claims (1001, 1001, 1001) nodes", "stores only 0 compressed bytes")
    assert (tmp_path / name).stat().st_size < 100_000
    before = snapshot(tmp_path)
    started = time.perf_counter()
    one_line(run_cli("evaluate", name), *words)
    assert time.perf_counter() - started < 20  # the cgns header alone ran for minutes
    assert snapshot(tmp_path) == before


def test_sigterm_while_the_cad_process_reads_ends_both(tmp_path):
    """SIGTERM to meshgen while its CAD process works: meshgen exits 143 (not 0), and the CAD
    process is gone. The CAD process is stopped (SIGSTOP) once it exists, so it is still
    working when the signal comes, however fast the machine."""
    pytest.importorskip("gmsh", reason="CAD files need gmsh")
    from shape_helpers import write_twisted_loft

    write_twisted_loft(tmp_path / "loft.step")
    environment = {**os.environ, "PYTHONPATH": str(REPO)}
    command = [sys.executable, "-m", "meshgen", "mesh", "-g", "loft.step", "--method", "tfi", "--dims", "2", "2", "2"]
    process = subprocess.Popen([*command, "-o", "m.vtu"], cwd=tmp_path, env=environment, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        found = set()
        while not found and time.monotonic() < deadline and process.poll() is None:
            found = children(process.pid)
            time.sleep(0.01)
        assert found, "meshgen never started its CAD process"
        (child,) = found
        os.kill(child, signal.SIGSTOP)
        os.kill(process.pid, signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert not (tmp_path / "m.vtu").exists()
    for _ in range(100):
        if not Path(f"/proc/{child}").exists():
            break
        time.sleep(0.05)
    assert not Path(f"/proc/{child}").exists(), "the CAD process outlived meshgen"
