"""The launch file ``rimd_sim/launch/rig.launch.xml`` brings up the rig of ``rimd rig``: checked statically.

``ros2 launch`` (launch, launch_ros) is not installable from the registry (docs/ros-install.md), so the file is read
here with xml.etree and its substitutions are evaluated by a small interpreter of the few it uses (``$(var)``,
``$(find-pkg-share)``, ``$(or)``, ``$(and)``, ``$(not)``, ``<let>``, a node's ``args`` split on white space as
launch_ros does; any other fails the test, so it cannot pass by ignoring what it does not understand).

Hypotheses: every node it starts is an executable of the registry (rimd_sim/ros/nodes/registry.py), under the
registry's node name and namespace, but the composed rig (``rimd_composed``), which has neither: launch would
remap every node of its process to them; the parameter file it names exists in rimd_sim/config and is installed;
every parameter it sets is declared by the node it sets it on (rimd_sim/settings/params.py declarations); and for
every combination of its arguments ``record``, ``rerun``, ``foxglove`` and ``separate`` it starts the processes
that ``rimd rig`` plans (:attr:`rimd_sim.ros.bringup.RigPlan.processes` of :func:`~rimd_sim.ros.bringup.plan_rig`
with ``--no-record``, ``--no-rerun``, ``--foxglove``, ``--separate``): by default the composed rig, one process,
with the same nodes, the same parameter file and the same parameter values, but one: ``rimd rig`` with separate
processes starts the simulator paused and resumes it once its consumers subscribe, which a launch file cannot do
(``start_paused``, the file's comment says so).
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


#: The composed rig's executable: one process, the simulator with the recorder and the bridge.
COMPOSED = "rimd_composed"


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
        if node.tag == "let":   # in file order, as launch sets them
            assert set(node.attrib) == {"name", "value"}, node.attrib
            args[node.get("name")] = substitute(node.get("value"), args)
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
        known = {"pkg", "exec", "name", "namespace", "output", "if", "unless", "args"}
        assert set(node.attrib) <= known, f"attributes this test does not understand: {set(node.attrib) - known}"
        nodes[node.get("exec")] = {"pkg": node.get("pkg"), "name": node.get("name"),
                                   "namespace": node.get("namespace"), "files": files, "params": params,
                                   "args": substitute(node.get("args", ""), args).split()}
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


def _composed_args(args: list[str] | tuple[str, ...]) -> tuple[dict[str, bool], dict[str, dict[str, Any]]]:
    """``--record``, ``--bridge`` and the ``--param NODE:NAME:=VALUE`` of a composed rig's command line."""
    args = list(args)
    args = args[:args.index("--ros-args")] if "--ros-args" in args else args
    assert len(args) % 2 == 0, args
    flags: dict[str, bool] = {}
    params: dict[str, dict[str, Any]] = {}
    for flag, value in zip(args[::2], args[1::2], strict=True):
        if flag in ("--record", "--bridge"):
            flags[flag[2:]] = _boolean(value)
        else:
            assert flag == "--param", f"{COMPOSED} has no option {flag}"
            node, _, rest = value.partition(":")
            name, _, text = rest.partition(":=")
            params.setdefault(node, {})[name] = yaml.safe_load(text)
    return flags, params


def _composed_nodes(flags: dict[str, bool]) -> list[str]:
    """The nodes a composed rig runs, in ``rimd rig``'s order (consumers first, the simulator last)."""
    return [*(["rimd_recorder"] if flags["record"] else []), *(["rimd_rerun"] if flags["bridge"] else []),
            "rimd_simulator"]


def launched_processes(overrides: dict[str, str]) -> dict[str, dict[str, Any]]:
    """The processes the launch starts, by executable: the nodes each runs, their parameter files, their values.

    The composed rig's ``--param`` values of a node it does not run are left out: it ignores them.
    """
    out = {}
    for executable, node in launched(overrides).items():
        if executable == COMPOSED:
            flags, params = _composed_args(node["args"])
            nodes = _composed_nodes(flags)
            assert not node["params"], f"a <param name=...> of {COMPOSED} would set it on every node of the process"
            out[executable] = {"nodes": nodes, "files": node["files"],
                               "params": {n: params.get(n, {}) for n in nodes}}
        else:
            assert not node["args"], executable
            out[executable] = {"nodes": [executable], "files": node["files"], "params": {executable: node["params"]}}
    return out


ALL = {"record": "true", "rerun": "true", "foxglove": "true"}


@pytest.mark.parametrize("separate", ["true", "false"])
def test_every_node_is_an_executable_of_the_registry_under_its_name_and_namespace(separate):
    registry = {node.executable: node for node in NODES}
    nodes = launched({**ALL, "separate": separate})
    assert nodes, "the launch file starts nothing"
    for executable, node in nodes.items():
        assert node["pkg"] == "rimd_sim"
        assert executable in registry, f"{executable} is not a console script of the registry"
        if executable == COMPOSED:   # a name or a namespace would be remapped onto every node of the process
            assert node["name"] is None and node["namespace"] is None, node
            continue
        assert node["name"] == executable, "the registry's executable is also the node's name"
        assert node["namespace"] == registry[executable].namespace, executable
    # The console scripts of setup.py are the registry's (tests/test_packaging.py checks they are installed).
    started = [n for p in launched_processes({**ALL, "separate": separate}).values() for n in p["nodes"]]
    assert sorted(n.executable for n in rig_nodes()) == sorted(started)
    assert (COMPOSED in nodes) == (separate == "false"), "the composed rig by default, separate:=true: one per node"
    assert list(launched({})) == [COMPOSED], "by default, as rimd rig: the composed rig"


def test_the_parameter_file_exists_and_is_installed(repo_root):
    defaults = launch_arguments()
    config = substitute(defaults["config"], {})
    assert config == f"{SHARE}/config/rimd.yaml"
    source = _installed_path(config, repo_root)
    assert source.is_file(), source
    assert source.parent == repo_root / "rimd_sim" / "config"   # setup.py installs config/*.yaml to share/rimd_sim
    for separate in ("true", "false"):
        for node in launched({"separate": separate}).values():
            assert node["files"] == [config]


@pytest.mark.parametrize("separate", ["true", "false"])
def test_every_parameter_it_sets_is_declared_by_the_node(separate):
    declared = _declared()
    for process in launched_processes({**ALL, "separate": separate}).values():
        for executable, params in process["params"].items():
            unknown = set(params) - declared[executable]
            assert not unknown, f"{executable} declares no parameter {sorted(unknown)}"


def test_the_composed_rig_parses_the_arguments_the_launch_gives_it():
    """Its command line is the one :mod:`rimd_sim.ros.nodes.composed` parses (its own parser, not this test's)."""
    composed = pytest.importorskip("rimd_sim.ros.nodes.composed")
    node = launched(ALL)[COMPOSED]
    options, ros_args = composed.parse_arguments(node["args"])
    assert (options.record, options.bridge) == (True, True)
    flags, params = _composed_args(node["args"])
    assert {(n, p.name, p.value) for n, p in options.param} == \
        {(n, name, value) for n, values in params.items() for name, value in values.items()}
    assert ros_args == []


def _plan_processes(plan) -> dict[str, dict[str, Any]]:
    """The processes ``rimd rig`` starts for ``plan``, in the form of :func:`launched_processes`."""
    out = {}
    for process in plan.processes:
        pairs = list(zip(process.args, process.args[1:], strict=False))
        files = [value for flag, value in pairs if flag == "--params-file"]
        if process.name == COMPOSED:
            flags, params = _composed_args(process.args)
            nodes = _composed_nodes(flags)
            out[process.name] = {"nodes": nodes, "files": files, "params": {n: params.get(n, {}) for n in nodes}}
        else:
            out[process.name] = {"nodes": [process.name], "files": files,
                                 "params": {process.name: _plan_parameters(process.args)}}
    return out


def _plan_parameters(args: tuple[str, ...]) -> dict[str, Any]:
    values = {}
    for flag, value in zip(args, args[1:], strict=False):
        if flag == "-p":
            name, _, text = value.partition(":=")
            values[name] = yaml.safe_load(text)
    return values


@pytest.mark.parametrize(("record", "rerun", "foxglove", "separate"),
                         list(itertools.product((True, False), repeat=4)))
def test_it_brings_up_what_rimd_rig_plans(repo_root, tmp_path, record, rerun, foxglove, separate):
    config = repo_root / "rimd_sim" / "config" / "rimd.yaml"
    plan = plan_rig(config, output_dir=tmp_path / "rec", record=record, rerun=rerun, foxglove=foxglove,
                    separate=separate)
    processes = launched_processes({"record": str(record).lower(), "rerun": str(rerun).lower(),
                                    "foxglove": str(foxglove).lower(), "separate": str(separate).lower(),
                                    "output_dir": str(tmp_path / "rec")})
    planned = _plan_processes(plan)
    assert list(planned) == list(processes), "the same processes, in the same order (consumers first)"
    assert [n.name for n in plan.nodes] == [n for p in processes.values() for n in p["nodes"]], "the same nodes"
    sections = yaml.safe_load(config.read_text())
    for name, process in processes.items():
        files = [str(_installed_path(f, repo_root)) for f in process["files"]]
        assert files == planned[name]["files"]
        for node, params in process["params"].items():
            planned_values = dict(planned[name]["params"][node])
            params = dict(params)
            if node == "rimd_simulator":   # rimd rig resumes separate ones once the consumers subscribe
                assert planned_values.pop("start_paused", False) == (separate and any(n.consumer for n in plan.nodes))
                assert params.pop("start_paused") is False
            if "output_dir" in planned_values:
                assert Path(planned_values.pop("output_dir")) == Path(params.pop("output_dir")).resolve()
            # The values rimd rig gives; a parameter it leaves to the file has the file's value in the launch too.
            in_file = sections.get(f"/**/{node}", {}).get("ros__parameters", {})
            for param, value in params.items():
                expected = planned_values.pop(param) if param in planned_values else _flat(in_file).get(param)
                assert value == expected, f"{node}: {param} = {value!r}, rimd rig: {expected!r}"
            assert not planned_values, f"{node}: rimd rig sets {planned_values}, the launch file does not"


def _flat(section: dict, prefix: str = "") -> dict[str, Any]:
    out = {}
    for key, value in section.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out

