"""Errors a user can act on. The CLI prints them as one line and exits with status 2."""


class MeshgenError(Exception):
    """A problem with the user's input or environment, reported without a traceback."""


class GeometryError(MeshgenError):
    """A geometry could not be found, loaded, parametrised or evaluated."""


class FormatError(MeshgenError):
    """A mesh could not be written or read in the requested format."""
