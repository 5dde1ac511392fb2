"""The launch file ``rimd_sim/launch/rig.launch.xml`` brings up the rig of ``rimd rig``: checked statically.

``ros2 launch`` (launch, launch_ros) is not installable from the registry (docs/ros-install.md), so the file is read
here with xml.etree and its substitutions are evaluated by a small interpreter of the few it uses (``$(var)``,
``$(find-pkg-share)``, ``$(or)``, ``$(and)``, ``$(not)``; any other fails the test, so it cannot pass by ignoring
what it does not understand).

Hypotheses: every node it starts is an executable of the registry (rimd_sim/ros/nodes/registry.py), under the
registry's node name and namespace; the parameter file it names exists in rimd_sim/config and is installed; every
parameter it sets is declared by that node (rimd_sim/settings/params.py declarations); and for every combination of
its arguments ``record``, ``rerun`` and ``foxglove`` it starts the nodes that ``rimd rig`` plans
(:func:`rimd_sim.ros.bringup.plan_rig` with ``--no-record``, ``--no-rerun``, ``--foxglove``) with the same
parameter file and the same parameter values, but one: ``rimd rig`` starts the simulator paused and resumes it
once its consumers subscribe, which a launch file cannot do (``start_paused``, the file's comment says so).
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import yaml

from rimd_sim.ros.bringup import plan_rig
from rimd_sim.ros.nodes.registry import NODES, rig_nodes

LAUNCH = Path(__file__).resolve().parent.parent / "rimd_sim" / "launch" / "rig.launch.xml"
SHARE = "/opt/ros/jazzy/share/rimd_sim"   # what $(find-pkg-share rimd_sim) stands for here: mapped to the package


def _declared() -> dict[str, set[str]]:
    """The parameters each node declares, by executable (the tables the nodes declare; scripts/gen_docs.py's too)."""
    from rimd_sim.runtime.replay import ReplaySettings
    from rimd_sim.settings import config, recording
    from rimd_sim.settings.params import parameters
    from rimd_sim.viz import bridge_settings

    return {"rimd_simulator": {*config.PARAMETERS, *config.NODE_PARAMETERS}, "rimd_recorder": set(recording.PARAMETERS),
            "rimd_rerun": set(bridge_settings.PARAMETERS), "rimd_replay": set(parameters(ReplaySettings))}


# ---- a tiny interpreter of the launch file -------------------------------------------------------------------

_TRUE, _FALSE = ("true", "True", "1", "on"), ("false", "False", "0", "off")


def _boolean(text: str) -> bool:
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    raise ValueError(f"not a boolean for launch: {text!r}")


def _split_arguments(text: str) -> list[str]:
    """The space-separated arguments of a substitution, a nested ``$( )`` kept whole."""
    parts, depth, current = [], 0, ""
    for char in text.strip():
        if char == " " and depth == 0:
            if current:
                parts.append(current)
            current = ""
            continue
        depth += {"(": 1, ")": -1}.get(char, 0)
        current += char
    if current:
        parts.append(current)
    return parts


def substitute(text: str, args: dict[str, str]) -> str:
    """``text`` with its substitutions done as ros2 launch would (the ones this file uses)."""
    out, i = "", 0
    while i < len(text):
        if text.startswith("$(", i):
            depth, j = 0, i + 1
            while True:
                depth += {"(": 1, ")": -1}.get(text[j], 0)
                if depth == 0:
                    break
                j += 1
            name, _, rest = text[i + 2:j].partition(" ")
            values = [substitute(a, args) for a in _split_arguments(rest)]
            if name == "var":
                out += args[values[0]]
            elif name == "find-pkg-share":
                assert values == ["rimd_sim"], values
                out += SHARE
            elif name in ("or", "and"):
                assert len(values) == 2, f"$({name}) takes two arguments: {text}"
                left, right = (_boolean(v) for v in values)
                out += "true" if (left or right if name == "or" else left and right) else "false"
            elif name == "not":
                out += "false" if _boolean(values[0]) else "true"
            else:
                raise AssertionError(f"substitution $({name}) is not understood by this test: {text}")
            i = j + 1
        else:
            out += text[i]
            i += 1
    return out


def launch_arguments() -> dict[str, str]:
    """The ``<arg>`` defaults of the file."""
    root = ET.parse(LAUNCH).getroot()
    return {arg.get("name"): arg.get("default") for arg in root.iter("arg")}


def launched(overrides: dict[str, str]) -> dict[str, dict[str, Any]]:
    """The nodes ``ros2 launch rimd_sim rig.launch.xml ARG:=VALUE...`` starts, by executable (in file order)."""
    root = ET.parse(LAUNCH).getroot()
    assert root.tag == "launch"
    args = {name: default for name, default in launch_arguments().items()}
    unknown = set(overrides) - set(args)
    assert not unknown, f"arguments the launch file does not declare: {unknown}"
    args.update(overrides)
    args = {name: substitute(value, args) for name, value in args.items()}
    nodes = {}
    for node in root:
        if node.tag == "arg":
            continue
        assert node.tag == "node", f"unexpected element <{node.tag}>"
        if "if" in node.attrib and not _boolean(substitute(node.get("if"), args)):
            continue
        if "unless" in node.attrib and _boolean(substitute(node.get("unless"), args)):
            continue
        files, params = [], {}
        for param in node:
            assert param.tag == "param", f"unexpected <{param.tag}> in <node>"
            if "from" in param.attrib:
                files.append(substitute(param.get("from"), args))
            else:
                params[param.get("name")] = yaml.safe_load(substitute(param.get("value"), args))
        nodes[node.get("exec")] = {"pkg": node.get("pkg"), "name": node.get("name"),
                                   "namespace": node.get("namespace", "/"), "files": files, "params": params}
    return nodes


def _installed_path(path: str, repo_root: Path) -> Path:
    """A path under the installed share directory, as the file in the package that setup.py installs there."""
    assert path.startswith(SHARE + "/"), path
    return repo_root / "rimd_sim" / path[len(SHARE) + 1:]


# ---- the checks ----------------------------------------------------------------------------------------------


def test_the_interpreter_refuses_what_it_does_not_know():
    with pytest.raises(AssertionError, match=r"\$\(env\) is not understood"):
        substitute("$(env HOME)", {})
    assert substitute("$(or $(var a) $(not $(var b)))", {"a": "false", "b": "false"}) == "true"
    assert substitute("x/$(var a)/y", {"a": "1"}) == "x/1/y"


def test_every_node_is_an_executable_of_the_registry_under_its_name_and_namespace():
    registry = {node.executable: node for node in NODES}
    nodes = launched({"record": "true", "rerun": "true", "foxglove": "true"})
    assert nodes, "the launch file starts nothing"
    for executable, node in nodes.items():
        assert node["pkg"] == "rimd_sim"
        assert executable in registry, f"{executable} is not a console script of the registry"
        assert node["name"] == executable, "the registry's executable is also the node's name"
        assert node["namespace"] == registry[executable].namespace, executable
    # The console scripts of setup.py are the registry's (tests/test_packaging.py checks they are installed).
    assert {n.executable for n in rig_nodes()} == set(nodes)


def test_the_parameter_file_exists_and_is_installed(repo_root):
    defaults = launch_arguments()
    config = substitute(defaults["config"], {})
    assert config == f"{SHARE}/config/rimd.yaml"
    source = _installed_path(config, repo_root)
    assert source.is_file(), source
    assert source.parent == repo_root / "rimd_sim" / "config"   # setup.py installs config/*.yaml to share/rimd_sim
    for node in launched({}).values():
        assert node["files"] == [config]


def test_every_parameter_it_sets_is_declared_by_the_node():
    declared = _declared()
    for executable, node in launched({"record": "true", "rerun": "true", "foxglove": "true"}).items():
        unknown = set(node["params"]) - declared[executable]
        assert not unknown, f"{executable} declares no parameter {sorted(unknown)}"


def _plan_parameters(args: tuple[str, ...]) -> dict[str, Any]:
    values = {}
    for flag, value in zip(args, args[1:], strict=False):
        if flag == "-p":
            name, _, text = value.partition(":=")
            values[name] = yaml.safe_load(text)
    return values


@pytest.mark.parametrize(("record", "rerun", "foxglove"), list(itertools.product((True, False), repeat=3)))
def test_it_brings_up_what_rimd_rig_plans(repo_root, tmp_path, record, rerun, foxglove):
    config = repo_root / "rimd_sim" / "config" / "rimd.yaml"
    plan = plan_rig(config, output_dir=tmp_path / "rec", record=record, rerun=rerun, foxglove=foxglove)
    nodes = launched({"record": str(record).lower(), "rerun": str(rerun).lower(), "foxglove": str(foxglove).lower(),
                      "output_dir": str(tmp_path / "rec")})
    assert [(n.name, n.namespace) for n in plan.nodes] == [(e, nodes[e]["namespace"]) for e in nodes], \
        "the same nodes, in the same order (consumers first, the simulator last)"
    sections = yaml.safe_load(config.read_text())
    for planned in plan.nodes:
        node = nodes[planned.name]
        files = [str(_installed_path(f, repo_root)) for f in node["files"]]
        pairs = zip(planned.args, planned.args[1:], strict=False)
        assert files == [value for flag, value in pairs if flag == "--params-file"]
        planned_values = _plan_parameters(planned.args)
        if planned.name == "rimd_simulator":   # rimd rig resumes it once the consumers subscribe; a launch cannot
            assert planned_values.pop("start_paused", False) == any(n.consumer for n in plan.nodes) == record
            assert node["params"].pop("start_paused") is False
        if "output_dir" in planned_values:
            assert Path(planned_values.pop("output_dir")) == Path(node["params"].pop("output_dir")).resolve()
        # The values rimd rig gives; a parameter it leaves to the file has the file's value in the launch too.
        in_file = sections.get(f"/**/{planned.name}", {}).get("ros__parameters", {})
        for name, value in node["params"].items():
            expected = planned_values.pop(name) if name in planned_values else _flat(in_file).get(name)
            assert value == expected, f"{planned.name}: {name} = {value!r}, rimd rig: {expected!r}"
        assert not planned_values, f"{planned.name}: rimd rig sets {planned_values}, the launch file does not"


def _flat(section: dict, prefix: str = "") -> dict[str, Any]:
    out = {}
    for key, value in section.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out

