"""Meshing methods, looked up by name: one registry for ``meshgen mesh``, ``meshgen compare`` and
``meshgen.mesh``. Each maps a geometry and 1D parametric node coordinates to a node array:
``build(geometry, coords, **options) -> (X, info)``, with ``info`` a JSON-serialisable dict of what
the method wants recorded (iterations, residual, ...).

The neural methods are one function, ``meshgen.neural.models.build_neural`` (a trained network
evaluated at the nodes, its boundary corrected onto the geometry), registered once as ``neural``
(any trained model) and once per training preset (``3dmeshnet``, ``exact``, ``pinn`` ...: the
methods of design notes §6, which ``meshgen compare`` trains with that preset). So a mesh of the
same checkpoint is the same mesh, whichever command makes it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from meshgen.errors import ParameterError, unknown_name
from meshgen.geometry.layout import with_layout
from meshgen.methods.tfi import tfi
from meshgen.run.limits import check_mesh_memory

__all__ = ["METHODS", "NEURAL", "NEURAL_OPTIONS", "TRAINED", "Method", "build_tfi", "get_method", "make_mesh", "register_method"]


@dataclass(frozen=True)
class Method:
    name: str
    function: str  # "module:function"
    description: str
    options: tuple[str, ...] = ()  # keyword options the function accepts beyond (geometry, coords)
    preset: str | None = None  # neural: the training preset that makes its network (None: any model)

    @property
    def neural(self) -> bool:
        return "model" in self.options

    def build(self, geometry, coords, **options):
        module_name, function_name = self.function.split(":")
        return getattr(importlib.import_module(module_name), function_name)(geometry, coords, **options)


METHODS: dict[str, Method] = {}


def register_method(method: Method) -> None:
    METHODS[method.name] = method


NEURAL = "meshgen.neural.models:build_neural"
NEURAL_OPTIONS = ("model", "correct", "device", "polish")
register_method(
    Method(
        "tfi",
        "meshgen.methods.registry:build_tfi",
        "transfinite interpolation (Gordon-Hall), algebraic",
        options=("boundary_layout",),
    )
)
register_method(
    Method(
        "elliptic",
        "meshgen.methods.elliptic:build_elliptic",
        "Winslow elliptic equations, nonlinear multigrid",
        options=("tol", "max_iter", "progress", "boundary_layout", "orthogonal", "device"),
    )
)
register_method(
    Method("neural", NEURAL, "a network trained with meshgen train (3DMeshNet), evaluated at the nodes", options=NEURAL_OPTIONS)
)
# The trained methods of design notes §6: name -> training preset (presets/<preset>.yaml).
TRAINED = {
    "3dmeshnet": "default",
    "exact": "exact",
    "pinn": "pinn",
    "fd-pinn": "fd-pinn",
    "rwgp-pinn": "rwgp-pinn",
    "mgnet": "mgnet",
}
for _name, _preset in TRAINED.items():
    register_method(Method(_name, NEURAL, f"a network trained with preset '{_preset}'", options=NEURAL_OPTIONS, preset=_preset))


def get_method(name: str) -> Method:
    if name not in METHODS:
        raise unknown_name("method", name, METHODS)
    return METHODS[name]


def build_tfi(geometry, coords, boundary_layout: str = "fixed"):
    """TFI of the geometry's boundary map ("fixed", the default: the algebraic reference), or of
    the smoothed boundary layout (``meshgen.geometry.layout``)."""
    return tfi(with_layout(geometry, boundary_layout), None, coords), {"boundary_layout": boundary_layout}


def make_mesh(method_name: str, geometry, coords, **options):
    """Run method ``method_name``; options it does not take are an error, unset ones (None) are dropped."""
    method = get_method(method_name)
    check_mesh_memory([len(c) - 1 for c in coords], chunked=False)  # before the method allocates its node array
    given = {k: v for k, v in options.items() if v is not None}
    foreign = sorted(set(given) - set(method.options))
    if foreign:
        raise ParameterError(foreign[0], f"{{name}} does not apply to method '{method_name}'")
    return method.build(geometry, coords, **given)
