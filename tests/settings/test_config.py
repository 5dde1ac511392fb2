"""Configuration: the presets load, defaults agree with config/rimd.yaml, and bad values are refused with
the key, the value and the rule.
"""

from __future__ import annotations

import math

import pytest

from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import PARAMETERS, SimConfig, find_config_file, load_config, read_ros_parameters


def test_default_yaml_equals_code_defaults():
    """config/rimd.yaml restates the code defaults: one source of truth, documented in YAML."""
    assert load_config(find_config_file("rimd.yaml")) == SimConfig()


def test_paper_model_preset_differs_in_the_paper_values_mass_and_damping():
    """paper_model.yaml: the paper's equations with its A0 and natural frequency, no damping, an assumed 1 kg."""
    paper = load_config(find_config_file("paper_model.yaml")).to_parameters()
    default = SimConfig().to_parameters()
    assert {k for k in default if default[k] != paper[k]} == {"mass", "damping_ratio", "amplitude",
                                                              "natural_frequency"}
    assert (paper["mass"], paper["damping_ratio"], paper["amplitude"], paper["natural_frequency"]) == (
        1.0, 0.0, 1e-3, 1.82)


def test_derived_length_from_natural_frequency():
    """L = g / (2 pi 1.763)^2 = 0.0799 m (docs/physics.md, Model)."""
    assert SimConfig().rig.length == pytest.approx(0.07995, abs=1e-5)


BAD_VALUES = [
    ("mass", -0.15, ">= 0.001"),
    ("mass", 0.0, ">= 0.001"),
    ("gap", float("nan"), "finite"),
    ("gap", -1e-3, ">= 0"),
    ("gap", 0.04, "half the pendulum length"),
    ("amplitude", float("inf"), "finite"),
    ("natural_frequency", 0.0, "> 0"),
    ("damping_ratio", -0.1, ">= 0"),
    ("contact.model", "rubber", "one of"),
    ("contact.model", 3, "string"),
    ("contact.stiffness", -5.5e6, "> 0"),
    ("contact.stiffness", "5.5e6", "write exponents with a sign"),
    ("contact.damping", -1.0, ">= 0"),
    ("contact.exponent", 0.5, ">= 1"),
    ("contact.restitution", 1.5, "<= 1"),
    ("contact.restitution", 0.0, "> 0"),
    ("motor.max_frequency", 0.0, "> 0"),
    ("motor.ramp_rate", -2.0, "> 0"),
    ("motor.initial_setpoint", 50.0, "motor.max_frequency"),
    ("integrator.rtol", 0.1, "<= 0.001"),
    ("channels.impact_force.sample_rate", 0.0, "> 0"),
    ("channels.rimd_acceleration.sample_rate", -20000.0, "> 0"),
    ("channels.cart_displacement.range_max", -0.02, "range_min"),
    ("channels.rimd_acceleration.highpass", 15000.0, "0.45 x sample_rate"),
    ("channels.cart_displacement.noise_std", -1e-6, ">= 0"),
    ("noise.enabled", "yes", "true or false"),
    ("seed", -1, ">= 0"),
    ("structure.axial_stiffness", 5.0, "0 (rigid) or >= 1000"),
    ("real_time_factor", 1e-4, "or >= 0.001"),
    ("seed", 1.5, "integer"),
    ("real_time_factor", -1.0, ">= 0"),
    ("block_rate", 0.0, ">= 1"),
    ("truth.sample_rate", 0.0, "> 0"),
    ("channels.impact_force.frame_id", "", "non-empty"),
    ("channels.impact_force.frame_id", "force\0sensor", "without NUL"),
    ("no_such_parameter", 1.0, "unknown parameter"),
]


@pytest.mark.parametrize(("key", "value", "rule"), BAD_VALUES, ids=[f"{k}={v!r}" for k, v, _ in BAD_VALUES])
def test_bad_value_refused_with_key_value_and_rule(key, value, rule):
    with pytest.raises(ConfigError) as info:
        SimConfig().with_parameters({key: value})
    message = str(info.value)
    assert key in message or (key == "channels.cart_displacement.range_max" and "range_max" in message)
    assert rule in message
    if isinstance(value, float) and math.isnan(value):
        assert "nan" in message
    else:
        assert repr(value) in message or str(value) in message


def test_bad_value_in_yaml_file_names_key(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("rimd_simulator:\n  ros__parameters:\n    contact:\n      model: rubber\n")
    with pytest.raises(ConfigError, match="contact.model"):
        load_config(path)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("rimd_simulator: [1, 2", "not valid YAML"),
        ("other_node:\n  ros__parameters:\n    gap: 0.0\n", "no 'rimd_simulator: ros__parameters:' section"),
        ("- 1\n- 2\n", "must be a mapping"),
    ],
)
def test_malformed_files_refused(tmp_path, text, message):
    path = tmp_path / "f.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_missing_file_refused(tmp_path):
    with pytest.raises(ConfigError, match="cannot be read"):
        load_config(tmp_path / "absent.yaml")


def test_wildcard_section_is_merged(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text("/**:\n  ros__parameters:\n    seed: 5\nrimd_simulator:\n  ros__parameters:\n    gap: 0.001\n")
    assert read_ros_parameters(path) == {"seed": 5, "gap": 0.001}
    cfg = load_config(path)
    assert cfg.seed == 5 and cfg.rig.gap == 0.001


def another_valid_value(p):
    """A valid value of parameter ``p`` other than its default (within its declared rule)."""
    if p.kind == "bool":
        return not p.default
    if p.kind == "str":
        return next(c for c in p.choices if c != p.default) if p.choices else p.default + "_2"
    if p.kind == "int":
        return p.default + 1
    value = p.default * 1.01 if p.default else (p.low or 0) + ((p.high or 1.0) - (p.low or 0)) * 1e-6
    assert p.validate(value) == value and value != p.default, p.name
    return value


def test_every_parameter_round_trips():
    """Each declared parameter reads back a new value (what a node's descriptor table relies on).

    Hypothesis: setting any parameter to another valid value changes exactly that parameter; a configuration
    that ignored a key, or wrote it elsewhere, fails here.
    """
    cfg = SimConfig()
    before = cfg.to_parameters()
    for key, spec in PARAMETERS.items():
        value = another_valid_value(spec)
        if spec.relation and key == "pendulum_length":   # the rule with natural_frequency: the midpoint keeps it
            value = (spec.low + spec.high) / 2
        after = cfg.with_parameters({key: value}).to_parameters()
        assert after[key] == value, key
        assert {k for k in after if after[k] != before[k]} == {key}, key


def test_every_default_obeys_its_own_rule():
    """The declaration is consistent: each default passes the rule declared with it."""
    from rimd_sim.settings.config import NODE_PARAMETERS

    for table in (PARAMETERS, NODE_PARAMETERS):
        for name, p in table.items():
            assert p.validate(p.default) == p.default, name


def test_an_integer_is_accepted_where_a_real_number_is_meant():
    """`gap: 0`, `-p real_time_factor:=2`: an integer for a real parameter is converted, not refused."""
    cfg = SimConfig().with_parameters({"real_time_factor": 2, "gap": 0, "contact.stiffness": 6000000})
    assert cfg.real_time_factor == 2.0 and isinstance(cfg.real_time_factor, float)
    assert cfg.rig.contact.stiffness == 6e6 and isinstance(cfg.rig.contact.stiffness, float)


def test_yaml_errors_name_the_file_line_and_column(tmp_path):
    """Every YAML the product reads reports where it is broken, as a compiler would."""
    path = tmp_path / "rig.yaml"
    path.write_text("/**/rimd_simulator:\n  ros__parameters:\n    gap: 0.001\n    mass: [0.1\n")
    with pytest.raises(ConfigError, match=rf"config file is not valid YAML: {path}:5:1: "):
        load_config(path)


def test_a_key_given_twice_is_refused_where_it_is_given_again(tmp_path):
    """YAML forbids it, and PyYAML and ROS's parser would take the second value in silence: a config that sets
    ``gap`` twice is refused at the second, naming the first; the same key in two mappings is no repetition."""
    path = tmp_path / "rig.yaml"
    path.write_text("/**/rimd_simulator:\n  ros__parameters:\n    gap: 0.001\n    mass: 0.1\n    gap: 0.002\n"
                    "/**/rimd_recorder:\n  ros__parameters:\n    output_dir: out\n")
    with pytest.raises(ConfigError, match=rf"config file is not valid YAML: {path}:5:5: key 'gap' given twice "
                                          r"\(first on line 3\)"):
        load_config(path)
    path.write_text(path.read_text().replace("    gap: 0.002\n", ""))
    assert load_config(path).rig.gap == 0.001   # ros__parameters in both sections: each mapping's keys apart


def test_a_relative_config_is_found_from_anywhere(tmp_path, monkeypatch):
    """`rimd rig --config config/paper_model.yaml` typed outside the repository finds the shipped preset; a file
    found nowhere is refused saying where it was looked for."""
    from rimd_sim.settings.yaml_file import resolve_config

    monkeypatch.chdir(tmp_path)
    assert resolve_config("config/paper_model.yaml") == find_config_file("paper_model.yaml")
    (tmp_path / "mine.yaml").write_text("x: 1\n")
    assert resolve_config("mine.yaml") == tmp_path / "mine.yaml"          # the working directory first
    with pytest.raises(ConfigError) as refused:
        resolve_config("config/nope.yaml")
    message = str(refused.value)
    assert message.startswith("--config config/nope.yaml: not found; looked in ")
    assert str(tmp_path / "config" / "nope.yaml") in message and str(find_config_file().parent / "nope.yaml") in message
