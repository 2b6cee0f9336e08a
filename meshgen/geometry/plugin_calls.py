"""The one place that runs geometry plugin code (design notes, "Trust boundary and faults").

A plugin is foreign code: whatever it does wrong becomes one GeometryError line naming the plugin
and the function, never a traceback and never meshgen's own exit. ``call_plugin`` runs a plugin
function with NumPy's floating-point errors raised (an overflow or an invalid operation inside
the plugin is an error, not a warning and a misleading message later) and turns every exception
into that line: SystemExit (``sys.exit()`` in a plugin must not end meshgen with the plugin's
status), GeneratorExit and any other BaseException. KeyboardInterrupt (the user's Ctrl-C) and
meshgen's own BaseExceptions (raised by its signal handlers) pass through. ``plugin_array`` checks what a plugin returned: real numbers (complex values are
refused, not cast), the expected shape, finite.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from meshgen.errors import GeometryError, excerpt
from meshgen.run.limits import MAX_COORDINATE

__all__ = ["call_plugin", "passes_through", "plugin_array"]


def call_plugin(plugin: str, function: str, code: Callable, *args, failed: str | None = None, **kwargs):
    """``code(*args, **kwargs)``, a function of the plugin ``plugin`` (its name and file, for the
    message) called ``function``. A GeometryError the plugin raises itself is passed on (its own
    words); every other exception but KeyboardInterrupt becomes GeometryError
    "``failed`` TYPE: MESSAGE", ``failed`` by default "geometry PLUGIN: FUNCTION raised"."""
    try:
        with np.errstate(over="raise", divide="raise", invalid="raise", under="ignore"):
            return code(*args, **kwargs)
    except GeometryError:
        raise
    except BaseException as exc:  # noqa: BLE001 - foreign code: SystemExit and GeneratorExit too
        if passes_through(exc):
            raise
        detail = f": {excerpt(exc)}" if str(exc) else ""
        raise GeometryError(f"{failed or f'geometry {plugin}: {function} raised'} {type(exc).__name__}{detail}") from None


def passes_through(exc: BaseException) -> bool:
    """Whether ``exc`` ends meshgen rather than the plugin call: the user's Ctrl-C
    (KeyboardInterrupt) and meshgen's own BaseException subclasses, which its signal handlers
    raise (SIGTERM, SIGHUP) wherever the process is, a plugin's code included."""
    own = type(exc).__module__.split(".")[0] == "meshgen" and not isinstance(exc, Exception)
    return isinstance(exc, KeyboardInterrupt) or own


def plugin_array(plugin: str, function: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` (what ``function`` of ``plugin`` returned) as a float64 array of ``shape``, else
    GeometryError: not numbers, complex numbers, another shape, or non-finite values."""
    try:
        array = np.asarray(value)
    except BaseException as exc:  # noqa: BLE001 - a foreign object's __array__ is foreign code too
        if passes_through(exc):
            raise
        raise GeometryError(f"geometry {plugin}: {function} returned something that is not an array of numbers") from None
    if np.iscomplexobj(array):
        raise GeometryError(f"geometry {plugin}: {function} returned complex numbers (the map must be real)")
    if array.dtype.kind not in "biuf":
        try:
            array = array.astype(float)
        except (TypeError, ValueError):
            raise GeometryError(
                f"geometry {plugin}: {function} returned something that is not an array of numbers ({type(value).__name__})"
            ) from None
        if np.iscomplexobj(array):
            raise GeometryError(f"geometry {plugin}: {function} returned complex numbers (the map must be real)")
    array = np.asarray(array, dtype=float)
    if array.shape != shape:
        raise GeometryError(f"geometry {plugin}: {function} returned shape {array.shape} for input shape {shape}")
    if not np.all(np.isfinite(array)):
        raise GeometryError(f"geometry {plugin}: {function} returned non-finite values")
    if array.size and np.abs(array).max() > MAX_COORDINATE:
        raise GeometryError(
            f"geometry {plugin}: {function} returned values beyond {MAX_COORDINATE:g} (they overflow every measure)"
        )
    return array
