"""Errors a user can act on. The CLI prints them as one line and exits with status 2."""

import difflib

__all__ = [
    "EXCERPT_CHARS",
    "FormatError",
    "GeometryError",
    "MeshgenError",
    "MeshgenWarning",
    "ParameterError",
    "did_you_mean",
    "excerpt",
    "unknown_name",
]

# The most characters of a file's or a user's text that an error message repeats.
EXCERPT_CHARS = 80


class MeshgenError(Exception):
    """A problem with the user's input or environment, reported without a traceback."""


class MeshgenWarning(UserWarning):
    """Something the user should know about an output that was written (a re-meshed case kept a
    user's field): the CLI prints it as one ``Warning:`` line."""


class GeometryError(MeshgenError):
    """A geometry could not be found, loaded, parametrised or evaluated."""


class FormatError(MeshgenError):
    """A mesh could not be written or read in the requested format."""


class ParameterError(MeshgenError):
    """A bad value of one parameter of a library function. The message names the parameter where
    ``{name}`` stands in ``template``: as the parameter (``tol``) for a Python caller, as its flag
    (``--tol``) on the command line (``message_for``)."""

    def __init__(self, parameter: str, template: str):
        self.parameter = parameter
        self.template = template
        super().__init__(template.replace("{name}", parameter))

    def message_for(self, name: str) -> str:
        return self.template.replace("{name}", name)


def did_you_mean(name: str, choices) -> str:
    """``"; did you mean 'x'?"`` for the choice closest to a misspelt ``name``, or ``""``."""
    close = difflib.get_close_matches(name, list(choices), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


def unknown_name(kind: str, name: str, choices, error=MeshgenError) -> MeshgenError:
    """The error for an unknown ``kind`` (method, preset, ...): ``unknown method 'x' (methods: a,
    b); did you mean 'a'?``."""
    return error(f"unknown {kind} '{name}' ({kind}s: {', '.join(choices)}){did_you_mean(name, choices)}")


def excerpt(text, limit: int = EXCERPT_CHARS, tail: bool = False) -> str:
    """``text`` on one line, cut to ``limit`` characters (an ellipsis and the length marks a cut):
    an error message never repeats more than a short excerpt of what it was given. ``tail``: keep
    the end (a path's file name) rather than the start."""
    flat = " ".join(str(text).split())
    if len(flat) <= limit:
        return flat
    return f"…{flat[1 - limit :]} ({len(flat)} characters)" if tail else f"{flat[: limit - 1]}… ({len(flat)} characters)"
