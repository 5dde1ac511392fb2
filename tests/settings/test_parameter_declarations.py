"""Every parameter of every node against its one declaration (rimd_sim.settings.params), without ROS: the rule sweep.

Hypotheses, for each parameter of the simulator (its configuration and its node settings), the recorder, the
replay and the Rerun bridge, with the cases generated from the declaration itself (type, bounds, choices, the
values that break its extra rule):

- a value of another type, NaN, an infinity, a subnormal number, a number beyond a bound, a string outside the
  choices, a value that breaks the extra rule: refused with a ``ConfigError`` that names the key and says "must";
- a value within the rule (the default, the bounds that are inclusive, a value between them, every choice, an
  integer where a real number is meant) is accepted and comes back converted, unchanged;
- the default obeys its own rule.

And "adding a parameter is one edit" (docs/architecture.md): a settings class with one field more, made at run
time, gives the parameter to the configuration, to the node's descriptors and its set-time validation (the real recorder
node in this process), and to the generated documentation table.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rimd_sim.errors import ConfigError
from rimd_sim.runtime.replay import ReplaySettings
from rimd_sim.settings.config import NODE_PARAMETERS
from rimd_sim.settings.config import PARAMETERS as SIMULATOR
from rimd_sim.settings.params import Param, build, param, parameters
from rimd_sim.settings.recording import PARAMETERS as RECORDER
from rimd_sim.viz.bridge_settings import PARAMETERS as BRIDGE

TABLES = {"simulator": {**SIMULATOR, **NODE_PARAMETERS}, "recorder": RECORDER,
          "replay": parameters(ReplaySettings), "rerun": BRIDGE}
ALL = [(node, name) for node, table in TABLES.items() for name in table]
SWEEP = settings(max_examples=25, derandomize=True, database=None, deadline=None,
                 suppress_health_check=list(HealthCheck))


def bad_values(p: Param) -> st.SearchStrategy:
    """Values the declaration of ``p`` refuses."""
    others = {"bool": st.booleans(), "int": st.integers(-10**6, 10**6), "float": st.floats(allow_nan=False),
              "str": st.text(max_size=5), "str[]": st.lists(st.text(max_size=3), max_size=2)}
    wrong_type = [s for kind, s in others.items()
                  if kind != p.kind and not (p.kind == "float" and kind == "int")] + [st.none()]
    options = [st.one_of(wrong_type)]
    if p.kind == "float":
        options.append(st.sampled_from([math.nan, math.inf, -math.inf, 5e-324, -1e-310]))
    if p.kind == "float":
        finite = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}
        for bound, below, inclusive in ((p.ge, True, True), (p.gt, True, False), (p.le, False, True),
                                        (p.lt, False, False)):
            if bound is not None:   # beyond the bound (the bound itself when it is excluded)
                options.append(st.floats(max_value=bound, exclude_max=inclusive, **finite) if below
                               else st.floats(min_value=bound, exclude_min=inclusive, **finite))
    if p.kind == "int":
        for bound, below, inclusive in ((p.ge, True, True), (p.gt, True, False), (p.le, False, True),
                                        (p.lt, False, False)):
            if bound is not None:
                edge = int(bound) + (0 if not inclusive else (-1 if below else 1))
                options.append(st.integers(max_value=edge) if below else st.integers(min_value=edge))
    if p.choices:
        options.append(st.text(max_size=12).filter(lambda v: v not in p.choices))
    if p.breaks:
        options.append(st.sampled_from(p.breaks))
    strategy = st.one_of(options)
    if p.zero:
        strategy = strategy.filter(lambda v: v != 0 or isinstance(v, (bool, str, list)) or v is None)
    return strategy


def good_values(p: Param) -> list:
    """Values the declaration of ``p`` accepts (beyond its default)."""
    values = [p.default]
    if p.kind in ("float", "int"):
        low, high = p.low, p.high
        for bound in (p.ge, p.le):   # the inclusive bounds
            if bound is not None:
                values.append(int(bound) if p.kind == "int" else float(bound))
        if low is not None and high is not None:
            values.append((low + high) / 2 if p.kind == "float" else int((low + high) // 2))
        if p.zero:
            values.append(0.0)
        if p.kind == "float" and p.default == int(p.default) and abs(p.default) < 2**53:
            values.append(int(p.default))   # an integer where a real number is meant
    values += list(p.choices)
    return values


@pytest.mark.parametrize(("node", "name"), ALL, ids=[f"{n}:{k}" for n, k in ALL])
def test_the_declaration_refuses_what_breaks_its_rule_and_accepts_what_keeps_it(node, name):
    p = TABLES[node][name]

    @SWEEP
    @given(bad_values(p))
    def refused(value) -> None:
        with pytest.raises(ConfigError) as info:
            p.validate(value)
        text = str(info.value)
        assert f"parameter '{name}' = " in text and "refused: must" in text, text

    refused()
    for value in good_values(p):
        kept = p.validate(value)
        assert kept == (tuple(value) if isinstance(value, list) else value)
        assert type(kept) is (float if p.kind == "float" else tuple if p.kind == "str[]" else type(p.default))


def test_the_sweep_covers_every_node_and_enough_parameters():
    assert {node for node, _ in ALL} == {"simulator", "recorder", "replay", "rerun"}
    assert len(ALL) > 120 and all(p.description for table in TABLES.values() for p in table.values())


# ---- one edit ---------------------------------------------------------------------------------------------------

def test_adding_a_parameter_is_one_edit(rclpy_context, tmp_path, monkeypatch):
    """A field declared with param() in the recorder's settings class, and nothing else."""
    import rimd_sim.ros.nodes.recorder as recorder_module
    from rimd_sim.settings.recording import RecorderSettings

    extended = dataclasses.make_dataclass(
        "ExtendedRecorderSettings",
        [("ring_buffer", float, param(2.5, "seconds kept in memory before writing", unit="s", gt=0, le=60,
                                      read_only=True))],
        bases=(RecorderSettings,), frozen=True)
    table = parameters(extended)
    # The configuration.
    assert build(extended, {"ring_buffer": 4}).ring_buffer == 4.0
    with pytest.raises(ConfigError, match=r"'ring_buffer' = 0.0 refused: must be > 0 and <= 60 s"):
        build(extended, {"ring_buffer": 0.0})
    # The node's descriptors and validation: the real recorder node, built from the extended declaration.
    monkeypatch.setattr(recorder_module, "RecorderSettings", extended)
    monkeypatch.setattr(recorder_module, "PARAMETERS", table)
    node = recorder_module.RecorderNode(context=rclpy_context, parameter_overrides=[],
                                        cli_args=["--ros-args", "-p", f"output_dir:={tmp_path}",
                                                  "-p", "ring_buffer:=7.0"])
    try:
        descriptor = node.describe_parameter("ring_buffer")
        assert descriptor.read_only and descriptor.additional_constraints == "must be > 0 and <= 60 s"
        assert "seconds kept in memory before writing [s]" in descriptor.description
        assert node._p.ring_buffer == 7.0
    finally:
        node.shutdown()
        node.destroy_node()
    # The generated documentation table.
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
    try:
        import gen_docs
    finally:
        sys.path.pop(0)
    row = [line for line in gen_docs.parameter_table(table).splitlines() if line.startswith("| `ring_buffer`")]
    assert row == ["| `ring_buffer` | `2.5` | float | s | must be > 0 and <= 60 s | seconds kept in memory before "
                   "writing (read at start) |"]


# ---- every rule in the documentation ---------------------------------------------------------------------------

ROOT = Path(__file__).resolve().parents[2]
#: The page that documents each node's parameters (the generated tables of scripts/gen_docs.py).
PAGES = {"simulator": "docs/configuration.md", "recorder": "docs/recording.md", "replay": "docs/recording.md",
         "rerun": "docs/rerun.md"}


def _refused_in_post_init(cls: type) -> set[str]:
    """The parameters the ``__post_init__`` of ``cls`` and of its groups names: the rules between fields.

    Every string constant of those methods' source that is a parameter's full name, or the tail of one after its
    group's prefix (``"range_max"`` of ``channels.<name>.range_max``).
    """
    import ast
    import inspect
    import textwrap

    names = parameters(cls)
    found: set[str] = set()
    seen: set[type] = set()

    def visit(klass: type) -> None:
        if klass in seen or not dataclasses.is_dataclass(klass):
            return
        seen.add(klass)
        if "__post_init__" in vars(klass):
            tree = ast.parse(textwrap.dedent(inspect.getsource(vars(klass)["__post_init__"])))
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and isinstance(node.value, str):
                    found.update(n for n in names if n == node.value or n.endswith("." + node.value))
        for f in dataclasses.fields(klass):
            default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
            for item in default if isinstance(default, tuple) else (default,):
                if dataclasses.is_dataclass(item):
                    visit(type(item))

    visit(cls)
    return found


def test_every_rule_between_fields_is_declared_on_the_parameter_it_refuses():
    """A refusal from a ``__post_init__`` names a parameter whose declaration says the rule (``relation``)."""
    from rimd_sim.settings.config import SimConfig, SimulatorNodeSettings
    from rimd_sim.settings.recording import RecorderSettings
    from rimd_sim.viz.bridge_settings import BridgeSettings

    checked = 0
    for cls in (SimConfig, SimulatorNodeSettings, RecorderSettings, ReplaySettings, BridgeSettings):
        refused = _refused_in_post_init(cls)
        table = parameters(cls)
        missing = sorted(name for name in refused if not table[name].relation)
        assert not missing, f"{cls.__name__}: rules between fields not declared (relation=...): {missing}"
        checked += len(refused)
    # The rules of the rig that users meet: the gap's l/2, the spring's, the motor's ceiling, the channels'.
    for name in ("gap", "pendulum_length", "structure.impactor_mass", "motor.initial_setpoint",
                 "channels.impact_force.range_max", "channels.impact_force.highpass", "lockstep.consumers"):
        assert name in _refused_in_post_init(SimConfig) | _refused_in_post_init(SimulatorNodeSettings), name
    assert checked >= 10


@pytest.mark.parametrize(("node", "name"), ALL, ids=[f"{n}:{k}" for n, k in ALL])
def test_every_rule_of_every_parameter_is_in_its_documentation(node, name):
    """The whole rule, the bounds, the choices, the extra rule and the relation, in the node's page."""
    p = TABLES[node][name]
    page = (ROOT / PAGES[node]).read_text(encoding="utf-8")
    rule = " ".join(p.rule.split()).replace("|", "\\|")
    if name.startswith("channels."):   # one row per field of every channel
        assert rule in page, f"{PAGES[node]} lacks the rule of {name}: {rule!r}"
    else:
        rows = [line for line in page.splitlines() if line.startswith(f"| `{name}` |")]
        assert rows and rule in rows[0], f"{PAGES[node]} lacks the rule of {name}: {rule!r}"
