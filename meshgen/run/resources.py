"""What the machine has now: memory available to a new allocation, and disk space for a file.

The chunked paths (``meshgen.run.chunked`` for meshing, ``meshgen.quality.chunked`` for evaluating)
are taken when the in-memory path would need more than half of the available memory
(``needs_chunking``).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from meshgen.errors import MeshgenError, ParameterError

__all__ = [
    "IN_MEMORY_BYTES_PER_NODE",
    "MEMINFO",
    "available_memory",
    "blocks_in_flight",
    "check_block_nodes",
    "check_free_space",
    "needs_chunking",
]

IN_MEMORY_BYTES_PER_NODE = 300  # measured: 200^3 in-memory mesh command peaks at about 2.2 GB
MEMINFO = "/proc/meminfo"  # Linux


def available_memory() -> int:
    """Bytes of memory available to a new allocation now (Linux MemAvailable; psutil elsewhere)."""
    linux = _meminfo_available()
    if linux is not None:
        return linux
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except ImportError:  # pragma: no cover - psutil comes with distributed
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def _meminfo_available() -> int | None:
    """MemAvailable of /proc/meminfo in bytes, the figure psutil's ``virtual_memory().available``
    reports on Linux (without importing psutil: 10 ms of a command's start); None where the file
    or the field is missing, or the figure is one psutil corrects (0, or above MemTotal)."""
    try:
        with open(MEMINFO, "rb") as handle:
            fields = dict(line.split()[:2] for line in handle if line.startswith((b"MemTotal:", b"MemAvailable:")))
        total, available = int(fields[b"MemTotal:"]) * 1024, int(fields[b"MemAvailable:"]) * 1024
    except (OSError, KeyError, ValueError):
        return None
    return available if 0 < available <= total else None


def needs_chunking(node_count: int, bytes_per_node: int = IN_MEMORY_BYTES_PER_NODE) -> bool:
    """True when the in-memory path would likely need more than half of the available memory."""
    return node_count * bytes_per_node > available_memory() // 2


def blocks_in_flight() -> int:
    """Blocks held at once by the chunked paths: two per worker thread (one computed, one queued)."""
    return 2 * (os.cpu_count() or 1)


def check_block_nodes(block_nodes: int | None, node_count: int, bytes_per_node: int) -> None:
    """ParameterError when a block size the user set cannot fit: the blocks in flight, each
    ``min(block_nodes, node_count)`` nodes of ``bytes_per_node`` bytes, would need more than the
    memory available now. None (the size chosen from the memory) always fits."""
    if block_nodes is None:
        return
    in_flight = blocks_in_flight()
    needed = in_flight * min(int(block_nodes), int(node_count)) * bytes_per_node
    available = available_memory()
    if needed > available:
        most = available // (in_flight * bytes_per_node)
        raise ParameterError(
            "block_nodes",
            f"{{name}} {block_nodes} needs about {needed / 1e9:.3g} GB for the {in_flight} blocks in flight but "
            f"{available / 1e9:.3g} GB of memory is available; give at most {most} or leave it out",
        )


def check_free_space(path, needed_bytes: int) -> None:
    """MeshgenError when the folder of ``path`` has less free space than ``needed_bytes``."""
    folder = Path(path).parent if str(Path(path).parent) else Path(".")
    free = shutil.disk_usage(folder).free
    if needed_bytes > free:
        raise MeshgenError(
            f"the mesh needs at least {needed_bytes / 1e9:.3g} GB but {folder} has {free / 1e9:.3g} GB free; "
            "pick fewer cells or another output folder"
        )
