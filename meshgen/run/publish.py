"""Publishing outputs: every file or folder meshgen writes for the user is first written under a
temporary name that carries the writer's pid and a random token (``temporary_path``: created
with ``O_CREAT | O_EXCL | O_NOFOLLOW``, or ``mkdir`` for a folder, so a link or file planted at a
name meshgen would use is never followed nor written: the name cannot be guessed, and a taken
name is never reused), then takes its real name by a rename. Several
outputs that belong together (a mesh and its ``.quality.json`` sidecar; a case's polyMesh, its
``system`` files and its sidecar) form one *publication*: they take their names together, under
one lock per output, or none of them does (design notes, "Concurrency, faults and reproducible
output").

- ``publishing(output)``: a publication. Writes made inside it through ``meshgen.run.atomic``
  (``atomic_path``) are staged; when the block ends without an error they are renamed into place
  while ``output_lock(output)`` is held, with the previous files kept aside until every rename has
  succeeded (a failure puts them back). An error or a signal in the block removes what was staged
  and any folder the publication made (``make_folder``), never anything another run made.
- ``output_lock(output)``: ``fcntl.flock`` on ``.<name>.lock`` beside the output, so two runs that
  write the same output publish one after the other, each whole. Its name is shared by every run
  (it cannot be random): it is opened with ``O_NOFOLLOW`` and must be a regular file, so a link
  or FIFO planted there is refused in one line, never followed.
- ``remove_stale_temporaries``: temporaries of processes that are gone (killed by SIGKILL, a power
  cut) are removed by the next run that writes there; a previous file that such a process had set
  aside is put back if nothing took its name.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import re
import secrets
import shutil
import signal
import stat
from dataclasses import dataclass, field
from pathlib import Path

from meshgen.errors import MeshgenError

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; publications still rename whole files
    fcntl = None

__all__ = [
    "Publication",
    "current_publication",
    "is_alive",
    "make_folder",
    "make_fresh_folder",
    "open_lock_file",
    "output_lock",
    "publishing",
    "reason",
    "remove_path",
    "remove_stale_temporaries",
    "replace_into",
    "set_aside_path",
    "temporary_path",
    "temporary_token",
]

# Temporaries (".<stem>.tmp-<pid>-<token><suffix>") and files set aside (".<name>.old-<pid>-<token>");
# names without a token are 0.2's, still cleaned up.
TEMPORARY_PATTERN = re.compile(r"^\.(?P<base>.+)\.(?P<kind>tmp|old)-(?P<pid>\d+)(?:-(?P<token>[0-9a-f]+))?(?P<suffix>\.[^.]*)?$")
# Signals held back while files are renamed, so a publication is never left half renamed.
HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM} | ({signal.SIGHUP} if hasattr(signal, "SIGHUP") else set())
# Flags of a new temporary file: created here or not at all, never through a link.
NEW_FILE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
NAME_TRIES = 100  # fresh tokens tried before a folder is said to refuse new names

_current: contextvars.ContextVar = contextvars.ContextVar("meshgen_publication", default=None)


def temporary_token() -> str:
    """The random part of a temporary's name (64 bits from ``secrets``): not guessable from the pid."""
    return secrets.token_hex(8)


def temporary_path(target: str | os.PathLike, folder: bool = False) -> Path:
    """Create and return a new temporary beside ``target``, ``.<stem>.tmp-<pid>-<token><suffix>``:
    an empty file made with ``O_CREAT | O_EXCL | O_NOFOLLOW`` (mode as the umask gives), or with
    ``folder`` an empty folder (``os.mkdir``, which never follows a link). A name that is taken
    (a planted link, a file) is never opened: another token is drawn. The one function that
    names and makes meshgen's temporaries; the caller writes there, then renames it."""
    target = Path(target)
    for _ in range(NAME_TRIES):
        path = target.with_name(f".{target.stem}.tmp-{os.getpid()}-{temporary_token()}{target.suffix}")
        try:
            if folder:
                os.mkdir(path)
            else:
                os.close(os.open(path, NEW_FILE_FLAGS, 0o666))
            return path
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary name beside {target} after {NAME_TRIES} tries")


def set_aside_path(target: str | os.PathLike) -> Path:
    """``.<name>.old-<pid>-<token>`` beside ``target``: where the previous file waits while a new
    one is published (a fresh name: ``os.link`` and ``os.replace`` to it never follow a link)."""
    target = Path(target)
    return target.with_name(f".{target.name}.old-{os.getpid()}-{temporary_token()}")


def is_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this machine (a process of another user counts)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def remove_path(path: Path) -> None:
    """Remove a file, link or folder; what is already gone is fine."""
    with contextlib.suppress(FileNotFoundError):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def remove_stale_temporaries(folder: str | os.PathLike, target: str | os.PathLike | None = None) -> list[Path]:
    """Remove meshgen's temporaries in ``folder`` whose writer (the pid in the name) is gone: those
    of ``target`` only, or every one when ``target`` is None. A previous file set aside by a gone
    writer is put back under its name when nothing took it, else removed. Returns what was removed."""
    folder = Path(folder)
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    target = Path(target) if target is not None else None
    removed = []
    for name in names:
        match = TEMPORARY_PATTERN.match(name)
        if match is None or is_alive(int(match["pid"])):
            continue
        if target is not None:
            own = (
                (match["kind"], match["base"], match["suffix"] or "") == ("tmp", target.stem, target.suffix)
                if match["kind"] == "tmp"
                else (match["base"], match["suffix"]) == (target.name, None)
            )
            if not own:
                continue
        path = folder / name
        with contextlib.suppress(OSError):
            original = folder / match["base"]
            if match["kind"] == "old" and match["suffix"] is None and not path.is_symlink() and not os.path.lexists(original):
                os.replace(path, original)
                continue
            remove_path(path)
            removed.append(path)
    return removed


def replace_into(source: Path, target: Path) -> Path | None:
    """Rename ``source`` to ``target``. A previous ``target`` is kept at ``set_aside_path(target)``
    (a hard link for a file, so ``target`` never goes missing; the folder itself for a folder),
    and that path is returned (None when there was none): the caller removes it, or puts it back."""
    if not os.path.lexists(target):
        os.replace(source, target)
        return None
    aside = set_aside_path(target)
    remove_path(aside)
    if target.is_dir() and not target.is_symlink():
        os.replace(target, aside)
    else:
        try:
            os.link(target, aside, follow_symlinks=False)
        except OSError:  # a file system without hard links
            os.replace(target, aside)
    try:
        os.replace(source, target)
    except BaseException:
        _put_back(aside, target)
        raise
    return aside


def _put_back(aside: Path, target: Path) -> None:
    if target.is_dir() and not target.is_symlink():
        remove_path(target)
    os.replace(aside, target)


@dataclass
class _Staged:
    temporary: Path | None  # None: a removal
    target: Path
    keep_existing: bool = False


@dataclass
class Publication:
    """What one publication has staged (``stage``, ``remove``) and the folders it made (``make_folder``)."""

    output: Path
    staged: list = field(default_factory=list)
    made: list = field(default_factory=list)

    def stage(self, temporary: Path, target: Path, keep_existing: bool = False) -> None:
        """Publish ``temporary`` as ``target`` when the publication ends well (``keep_existing``:
        only where nothing has that name by then)."""
        self.staged.append(_Staged(Path(temporary), Path(target), keep_existing))

    def remove(self, target: Path) -> None:
        """Remove ``target`` (an output of an earlier run that this one replaces by nothing, such as
        a sidecar that no longer describes the mesh) when the publication ends well."""
        self.staged.append(_Staged(None, Path(target)))

    def make_folder(self, folder: Path) -> None:
        """Create ``folder`` if it does not exist; a folder made here is removed again, if empty,
        when the publication fails. A folder another run made is never removed."""
        make_folder(folder, self)

    def discard(self) -> None:
        """Remove what was staged and the (empty) folders this publication made."""
        for item in self.staged:
            if item.temporary is not None:
                with contextlib.suppress(OSError):
                    remove_path(item.temporary)
        for folder in reversed(self.made):
            with contextlib.suppress(OSError):
                folder.rmdir()

    def commit(self) -> None:
        """Rename every staged file into place; on any failure undo the renames done so far."""
        done = []  # (target, what was there before, set aside; None: nothing)
        try:
            for item in self.staged:
                if item.temporary is None:
                    if os.path.lexists(item.target):
                        aside = set_aside_path(item.target)
                        remove_path(aside)
                        os.replace(item.target, aside)
                        done.append((item.target, aside, True))
                    continue
                if item.keep_existing and os.path.lexists(item.target):
                    remove_path(item.temporary)
                    continue
                done.append((item.target, replace_into(item.temporary, item.target), False))
        except BaseException:
            for target, aside, removal in reversed(done):
                with contextlib.suppress(OSError):
                    if removal:
                        os.replace(aside, target)
                    elif aside is None:
                        remove_path(target)
                    else:
                        _put_back(aside, target)
            raise
        for _, aside, _ in done:
            if aside is not None:
                with contextlib.suppress(OSError):
                    remove_path(aside)


def make_folder(folder: Path, publication: Publication | None = None) -> None:
    """``os.mkdir``, recorded in ``publication`` when it made the folder (see ``Publication.make_folder``)."""
    try:
        os.mkdir(folder)
    except FileExistsError:
        if not Path(folder).is_dir():
            raise
        return
    if publication is not None:
        publication.made.append(Path(folder))


def current_publication() -> Publication | None:
    """The publication this code runs in, or None."""
    return _current.get()


def make_fresh_folder(base: str | os.PathLike) -> Path:
    """Create and return ``base``, or ``base-2``, ``base-3`` ... when taken: each name is tried
    with ``os.mkdir``, never checked first, so two runs never share a folder."""
    base = Path(base)
    base.parent.mkdir(parents=True, exist_ok=True)
    for number in range(1, 10000):
        folder = base if number == 1 else base.with_name(f"{base.name}-{number}")
        try:
            os.mkdir(folder)
            return folder
        except FileExistsError:
            continue
    raise MeshgenError(f"no free folder name {base}-N under {base.parent}")


def open_lock_file(lock: Path) -> int:
    """A descriptor of the lock file ``lock`` (created if missing), opened with ``O_NOFOLLOW``: a
    link at its name (or anything but a regular file) is a MeshgenError, never followed."""
    flags = os.O_RDWR | os.O_CREAT | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    refused = f"{lock} (meshgen's lock file) is not a regular file: remove it (meshgen never follows a link there)"
    try:
        descriptor = os.open(lock, flags, 0o644)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENXIO, errno.EISDIR):
            raise MeshgenError(refused) from None
        raise
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        raise MeshgenError(refused)
    return descriptor


@contextlib.contextmanager
def output_lock(output: str | os.PathLike, wait: bool = True):
    """Hold ``fcntl.flock`` on ``.<name>.lock`` beside ``output``: waiting for another run that
    holds it, or (``wait`` False) raising MeshgenError at once. The lock file is removed on
    release; a lock file that was removed while this run waited for it is opened again."""
    output = Path(output)
    if fcntl is None:
        yield
        return
    lock = output.with_name(f".{output.name}.lock")
    while True:
        descriptor = open_lock_file(lock)
        try:
            try:
                fcntl.flock(descriptor, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
            except BlockingIOError:
                raise MeshgenError(f"{output} is in use by another meshgen process: wait for it to end") from None
            try:
                same = os.fstat(descriptor).st_ino == os.stat(lock).st_ino
            except FileNotFoundError:
                same = False
        except BaseException:
            os.close(descriptor)
            raise
        if same:
            break
        os.close(descriptor)
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(descriptor)


@contextlib.contextmanager
def _signals_held():
    """Hold back Ctrl-C, SIGTERM and SIGHUP while files are renamed; they arrive right after."""
    try:
        signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    except (AttributeError, ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, HELD_SIGNALS)


@contextlib.contextmanager
def publishing(output: str | os.PathLike, error=MeshgenError):
    """A publication of ``output`` and what belongs to it (see the module's docstring). Inside
    another publication, it is part of that one. An OSError or RuntimeError (how h5py and torch
    report a full disk) becomes ``error`` (one line, ``could not write <output>: <reason>``)."""
    outer = _current.get()
    if outer is not None:
        yield outer
        return
    publication = Publication(Path(output))
    token = _current.set(publication)
    try:
        try:
            yield publication
        finally:
            _current.reset(token)
        with output_lock(publication.output), _signals_held():
            publication.commit()
    except BaseException as exc:
        publication.discard()
        if isinstance(exc, (OSError, RuntimeError)):
            raise error(f"could not write {output}: {reason(exc)}") from exc
        raise


def reason(exc: BaseException) -> str:
    """The words of an OSError (``No space left on device``) or a library's RuntimeError, on one
    line; HDF5's long reports that carry the system's ``errno = N`` are said as that error."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = " ".join(str(exc).split())
    code = re.search(r"errno = (\d+)", text)
    if code:
        return os.strerror(int(code[1]))
    return text[:300] or type(exc).__name__
