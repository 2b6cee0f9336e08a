"""Configuration: presets, layering, --set parsing, and the errors for unknown keys and bad values."""

import pytest

from meshgen.neural.config import (
    ConfigError,
    TrainConfig,
    from_dict,
    list_presets,
    preset_paths,
    resolve_config,
    schema,
    to_dict,
    to_yaml,
)

ISSUE_PRESETS = {"default", "paper", "2d", "large", "pinn", "mgnet", "fd-pinn", "rwgp-pinn", "exact"}


def test_every_preset_named_by_the_issue_exists_loads_and_has_a_description():
    described = dict(list_presets())
    assert ISSUE_PRESETS <= set(described)
    for name in described:
        assert described[name] and "\n" not in described[name]
        resolve_config(name)


def test_default_yaml_spells_out_exactly_the_built_in_defaults():
    import yaml

    data = yaml.safe_load(preset_paths()["default"].read_text())
    assert data == to_dict(TrainConfig())


def test_presets_encode_the_variants_of_the_design_table():
    paper = resolve_config("paper")
    assert paper.model.widths == [85] * 4 and paper.points.interior == 4000 and paper.points.boundary == 6000
    assert (paper.adam.steps, paper.adam.lr, paper.adam.decay, paper.adam.decay_every) == (12000, 1e-3, 0.9, 1000)
    assert paper.lbfgs.steps > 0 and paper.dim == 3
    assert resolve_config("2d").model.widths == [45] * 3 and resolve_config("2d").dim == 2
    assert resolve_config("large").model.widths == [128] * 4
    table = {  # derivatives, reweighting, point weights, projection
        "pinn": ("autograd", False, False, False),
        "mgnet": ("autograd", False, False, False),
        "fd-pinn": ("fd", False, False, False),
        "rwgp-pinn": ("autograd", True, True, True),
        "default": ("fd", True, True, True),
    }
    for name, expected in table.items():
        method = resolve_config(name).method
        assert (method.derivatives, method.reweighting, method.point_weights > 0, method.pcgrad) == expected, name
    assert resolve_config("mgnet").method.boundary_weight > 1
    exact = resolve_config("exact")
    assert exact.model.exact_boundary and not exact.method.reweighting and not exact.method.pcgrad


def test_layers_apply_in_order_preset_file_set(tmp_path):
    config_file = tmp_path / "c.yaml"
    config_file.write_text("adam:\n  steps: 77\n  lr: 2e-3\nmodel:\n  widths: [5, 6]\n")
    config = resolve_config("paper", config_file, ["adam.steps=88", "method.pcgrad=false"], seed=4)
    assert config.adam.steps == 88 and config.adam.lr == 2e-3  # YAML 1.1's "2e-3" string read as a number
    assert config.model.widths == [5, 6] and config.method.pcgrad is False and config.seed == 4
    assert config.adam.decay_every == 1000  # from the preset
    assert resolve_config("default", steps=12).adam.steps == 12


def test_a_resolved_configuration_round_trips_through_yaml():
    import yaml

    config = resolve_config("mgnet", None, ["model.widths=[3,4]", "adam.weights_lr=0.01"])
    assert from_dict(yaml.safe_load(to_yaml(config))) == config


def test_unknown_keys_are_refused_with_the_list_of_valid_keys(tmp_path):
    with pytest.raises(ConfigError) as error:
        resolve_config("default", None, ["adam.stepz=3"])
    message = str(error.value)
    assert "unknown configuration key 'adam.stepz'" in message and "did you mean 'adam.steps'" in message
    for key in schema():
        assert key in message
    config_file = tmp_path / "c.yaml"
    config_file.write_text("lbfgs:\n  iterations: 3\n")
    with pytest.raises(ConfigError, match=r"c.yaml: unknown configuration key 'lbfgs.iterations'"):
        resolve_config("default", config_file)
    config_file.write_text("optimiser: {lr: 1}\n")
    with pytest.raises(ConfigError, match="unknown configuration key 'optimiser'"):
        resolve_config("default", config_file)


@pytest.mark.parametrize(
    "override, expected",
    [
        ("adam.steps=abc", "'adam.steps' must be an integer, got 'abc'"),
        ("adam.steps=2.5", "'adam.steps' must be an integer"),
        ("adam.lr=fast", "'adam.lr' must be a number"),
        ("method.pcgrad=1", "'method.pcgrad' must be true or false"),
        ("model.widths=[8,x]", "'model.widths' must be a list of integers"),
        ("model.widths=8", "'model.widths' must be a list of integers"),
        ("adam.weights_lr=yes", "'adam.weights_lr' must be null or a number"),
        ("method.derivatives=spectral", "'method.derivatives' must be one of fd, autograd"),
        ("adam.lr=-1", "'adam.lr' must be > 0"),
        ("model.widths=[]", "'model.widths' must be positive widths"),
        ("adam", "malformed --set 'adam'"),
        ("model=3", "unknown configuration key 'model'"),
    ],
)
def test_ill_typed_and_out_of_range_values_are_refused(override, expected):
    with pytest.raises(ConfigError) as error:
        resolve_config("default", None, [override])
    assert expected in str(error.value)


def test_inconsistent_switches_are_refused():
    with pytest.raises(ConfigError, match="method.reweighting' must be false with model.exact_boundary"):
        resolve_config("default", None, ["model.exact_boundary=true"])
    with pytest.raises(ConfigError, match="'method.derivatives' must be fd with model.exact_boundary"):
        resolve_config("exact", None, ["method.derivatives=autograd"])


def test_unknown_preset_and_malformed_yaml(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown preset 'papper' \(presets: .*\); did you mean 'paper'"):
        resolve_config("papper")
    bad = tmp_path / "bad.yaml"
    bad.write_text("adam:\n  steps: [1, 2\n")
    with pytest.raises(ConfigError, match="bad.yaml is malformed YAML at line"):
        resolve_config("default", bad)
    with pytest.raises(ConfigError, match="cannot be read"):
        resolve_config("default", tmp_path / "missing.yaml")
    listing = tmp_path / "list.yaml"
    listing.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        resolve_config("default", listing)


def test_the_schema_lists_every_leaf_of_the_dataclasses():
    keys = schema()
    assert {"seed", "dim", "adam.steps", "model.widths", "method.pcgrad", "lbfgs.max_iter"} <= set(keys)
    sections = ["model", "method", "points", "pretrain", "adam", "lbfgs", "checkpoint", "guard", "test"]
    assert all(any(k.startswith(s + ".") for k in keys) for s in sections)
    assert not any(k in sections for k in keys)  # sections themselves are not keys
