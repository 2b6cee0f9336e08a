"""CAD files read in a process of their own: a malformed STEP can crash OpenCASCADE (signal 11 on
a 455-byte file whose edge refers to itself) or make it allocate without end, and neither may take
meshgen with it.

``cad_block`` forks (``os.fork``, once per meshgen process, on the first CAD file) a child that
imports gmsh and serves requests over a pipe: read a file into a block (``cad.read_cad_block``),
and evaluate its boundary map (or one edge or face map) at an array of points. Only plain values cross the pipe
(names, face assignment, corner points, volume, box; (N,) or (N, 2) arrays in, (N, 3) arrays
out), so the parent's ``BoundaryPieces`` evaluates the true CAD surfaces as before, one round trip
per call of the boundary map (a call maps a whole array of boundary points).

The child ignores Ctrl-C and keeps the default action of SIGTERM (the parent handles both and
kills it), dies with the parent (``PR_SET_PDEATHSIG``; and its pipe closes), cannot use more
address space than it had plus, while it reads a file, ``limits.cad_read_bytes`` (``RLIMIT_AS``:
an endless allocation fails in the child within a second instead of filling the machine), and
has ``faulthandler`` off (a crash prints nothing). When it dies, the request that was in flight is one ``GeometryError``
naming the file and the signal; the next request starts a fresh child, which reads a file it
does not know again (each request carries the file's reading arguments).
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry import cube
from meshgen.geometry.shapes.cad import closest_on_face, read_cad_block
from meshgen.geometry.shapes.faces import BoundaryPieces
from meshgen.geometry.shapes.sweep_read import read_sweep
from meshgen.run.limits import cad_read_bytes
from meshgen.run.resources import available_memory
from meshgen.run.signals import TERMINATING_SIGNALS

__all__ = ["ContainedCadBlock", "cad_block", "cad_face_projection", "cad_sweep", "close_cad_process"]

PARENT_CHECK_SECONDS = 0.5  # how often a waiting parent checks that the child lives


class ContainedCadBlock:
    """A CAD solid read in the CAD process (``cad.CadBlock``'s values, copied): ``names`` per face,
    ``assignment`` cube face -> face index, ``pieces`` the boundary map (its edge and face maps
    evaluated in the CAD process), ``volume`` (OCC's), ``face_tags`` gmsh's surface tags."""

    def __init__(self, names, assignment, pieces, volume, face_tags, box):
        self.names, self.assignment, self.pieces = names, assignment, pieces
        self.volume, self.face_tags, self._box = volume, face_tags, box

    def extent(self):
        return self._box


def cad_block(path, given_faces: dict | None = None, content_hash: str = "", given_corners=None) -> ContainedCadBlock:
    """Read a CAD file and assign its six faces to the cube's (``cad.read_cad_block``), in the CAD
    process; GeometryError for anything wrong with the file, its crash included."""
    path = Path(path)
    corners = None if given_corners is None else np.asarray(given_corners, dtype=float)
    load = (os.getcwd(), str(path), given_faces, content_hash, corners)  # the child reads in this folder
    found = _request(path, ("block", load, None, None))
    names, assignment, corners, reflect, volume, face_tags, box = found
    edges = {edge.name: _remote_map(path, load, "edge", edge.name) for edge in cube.edges()}
    faces = {name: _remote_map(path, load, "face", name) for name in assignment}
    pieces = _RemotePieces(faces, edges, corners, reflect_eta=reflect, content_hash=content_hash, what=str(path))
    pieces.load = load
    return ContainedCadBlock(names, assignment, pieces, volume, face_tags, box)


def cad_sweep(path, content_hash: str = "", caps=None) -> dict:
    """The CAD file's solid seen as a straight sweep (``sweep_read.read_sweep``: plain values), read
    in the CAD process; ``caps``: the two face names to try as its caps (strings), else every pair;
    GeometryError for anything wrong with the file, its crash included."""
    path = Path(path)
    caps = None if caps is None else tuple(str(name) for name in caps)
    return _request(path, ("sweep", (os.getcwd(), str(path), caps, content_hash, None), None, None))


def cad_face_projection(path, face: int):
    """The map points (N, 3) -> their closest points on face ``face`` of the CAD file ``path``
    (``cad.closest_on_face``, in the CAD process: one round trip per call); the file and the face
    are checked now (GeometryError)."""
    path = Path(path)
    load = (os.getcwd(), str(path), int(face), "", None)

    def project(points):
        return _request(path, ("closest", load, None, np.ascontiguousarray(points, dtype=float).reshape(-1, 3)))

    project(np.zeros((0, 3)))
    return project


class _RemotePieces(BoundaryPieces):
    """The CAD block's boundary map: a call maps all its points in the CAD process in one round
    trip (that process's own ``BoundaryPieces``, ``reflect_eta`` included); ``faces`` and
    ``edges`` map one piece each there."""

    load = None

    def __call__(self, points, **_values):
        return _request(Path(self.what), ("pieces", self.load, None, np.ascontiguousarray(points, dtype=float)))


def _remote_map(path: Path, load, kind: str, name: str):
    def evaluate(points):
        return _request(path, (kind, load, name, np.ascontiguousarray(points, dtype=float)))

    return evaluate


# --- the parent's end --------------------------------------------------------------------------

_SERVER: dict = {}  # pid -> _Child: a forked meshgen process starts its own


class _Child:
    """A forked process (``os.fork``: a daemonic multiprocessing worker, such as the quality
    worker, may not start multiprocessing children) and this process's end of its pipe."""

    def __init__(self):
        from multiprocessing import Pipe

        self.connection, child_end = Pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        self.pid = os.fork()
        if self.pid == 0:  # the child: never returns
            try:
                _serve(child_end, self.connection)
            finally:
                os._exit(1)
        child_end.close()
        self.status = None

    def alive(self) -> bool:
        if self.status is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.status = status
        return self.status is None

    def end(self, wait: float = 0.0) -> None:
        """Wait up to ``wait`` seconds for the child to end by itself, then kill it; reap it."""
        deadline = time.monotonic() + wait
        while self.alive() and time.monotonic() < deadline:
            time.sleep(0.01)
        if self.alive():
            os.kill(self.pid, signal.SIGKILL)
            self.status = os.waitpid(self.pid, 0)[1]
        self.connection.close()

    def how_it_ended(self) -> str:
        if self.status is not None and os.WIFSIGNALED(self.status):
            number = os.WTERMSIG(self.status)
            try:
                return f"signal {number}, {signal.Signals(number).name}"
            except ValueError:
                return f"signal {number}"
        return f"exit status {os.WEXITSTATUS(self.status) if self.status is not None else 'unknown'}"


def _server(path: Path) -> _Child:
    child = _SERVER.get(os.getpid())
    if child is not None and child.alive():
        return child
    if "numba" in sys.modules and threading.current_thread() is not threading.main_thread():
        # Forking from a thread of a process whose numba (TBB) threads run is unsafe: the forked
        # quality worker evaluating the deviation lands here, fails, and its parent computes the
        # report itself with its own CAD process.
        raise GeometryError(f"{path}: the CAD process is not started from a thread of a process running numba")
    close_cad_process()
    _SERVER.clear()  # one inherited from the parent is not ours to use
    child = _SERVER[os.getpid()] = _Child()
    return child


def close_cad_process() -> None:
    """End this process's CAD process, if it started one."""
    child = _SERVER.pop(os.getpid(), None)
    if child is not None:
        child.end()


atexit.register(close_cad_process)


def _request(path: Path, message):
    """The CAD process's answer to ``message``; GeometryError when it reports one or dies. Any
    interruption (Ctrl-C, SIGTERM) while it works ends it before passing on."""
    child = _server(path)
    connection = child.connection
    try:
        connection.send(message)
        while not connection.poll(PARENT_CHECK_SECONDS):
            if not child.alive():
                break
        kind, value = connection.recv()
    except (EOFError, OSError):
        _SERVER.pop(os.getpid(), None)
        child.end(wait=5.0)
        raise GeometryError(
            f"{path}: the CAD reader (gmsh, OpenCASCADE) crashed on it ({child.how_it_ended()}): "
            "a malformed or unsupported CAD file"
        ) from None
    except BaseException:
        close_cad_process()  # interrupted mid-request: the child's answer would be out of step
        raise
    if kind == "error":
        raise GeometryError(value)
    return value


# --- the child ---------------------------------------------------------------------------------


def _contain() -> None:
    """The child's own limits: default SIGTERM, no Ctrl-C, death with the parent, no faulthandler
    output, address space bounded by what it has plus the memory available now."""
    import faulthandler

    faulthandler.disable()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in TERMINATING_SIGNALS:
        signal.signal(signum, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    _limit_memory(int(available_memory()))


def _limit_memory(allowed: int) -> None:
    """Bound this process's address space to what it maps now plus ``allowed`` bytes (Linux)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import resource

        with open("/proc/self/statm") as statm:
            used = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (used + allowed, resource.getrlimit(resource.RLIMIT_AS)[1]))
    except (OSError, ValueError, ImportError):
        pass


def _serve(connection, parent_end) -> None:
    """The child: answer ("ok", value) or ("error", one-line message) to each request until the
    pipe closes, then exit without the parent's cleanup."""
    parent_end.close()
    _contain()
    blocks = {}
    status = 0
    try:
        while True:
            kind, load, name, points = connection.recv()
            try:
                block = blocks.get(_key(load)) if kind not in ("sweep", "closest") else None
                if kind == "closest":
                    folder, path, face, _, _ = load
                    os.chdir(folder)
                    _limit_memory(cad_read_bytes(os.stat(path).st_size))
                    try:
                        answer = ("ok", closest_on_face(path, face, points))
                    finally:
                        _limit_memory(int(available_memory()))
                    connection.send(answer)
                    continue
                if kind == "sweep":
                    folder, path, caps, content_hash, _ = load
                    os.chdir(folder)
                    _limit_memory(cad_read_bytes(os.stat(path).st_size))
                    try:
                        answer = ("ok", read_sweep(path, content_hash, caps))
                    finally:
                        _limit_memory(int(available_memory()))
                    connection.send(answer)
                    continue
                if block is None:
                    folder, path, faces, content_hash, corners = load
                    os.chdir(folder)  # the parent's working folder now, for a relative path
                    _limit_memory(cad_read_bytes(os.stat(path).st_size))  # OCC may allocate without end
                    try:
                        block = blocks[_key(load)] = read_cad_block(path, faces, content_hash, corners)
                    finally:
                        _limit_memory(int(available_memory()))
                if kind == "block":
                    pieces = block.pieces
                    value = (
                        tuple(block.names),
                        dict(block.assignment),
                        {ijk: np.asarray(point, dtype=float) for ijk, point in pieces.corners.items()},
                        bool(pieces.reflect_eta),
                        float(block.volume),
                        tuple(int(tag) for tag in block.face_tags),
                        tuple(np.asarray(corner, dtype=float) for corner in block.extent()),
                    )
                elif kind == "pieces":
                    value = np.asarray(block.pieces(points), dtype=float)
                else:
                    maps = block.pieces.edges if kind == "edge" else block.pieces.faces
                    value = np.asarray(maps[name](points), dtype=float)
                answer = ("ok", value)
            except MeshgenError as error:
                answer = ("error", str(error))
            except Exception as error:  # noqa: BLE001 - gmsh raises bare Exceptions; one line for the parent
                text = " ".join(str(error).split()) or type(error).__name__
                answer = ("error", f"{load[1]}: the CAD reader failed: {text}")
            connection.send(answer)
    except (EOFError, OSError, KeyboardInterrupt):  # the parent is gone, or closed the pipe
        status = 1
    finally:
        sys.stdout.flush()
        os._exit(status)


def _key(load) -> tuple:
    folder, path, faces, content_hash, corners = load
    return (
        os.path.join(folder, path),
        content_hash,
        repr(sorted((faces or {}).items())),
        None if corners is None else corners.tobytes(),
    )
