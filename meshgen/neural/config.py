"""The training configuration: plain data in nested dataclasses, read from YAML presets and files,
overridden by ``--set section.key=value``, checked before any work starts.

Layers, each over the previous: the defaults below (which ``presets/default.yaml`` spells out), the
preset chosen with ``--preset``, a YAML file given with ``--config``, then every ``--set``. A run
folder's ``config.yaml`` is a complete file of this kind, so ``--config runs/x/config.yaml``
repeats a run.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

from meshgen.errors import MeshgenError, did_you_mean, excerpt, unknown_name
from meshgen.geometry.plugins import builtin_dir
from meshgen.run.inputs import MAX_YAML_BYTES, InputError, load_yaml, read_input_text

__all__ = [
    "dotted_items",
    "keys_off_default",
    "ConfigError",
    "ModelConfig",
    "MethodConfig",
    "PointsConfig",
    "PretrainConfig",
    "AdamConfig",
    "LbfgsConfig",
    "CheckpointConfig",
    "GuardConfig",
    "TestConfig",
    "TrainConfig",
    "CHOICES",
    "schema",
    "set_key",
    "apply_mapping",
    "parse_override",
    "presets_dir",
    "preset_paths",
    "read_yaml",
    "load_preset",
    "list_presets",
    "resolve_config",
    "from_dict",
    "to_dict",
    "to_yaml",
    "validate",
]


class ConfigError(MeshgenError):
    """A preset, configuration file or override is unknown, malformed or inconsistent."""


@dataclass
class ModelConfig:
    widths: list[int] = field(default_factory=lambda: [48, 48, 48])  # hidden layer widths of the tanh MLP
    exact_boundary: bool = False  # output TFI + b N (boundary met exactly) instead of N


@dataclass
class MethodConfig:
    derivatives: str = "fd"  # "fd": finite differences on shifted grids; "autograd": AD at random points
    reweighting: bool = True  # learn a1, a2 (uncertainty weights with the log(1 + a1^2 + a2^2) term)
    balance_start: bool = True  # reweighting: start a1, a2 at the stationary point of L for the first losses
    pcgrad: bool = True  # project conflicting PDE / boundary gradients
    point_weights: float = 1.0  # c of the surface-point weights w = 1 + c |error|; 0 switches them off
    # L2's error: "relative" to the boundary's local size (scale-free, like L1), or "absolute" in
    # normalised units (the paper's)
    boundary_error: str = "relative"
    pde_weight: float = 1.0  # fixed weight of L1 (the starting weight when reweighting)
    boundary_weight: float = 1.0  # fixed weight of L2 (the starting weight when reweighting)
    # block sets only: weight in L1 of the pull of every block's network towards its start, the
    # elliptic mesh (pretrain.target tfi: its TFI; design notes §20); 0 switches it off. Refused
    # (unless 1) for one shape or a family
    tfi_anchor: float = 1.0


@dataclass
class PointsConfig:
    interior: int = 4000  # residual points per step (fd: the nearest m^dim grid nodes)
    boundary: int = 6000  # boundary points per step
    random_grid: bool = True  # fd: shift and rescale the training grid at random every step
    grid_min_scale: float = 0.8  # fd: the random grid spans a fraction in [this, 1] of each axis
    boundary_pool: int = 64  # boundary points are drawn from a fixed pool of this many steps' worth (0: fresh)
    # fd: every training grid lies on the smoothed layout's fine lattice (spacing 1/64), where its
    # faces solve the discrete Winslow equations, so the residual is zero for the interior those faces
    # imply (an extruded shape: its extrusion); off the lattice it is not (design notes §18). With the
    # fixed layout the lattice is only a grid of spacing 1/64
    lattice: bool = False
    # a family of wall-layer sections (--vary on the airfoil, meshgen.neural.wall_family): members
    # drawn (Latin hypercube) whose elliptic meshes the network fits, besides the 2^k corners and the middle
    members: int = 40


@dataclass
class PretrainConfig:
    steps: int = 20  # L-BFGS steps fitting the network to its start before training (0: start from random weights)
    lr: float = 1.0
    points: int = 4000  # fixed interior points (and as many boundary points) of the fit to TFI
    # what the networks are fitted to first: auto (a block set's elliptic mesh, one block's TFI),
    # tfi, or elliptic (block sets only: the set's multi-block elliptic mesh on a fine grid,
    # meshgen.neural.elliptic_start; method.tfi_anchor then pulls towards it too)
    target: str = "auto"


@dataclass
class AdamConfig:
    steps: int = 500
    lr: float = 1e-4  # paper: 1e-3 from random weights; after the fit to TFI a smaller step keeps the boundary
    decay: float = 0.9  # the learning rate is multiplied by this ...
    decay_every: int = 1000  # ... every this many steps
    weights_lr: float | None = None  # learning rate of log a1, log a2 (null: lr, decayed alike)
    # a one-block run that trains an extruded shape's 2D section (design notes §20): its Adam steps (null: steps)
    section_steps: int | None = None
    # a block set fitted to its elliptic mesh first (pretrain.target auto or elliptic): its Adam
    # steps (null: steps); 0 by default, the fit being where the Winslow loss ends (design notes §20)
    block_steps: int | None = 0


@dataclass
class LbfgsConfig:
    steps: int = 300  # L-BFGS steps (strong Wolfe line search) on fixed points after Adam
    max_iter: int = 20  # iterations per step
    history_size: int = 50
    lr: float = 1.0
    # the network and its residual in float64 for this stage (float32 otherwise): in float32 the
    # finite-difference residual's round-off stops L-BFGS well above what the network can reach
    float64: bool = False
    section_steps: int | None = None  # a one-block run that trains an extruded shape's 2D section: its L-BFGS steps (null: steps)
    block_steps: int | None = 0  # a block set fitted to its elliptic mesh first: its L-BFGS steps (null: steps)


@dataclass
class CheckpointConfig:
    every: int = 100  # save every this many steps (and at the end)


@dataclass
class GuardConfig:
    max_retries: int = 5  # consecutive non-finite losses tolerated before training stops
    lr_factor: float = 0.5  # learning-rate factor after a non-finite loss


@dataclass
class TestConfig:
    interior: int = 1000  # held-out interior points (fixed, independent of the seed)
    boundary: int = 1000  # held-out boundary points


@dataclass
class TrainConfig:
    description: str = "the full 3DMeshNet method, sized for a few minutes on a 2-core CPU (fit to TFI, Adam, L-BFGS)"
    dim: int | None = None  # 2 or 3 for presets made for one dimension; null: any
    seed: int = 0
    # the boundary the network learns: "smoothed" (meshgen.geometry.layout: the faces' own Winslow grids) or
    # "fixed" (the geometry's map: each face the Coons layout of its edges)
    boundary_layout: str = "smoothed"
    model: ModelConfig = field(default_factory=ModelConfig)
    method: MethodConfig = field(default_factory=MethodConfig)
    points: PointsConfig = field(default_factory=PointsConfig)
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    adam: AdamConfig = field(default_factory=AdamConfig)
    lbfgs: LbfgsConfig = field(default_factory=LbfgsConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    guard: GuardConfig = field(default_factory=GuardConfig)
    test: TestConfig = field(default_factory=TestConfig)


CHOICES = {
    "method.derivatives": ("fd", "autograd"),
    "method.boundary_error": ("relative", "absolute"),
    "pretrain.target": ("auto", "tfi", "elliptic"),
}

# The range of every number of the configuration, (lowest, highest) inclusive (model.widths: of
# each width). Every int and float key has one (tests/test_trust.py checks): an upper bound keeps
# a mistyped value from asking for more than any machine has.
BOUNDS = {
    "seed": (0, 2**63 - 1),
    "dim": (2, 3),
    "model.widths": (1, 4096),
    "method.point_weights": (0.0, 1e6),
    "method.pde_weight": (0.0, 1e6),
    "method.boundary_weight": (0.0, 1e6),
    "method.tfi_anchor": (0.0, 1e6),
    "points.interior": (1, 10**7),
    "points.boundary": (1, 10**7),
    "points.grid_min_scale": (0.0, 1.0),
    "points.boundary_pool": (0, 10**4),
    "points.members": (0, 10**4),
    "pretrain.steps": (0, 10**7),
    "pretrain.lr": (0.0, 1e3),
    "pretrain.points": (1, 10**7),
    "adam.steps": (0, 10**8),
    "adam.lr": (0.0, 1e3),
    "adam.decay": (0.0, 1.0),
    "adam.decay_every": (1, 10**9),
    "adam.weights_lr": (0.0, 1e3),
    "adam.section_steps": (0, 10**8),
    "adam.block_steps": (0, 10**8),
    "lbfgs.steps": (0, 10**7),
    "lbfgs.max_iter": (1, 10**4),
    "lbfgs.history_size": (1, 10**4),
    "lbfgs.lr": (0.0, 1e3),
    "lbfgs.section_steps": (0, 10**7),
    "lbfgs.block_steps": (0, 10**7),
    "checkpoint.every": (1, 10**9),
    "guard.max_retries": (0, 1000),
    "guard.lr_factor": (0.0, 1.0),
    "test.interior": (1, 10**7),
    "test.boundary": (1, 10**7),
}
MAX_LAYERS = 64  # hidden layers of model.widths


# ---------------------------------------------------------------------------------------------
# keys and types


def _fields(cls) -> dict[str, typing.Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def schema(cls=TrainConfig, prefix: str = "") -> dict[str, typing.Any]:
    """Every dotted key with its type, e.g. {"adam.steps": int, ...}."""
    keys = {}
    for name, kind in _fields(cls).items():
        if dataclasses.is_dataclass(kind):
            keys.update(schema(kind, f"{prefix}{name}."))
        else:
            keys[f"{prefix}{name}"] = kind
    return keys


def _type_name(kind) -> str:
    if kind is bool:
        return "true or false"
    if kind is int:
        return "an integer"
    if kind is float:
        return "a number"
    if kind is str:
        return "a string"
    if typing.get_origin(kind) is list:
        return "a list of integers, e.g. [48, 48, 48]"
    return f"null or {_type_name(typing.get_args(kind)[0])}"


def _coerce(key: str, kind, value):
    """``value`` as ``kind`` (int -> float allowed, nothing else), or ConfigError."""
    ok = False
    if kind is bool:
        ok = isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        if isinstance(value, str):  # YAML 1.1 reads 1e-3 (no dot) as a string
            try:
                value = float(value)
            except ValueError:
                pass
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
        if ok and not math.isfinite(value):  # .inf and .nan are YAML numbers, not usable ones
            raise ConfigError(f"configuration key '{key}' must be a finite number, got {value!r}")
    elif kind is str:
        ok = isinstance(value, str)
    elif typing.get_origin(kind) is list:
        ok = isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        value = list(value) if ok else value
    else:  # Optional[int] or Optional[float]
        try:
            return None if value is None else _coerce(key, typing.get_args(kind)[0], value)
        except ConfigError:
            ok = False
    if not ok:
        raise ConfigError(f"configuration key '{key}' must be {_type_name(kind)}, got {excerpt(repr(value))}")
    return value


def _unknown(key: str) -> ConfigError:
    valid = list(schema())
    return ConfigError(f"unknown configuration key '{key}'{did_you_mean(key, valid)} (valid keys: {', '.join(valid)})")


def set_key(config: TrainConfig, key: str, value) -> None:
    """Set the dotted ``key`` of ``config`` to ``value`` (type-checked)."""
    kinds = schema()
    if key not in kinds:
        raise _unknown(key)
    *sections, name = key.split(".")
    target = config
    for section in sections:
        target = getattr(target, section)
    setattr(target, name, _coerce(key, kinds[key], value))


def apply_mapping(config: TrainConfig, data, source: str) -> None:
    """Apply a nested mapping (as read from YAML) to ``config``; ``source`` names it in errors."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping of configuration keys, got {type(data).__name__}")
    sections = {name for name, kind in _fields(TrainConfig).items() if dataclasses.is_dataclass(kind)}

    def walk(mapping, prefix):
        for name, value in mapping.items():
            key = f"{prefix}{name}"
            if prefix == "" and name in sections:
                if not isinstance(value, dict):
                    raise ConfigError(f"{source}: '{key}' must be a mapping of keys, got {value!r}")
                walk(value, f"{key}.")
            else:
                try:
                    set_key(config, key, value)
                except ConfigError as exc:
                    raise ConfigError(f"{source}: {exc}") from None

    walk(data, "")


def parse_override(text: str) -> tuple[str, typing.Any]:
    """``"adam.steps=100"`` -> ("adam.steps", 100): the value is read as YAML (numbers, true/false,
    lists, null, strings)."""
    import yaml

    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"malformed --set {text!r}: expected key=value, e.g. adam.steps=2000")
    try:
        value = load_yaml(raw, f"--set {excerpt(text)}") if raw.strip() else ""
    except InputError as exc:
        raise ConfigError(str(exc)) from None
    except yaml.YAMLError:
        raise ConfigError(f"malformed --set {excerpt(repr(text))}: {excerpt(repr(raw))} is not a value") from None
    return key, value


# ---------------------------------------------------------------------------------------------
# presets and files


def presets_dir() -> Path:
    return builtin_dir("presets")


def preset_paths() -> dict[str, Path]:
    return {p.stem: p for p in sorted(presets_dir().glob("*.yaml"))}


def read_yaml(path: Path, what: str):
    import yaml

    try:
        text = read_input_text(path, what, MAX_YAML_BYTES)
        return load_yaml(text, f"{what} {path}") or {}
    except InputError as exc:
        message = str(exc)
        if message.endswith("(not UTF-8)"):
            message += ": a YAML file was expected"
        raise ConfigError(message) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise ConfigError(f"{what} {path} is malformed YAML{where}: {problem}") from None


def load_preset(name: str) -> dict:
    """The mapping of preset ``name`` (unknown names raise with the list of presets)."""
    paths = preset_paths()
    if name not in paths:
        raise unknown_name("preset", name, paths, ConfigError)
    return read_yaml(paths[name], "preset")


def list_presets() -> list[tuple[str, str]]:
    """(name, one-line description) of every preset."""
    described = []
    for name in preset_paths():
        data = load_preset(name)
        described.append((name, str(data.get("description", "")).strip() if isinstance(data, dict) else ""))
    return described


def resolve_config(preset="default", config_file=None, overrides=(), steps=None, seed=None) -> TrainConfig:
    """The configuration of a run: defaults, then the preset, the file, every ``key=value`` of
    ``overrides``, ``steps`` (adam.steps) and ``seed``; validated."""
    config = TrainConfig()
    if preset is not None:
        apply_mapping(config, load_preset(preset), f"preset '{preset}'")
    if config_file is not None:
        apply_mapping(config, read_yaml(Path(config_file), "configuration file"), str(config_file))
    for text in overrides:
        key, value = parse_override(text)
        try:
            set_key(config, key, value)
        except ConfigError as exc:
            raise ConfigError(f"--set {text}: {exc}") from None
    if steps is not None:
        set_key(config, "adam.steps", steps)
    if seed is not None:
        set_key(config, "seed", seed)
    validate(config)
    return config


def from_dict(data: dict) -> TrainConfig:
    """A configuration from a complete mapping (a checkpoint's or a run folder's), validated."""
    config = TrainConfig()
    apply_mapping(config, data, "configuration")
    validate(config)
    return config


def to_dict(config: TrainConfig) -> dict:
    return dataclasses.asdict(config)


def to_yaml(config: TrainConfig) -> str:
    import yaml

    return yaml.safe_dump(to_dict(config), sort_keys=False, default_flow_style=False)


# ---------------------------------------------------------------------------------------------
# consistency


def validate(config: TrainConfig) -> None:
    """Raise ConfigError for values out of range or switches that do not go together."""

    def need(condition, key, text):
        if not condition:
            value = config
            for part in key.split("."):
                value = getattr(value, part)
            raise ConfigError(f"configuration key '{key}' {text}, got {excerpt(repr(value))}")

    for key, choices in CHOICES.items():
        section, name = key.split(".")
        need(getattr(getattr(config, section), name) in choices, key, f"must be one of {', '.join(choices)}")
    need(config.dim in (None, 2, 3), "dim", "must be 2, 3 or null")
    need(config.boundary_layout in ("smoothed", "fixed"), "boundary_layout", "must be one of smoothed, fixed")
    need(len(config.model.widths) >= 1 and min(config.model.widths) >= 1, "model.widths", "must be positive widths")
    need(config.method.point_weights >= 0, "method.point_weights", "must be >= 0")
    need(config.method.pde_weight > 0, "method.pde_weight", "must be > 0")
    need(config.method.boundary_weight > 0, "method.boundary_weight", "must be > 0")
    need(config.method.tfi_anchor >= 0, "method.tfi_anchor", "must be >= 0")
    need(config.points.interior >= 1, "points.interior", "must be >= 1")
    need(config.points.boundary >= 1, "points.boundary", "must be >= 1")
    need(0 < config.points.grid_min_scale <= 1, "points.grid_min_scale", "must be in (0, 1]")
    need(config.points.boundary_pool >= 0, "points.boundary_pool", "must be >= 0")
    for stage in ("pretrain", "adam", "lbfgs"):
        need(getattr(config, stage).steps >= 0, f"{stage}.steps", "must be >= 0")
        need(getattr(config, stage).lr > 0, f"{stage}.lr", "must be > 0")
    need(config.pretrain.points >= 1, "pretrain.points", "must be >= 1")
    need(0 < config.adam.decay <= 1, "adam.decay", "must be in (0, 1]")
    need(config.adam.weights_lr is None or config.adam.weights_lr > 0, "adam.weights_lr", "must be > 0 or null")
    need(config.adam.decay_every >= 1, "adam.decay_every", "must be >= 1")
    need(config.lbfgs.max_iter >= 1, "lbfgs.max_iter", "must be >= 1")
    need(config.lbfgs.history_size >= 1, "lbfgs.history_size", "must be >= 1")
    need(config.checkpoint.every >= 1, "checkpoint.every", "must be >= 1")
    need(config.guard.max_retries >= 0, "guard.max_retries", "must be >= 0")
    need(0 < config.guard.lr_factor < 1, "guard.lr_factor", "must be in (0, 1)")
    need(config.test.interior >= 1, "test.interior", "must be >= 1")
    need(config.test.boundary >= 1, "test.boundary", "must be >= 1")
    if config.model.exact_boundary:
        # The boundary is met by construction: L2 is zero and only the PDE loss is trained.
        need(config.method.derivatives == "fd", "method.derivatives", "must be fd with model.exact_boundary")
        need(not config.method.reweighting, "method.reweighting", "must be false with model.exact_boundary (no L2)")
        need(not config.method.pcgrad, "method.pcgrad", "must be false with model.exact_boundary (no L2)")
    if config.points.lattice:
        need(config.method.derivatives == "fd", "points.lattice", "needs method.derivatives fd")
    _check_bounds(config)


def _check_bounds(config: TrainConfig) -> None:
    """ConfigError for a number outside its ``BOUNDS`` (null optional keys pass)."""
    for key, (low, high) in BOUNDS.items():
        value = config
        for part in key.split("."):
            value = getattr(value, part)
        values = value if isinstance(value, list) else [value]
        if key == "model.widths" and len(values) > MAX_LAYERS:
            raise ConfigError(f"configuration key 'model.widths' has {len(values)} layers, at most {MAX_LAYERS}")
        for number in values:
            if number is not None and not low <= number <= high:
                raise ConfigError(f"configuration key '{key}' must lie in [{low:g}, {high:g}], got {excerpt(repr(number))}")


def keys_off_default(config: TrainConfig, keys) -> dict:
    """{dotted key: value} of those ``keys`` that ``config`` sets away from ``TrainConfig()``'s
    default, in the order of ``keys``."""
    chosen, default = dotted_items(to_dict(config)), dotted_items(to_dict(TrainConfig()))
    return {key: chosen[key] for key in keys if chosen[key] != default[key]}


def dotted_items(mapping: dict, prefix: str = "") -> dict:
    """A nested configuration mapping (``to_dict``'s, or a checkpoint's ``config``) as
    {dotted key: value}, e.g. {"adam.steps": 12000}."""
    items = {}
    for name, value in mapping.items():
        if isinstance(value, dict):
            items.update(dotted_items(value, f"{prefix}{name}."))
        else:
            items[f"{prefix}{name}"] = value
    return items
