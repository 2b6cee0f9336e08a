"""Write and read time and file size of every mesh format, on the semicylinder by TFI; then the
.vtu writer against meshio's, and the zlib settings it could use.

    python benchmarks/formats.py [--cells 100] [--repeat 3] [--vtu-repeat 5] [--only formats|vtu]
                                 [--json benchmarks/formats.json]

Formats table: times are the best of ``--repeat`` runs (a cell-data array and the metadata
included); "meshio vtu" is meshio's own zlib .vtu of the same mesh, the baseline design notes §9
quotes.

.vtu table: the mesh as ``meshgen mesh`` writes it (the seven quality arrays of
``meshgen.quality`` and the metadata), written by meshio at zlib's default level (meshio's
own writer, without the metadata, which meshio's writer drops) and by ``meshgen.formats._vtu`` at
ISA-L levels 0-3 (``isal.isal_zlib``, the writer's deflate); wall and process CPU time (all threads) of the write, median of
``--vtu-repeat``, file size, and read time by meshio (what ``meshgen evaluate`` uses) and by VTK.
Then the compression alone of the same arrays in 1 MiB blocks on the same thread pool, for the
zlib streams VTK reads: the stdlib's zlib levels and strategies (stored blocks, level 0, as the
no-compression bound) and ISA-L's levels. On a shared machine the CPU time is the steadier figure.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import sys
import tempfile
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.formats import FORMATS, read_mesh, write_mesh  # noqa: E402
from meshgen.geometry.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.tfi import tfi  # noqa: E402


def best_time(function, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def median_times(function, repeat: int) -> tuple[float, float]:
    """(wall, process CPU) seconds of ``function``, each the median of ``repeat`` runs."""
    walls, cpus = [], []
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        function()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=100, help="cells per axis")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--vtu-repeat", type=int, default=5)
    parser.add_argument("--only", choices=["formats", "vtu"], help="run one of the two tables")
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("formats.json"))
    args = parser.parse_args()

    dims = (args.cells,) * 3
    X = tfi(load_geometry("semicylinder"), dims)
    results = {"cells": list(dims), "cpu_count": os.cpu_count()}
    if args.only != "vtu":
        results.update(formats_table(X, args.repeat))
    if args.only != "formats":
        results.update(vtu_table(X, args.vtu_repeat))
    args.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.json}")


def formats_table(X, repeat: int) -> dict:
    dims = tuple(n - 1 for n in X.shape[:-1])
    cell_data = {"quality": np.random.default_rng(0).random(int(np.prod(dims)))}
    metadata = {"method": "tfi", "geometry": "semicylinder", "dims": list(dims)}
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for fmt in FORMATS:
            for extension in fmt.extensions:
                path = Path(folder) / f"mesh{extension}"
                write = best_time(lambda: write_mesh(path, X, cell_data, metadata), repeat)
                read = best_time(lambda: read_mesh(path), repeat)
                rows.append({"format": extension, "write_s": write, "read_s": read, "size_mb": os.path.getsize(path) / 1e6})

        import meshio

        path = Path(folder) / "meshio.vtu"
        mesh = meshio.Mesh(
            flat_points(X), [("hexahedron", cell_connectivity(X.shape[:-1]))], cell_data={"quality": [cell_data["quality"]]}
        )
        write = best_time(lambda: meshio.write(path, mesh, compression="zlib"), repeat)
        read = best_time(lambda: meshio.read(path), repeat)
        rows.append({"format": "meshio vtu", "write_s": write, "read_s": read, "size_mb": os.path.getsize(path) / 1e6})

    print(f"{' x '.join(map(str, dims))} cells, best of {repeat}")
    print(f"{'format':<12}{'write [s]':>10}{'read [s]':>10}{'size [MB]':>11}")
    for row in rows:
        print(f"{row['format']:<12}{row['write_s']:>10.2f}{row['read_s']:>10.2f}{row['size_mb']:>11.1f}")
    print()
    return {"repeat": repeat, "results": rows}


def vtu_table(X, repeat: int) -> dict:
    """The .vtu writers on two meshes with the seven quality arrays; then the codecs alone."""
    # TFI of the semicylinder is very regular (repeated values compress 5x); an elliptic or network
    # mesh varies in every bit: the same nodes moved by 1e-4 (radius 1, cells 0.01-0.03) stand in.
    perturbed = X + 1e-4 * np.random.default_rng(0).standard_normal(X.shape)
    results = {}
    for label, nodes in [("TFI", X), ("TFI, nodes moved by 1e-4", perturbed)]:
        results[label] = vtu_rows(nodes, label, repeat)
    return {"vtu": {"repeat": repeat, "meshes": results}}


def vtu_rows(X, mesh_label: str, repeat: int) -> dict:
    import meshio
    import vtk

    from meshgen.formats import _vtu
    from meshgen.geometry.grid import cell_connectivity
    from meshgen.quality import cell_metrics

    dims = tuple(n - 1 for n in X.shape[:-1])
    cell_data = {name: np.asarray(values, dtype=float).reshape(-1) for name, values in cell_metrics(X).items()}
    metadata = {"method": "tfi", "geometry": "semicylinder", "dims": list(dims)}

    def read_with_vtk(path):
        reader = vtk.vtkXMLUnstructuredGridReader()
        reader.SetFileName(str(path))
        reader.Update()

    cells = [("hexahedron", cell_connectivity(X.shape[:-1]))]
    meshio_mesh = meshio.Mesh(flat_points(X), cells, cell_data={name: [values] for name, values in cell_data.items()})
    writers = [("meshio, level 6 (old)", lambda path: meshio.vtu.write(path, meshio_mesh, binary=True, compression="zlib"))]
    writers += [
        (
            f"meshgen, ISA-L level {level}" + (" *" if level == _vtu.LEVEL else ""),
            lambda path, level=level: _vtu.write(path, X, cell_data, metadata, level=level),
        )
        for level in (0, 1, 2, 3)
    ]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mesh.vtu"
        for label, write in writers:
            wall, cpu = median_times(lambda: write(path), repeat)
            meshio_read, _ = median_times(lambda: meshio.read(path), 3)
            vtk_read, _ = median_times(lambda: read_with_vtk(path), 3)
            size = os.path.getsize(path) / 1e6
            rows.append(
                {
                    "writer": label,
                    "write_s": wall,
                    "write_cpu_s": cpu,
                    "size_mb": size,
                    "meshio_read_s": meshio_read,
                    "vtk_read_s": vtk_read,
                }
            )

    print(
        f".vtu of {mesh_label}, {' x '.join(map(str, dims))} cells with {len(cell_data)} quality arrays: write median of {repeat}, reads median of 3"
    )
    print(f"{'writer':<24}{'write [s]':>10}{'cpu [s]':>9}{'size [MB]':>11}{'meshio read [s]':>17}{'VTK read [s]':>14}")
    for row in rows:
        print(
            f"{row['writer']:<24}{row['write_s']:>10.2f}{row['write_cpu_s']:>9.2f}{row['size_mb']:>11.1f}"
            f"{row['meshio_read_s']:>17.2f}{row['vtk_read_s']:>14.2f}"
        )
    print(f"  * the default (ISA-L level {_vtu.LEVEL})")

    # The codecs alone: the same arrays, the writer's blocks and thread pool.
    arrays = [flat_points(X), cell_connectivity(X.shape[:-1]), *cell_data.values()]
    raw_mb = sum(array.nbytes for array in arrays) / 1e6
    codecs = [(f"zlib level {level}", _zlib_codec(level, zlib.Z_DEFAULT_STRATEGY)) for level in (0, 1, 2, 3, 6)]
    codecs += [("zlib Z_RLE", _zlib_codec(1, zlib.Z_RLE)), ("zlib Huffman only", _zlib_codec(1, zlib.Z_HUFFMAN_ONLY))]
    codecs += [
        (
            f"ISA-L level {level}" + (" (default)" if level == _vtu.LEVEL else ""),
            functools.partial(_vtu.compress_block, level=level),
        )
        for level in range(4)
    ]
    codec_rows = []
    for label, codec in codecs:
        wall, cpu = median_times(lambda: compress_blocks(arrays, codec), repeat)
        size = sum(compress_blocks(arrays, codec)) / 1e6
        codec_rows.append({"codec": label, "seconds": wall, "cpu_s": cpu, "size_mb": size})
    print(f"compression alone of its points, cells and quality arrays ({raw_mb:.1f} MB), median of {repeat}")
    print(f"{'codec':<24}{'time [s]':>10}{'cpu [s]':>9}{'size [MB]':>11}{'ratio':>7}")
    for row in codec_rows:
        print(
            f"{row['codec']:<24}{row['seconds']:>10.2f}{row['cpu_s']:>9.2f}{row['size_mb']:>11.1f}{row['size_mb'] / raw_mb:>7.2f}"
        )
    print()
    return {"cells": int(np.prod(dims)), "writers": rows, "codecs": codec_rows, "uncompressed_mb": raw_mb}


def _zlib_codec(level: int, strategy: int):
    def compress(block) -> bytes:
        compressor = zlib.compressobj(level, zlib.DEFLATED, zlib.MAX_WBITS, 8, strategy)
        return compressor.compress(block) + compressor.flush()

    return compress


def compress_blocks(arrays, codec) -> list[int]:
    """Compressed size of each block of ``arrays`` (the writer's blocks, thread pool and order)."""
    from meshgen.formats import _vtu

    with ThreadPoolExecutor(max_workers=_vtu.cpu_count()) as pool:
        blocks = [_vtu.compress_blocks(pool, np.ascontiguousarray(array), codec) for array in arrays]
        return [len(block.result()) for array_blocks in blocks for block in array_blocks]


if __name__ == "__main__":
    main()
