"""Meshing methods, looked up by name. Each maps a geometry and 1D parametric node coordinates to a
node array: ``build(geometry, coords, **options) -> (X, info)``, with ``info`` a JSON-serialisable
dict of what the method wants recorded (iterations, residual, ...)."""

from __future__ import annotations

import importlib
import difflib
from dataclasses import dataclass

from meshgen.errors import MeshgenError


@dataclass(frozen=True)
class Method:
    name: str
    function: str  # "module:function"
    description: str
    options: tuple[str, ...] = ()  # keyword options the function accepts beyond (geometry, coords)

    def build(self, geometry, coords, **options):
        module_name, function_name = self.function.split(":")
        return getattr(importlib.import_module(module_name), function_name)(geometry, coords, **options)


METHODS: dict[str, Method] = {}


def register_method(method: Method) -> None:
    METHODS[method.name] = method


register_method(Method("tfi", "meshgen.methods:build_tfi", "transfinite interpolation (Gordon-Hall), algebraic"))
register_method(Method("elliptic", "meshgen.elliptic:build_elliptic", "Winslow elliptic equations, nonlinear multigrid", options=("tol", "max_iter", "progress")))
register_method(Method("neural", "meshgen.neural.inference:build_neural", "a network trained with meshgen train (3DMeshNet), evaluated at the nodes", options=("model", "correct", "device")))


def get_method(name: str) -> Method:
    if name not in METHODS:
        close = difflib.get_close_matches(name, list(METHODS), n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise MeshgenError(f"unknown method '{name}' (methods: {', '.join(METHODS)}){hint}")
    return METHODS[name]


def build_tfi(geometry, coords):
    from meshgen.tfi import tfi

    return tfi(geometry, None, coords), {}


def make_mesh(method_name: str, geometry, coords, **options):
    """Run method ``method_name``; options it does not take are an error, unset ones (None) are dropped."""
    method = get_method(method_name)
    given = {k: v for k, v in options.items() if v is not None}
    foreign = sorted(set(given) - set(method.options))
    if foreign:
        flag = "--" + foreign[0].replace("_", "-")
        raise MeshgenError(f"{flag} does not apply to method '{method_name}'")
    return method.build(geometry, coords, **given)
