"""Run a command as a person at a terminal sees it: in a pseudo-terminal of a given width, with
what the screen ends up showing (carriage returns and rich's cursor moves applied, colours gone)."""

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time

from conftest import REPO

_COLOUR = re.compile(r"\x1b\[[0-9;]*m")
_CURSOR = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")  # moves, erases: a line ends


def run_in_terminal(args, columns: int, cwd, timeout: float = 300, env=None):
    """Run ``python -m meshgen ARGS`` with stdout and stderr on a ``columns``-wide pseudo-terminal.
    Returns (exit status, the raw output, the output's screen lines after control codes are
    removed and each line split at carriage returns: every state the line was drawn in)."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 50, columns, 0, 0))
    environment = {**os.environ, "PYTHONPATH": str(REPO), "TERM": "xterm", **(env or {})}
    for name in ("COLUMNS", "LINES", "MESHGEN_DEBUG"):
        environment.pop(name, None)
    process = subprocess.Popen(
        [sys.executable, "-m", "meshgen", *map(str, args)],
        cwd=cwd,
        env=environment,
        stdin=subprocess.DEVNULL,
        stdout=follower,
        stderr=follower,
        close_fds=True,
    )
    os.close(follower)
    chunks, deadline = [], time.time() + timeout
    while time.time() < deadline:
        ready, _, _ = select.select([leader], [], [], 0.5)
        if ready:
            try:
                data = os.read(leader, 65536)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif process.poll() is not None:
            break
    os.close(leader)
    status = process.wait(timeout=30)
    raw = b"".join(chunks).decode("utf-8", "replace")
    lines = [part for line in _CURSOR.sub("\n", _COLOUR.sub("", raw)).split("\n") for part in line.split("\r") if part.strip()]
    return status, raw, lines
