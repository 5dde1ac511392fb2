"""Bad input over DDS: every parameter and every service of every node, called with wrong values, refused.

The rule sweep (every kind of wrong value against every parameter's one declaration, thousands of cases) runs
without ROS in tests/settings/test_parameter_declarations.py. Here each node runs in its own process and the wiring is
proven: every parameter it declares (enumerated at run time with ``list_parameters``, typed with
``describe_parameters``) set through rclpy's parameter services with wrong values generated from its
declaration (a value of another type, NaN for a real number, a value beyond a bound, outside the choices, one
that breaks the extra rule; any value for a parameter read at start) and unknown names, unset values, is
refused with a reason that names the parameter and a rule; afterwards the value and the descriptor are what
they were and the node still runs and publishes; every service called with a wrong value or in a wrong state
is refused with a message naming the field or the state, and changes nothing; valid values are accepted.
The number of cases is printed: ``bad input: N cases (simulator a, recorder b, replay c, rerun d)``.
"""

from __future__ import annotations

import math
import re
import string
from collections.abc import Callable
from typing import Any

import pytest
from builtin_interfaces.msg import Time
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters, SetParametersAtomically
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.ros import call_service, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(240)]

T = ParameterType
#: Words of a rule in a refusal: the node's own rules say "must ..." or "cannot ...", rclpy's say "out of range"
#: (with the bounds) or "read-only"; an unknown name is "not a parameter".
RULE_WORDS = ("must", "cannot", "out of range", "read-only", "read at start", "not a parameter")
#: Cases per node: bad input (refused) and valid input (accepted), printed at the end of the module.
COUNTS: dict[str, dict[str, int]] = {}


def _settings(examples: int) -> settings:
    return settings(max_examples=examples, derandomize=True, database=None, deadline=None,
                    suppress_health_check=list(HealthCheck))


def _count(node: str, kind: str = "bad") -> None:
    COUNTS.setdefault(node, {"bad": 0, "valid": 0})[kind] += 1


@pytest.fixture(scope="module", autouse=True)
def _report_counts(request: pytest.FixtureRequest):
    """At the end of the module, the number of cases on the terminal (also without ``-s``)."""
    yield
    if COUNTS:
        bad = {name: c["bad"] for name, c in COUNTS.items()}
        parts = ", ".join(f"{name} {bad.get(name, 0)}" for name in ("simulator", "recorder", "replay", "rerun"))
        line = (f"bad input: {sum(bad.values())} cases ({parts}); valid input accepted: "
                f"{sum(c['valid'] for c in COUNTS.values())} cases")
        capture = request.config.pluginmanager.get_plugin("capturemanager")
        if capture is not None:
            with capture.global_and_fixture_disabled():
                print("\n" + line)
        else:
            print(line)


# ---- values of every parameter type ------------------------------------------------------------------------

def pv(kind: int, value: Any = None) -> ParameterValue:
    """A ParameterValue of ``kind`` holding ``value``."""
    field = {T.PARAMETER_BOOL: "bool_value", T.PARAMETER_INTEGER: "integer_value", T.PARAMETER_DOUBLE: "double_value",
             T.PARAMETER_STRING: "string_value", T.PARAMETER_BYTE_ARRAY: "byte_array_value",
             T.PARAMETER_BOOL_ARRAY: "bool_array_value", T.PARAMETER_INTEGER_ARRAY: "integer_array_value",
             T.PARAMETER_DOUBLE_ARRAY: "double_array_value", T.PARAMETER_STRING_ARRAY: "string_array_value"}
    msg = ParameterValue(type=kind)
    if kind != T.PARAMETER_NOT_SET:
        setattr(msg, field[kind], value)
    return msg


def show(value: ParameterValue) -> str:
    """A short description of a ParameterValue, for assertion messages."""
    for name in ("bool_value", "integer_value", "double_value", "string_value", "byte_array_value",
                 "bool_array_value", "integer_array_value", "double_array_value", "string_array_value"):
        kind = getattr(T, "PARAMETER_" + name.removesuffix("_value").upper())
        if value.type == kind:
            return f"{name[:-6]} {getattr(value, name)!r}"
    return "not set"


_TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc")), max_size=12)
_INT64 = st.integers(-2**63, 2**63 - 1)
#: Any value of each type (arrays short: what matters is the type).
ANY_OF_TYPE: dict[int, st.SearchStrategy[ParameterValue]] = {
    T.PARAMETER_NOT_SET: st.just(pv(T.PARAMETER_NOT_SET)),
    T.PARAMETER_BOOL: st.booleans().map(lambda v: pv(T.PARAMETER_BOOL, v)),
    T.PARAMETER_INTEGER: _INT64.map(lambda v: pv(T.PARAMETER_INTEGER, v)),
    T.PARAMETER_DOUBLE: st.floats().map(lambda v: pv(T.PARAMETER_DOUBLE, v)),
    T.PARAMETER_STRING: _TEXT.map(lambda v: pv(T.PARAMETER_STRING, v)),
    T.PARAMETER_BYTE_ARRAY: st.lists(st.binary(min_size=1, max_size=1), max_size=3).map(
        lambda v: pv(T.PARAMETER_BYTE_ARRAY, v)),
    T.PARAMETER_BOOL_ARRAY: st.lists(st.booleans(), max_size=3).map(lambda v: pv(T.PARAMETER_BOOL_ARRAY, v)),
    T.PARAMETER_INTEGER_ARRAY: st.lists(_INT64, max_size=3).map(lambda v: pv(T.PARAMETER_INTEGER_ARRAY, v)),
    T.PARAMETER_DOUBLE_ARRAY: st.lists(st.floats(), max_size=3).map(lambda v: pv(T.PARAMETER_DOUBLE_ARRAY, v)),
    T.PARAMETER_STRING_ARRAY: st.lists(_TEXT, max_size=3).map(lambda v: pv(T.PARAMETER_STRING_ARRAY, v)),
}
#: Canonical values of other types, tried first (explicit examples) for every parameter.
CANONICAL = [pv(T.PARAMETER_NOT_SET), pv(T.PARAMETER_BOOL, True), pv(T.PARAMETER_INTEGER, 2**62),
             pv(T.PARAMETER_INTEGER, -1), pv(T.PARAMETER_DOUBLE, math.nan), pv(T.PARAMETER_DOUBLE, math.inf),
             pv(T.PARAMETER_DOUBLE, -math.inf), pv(T.PARAMETER_DOUBLE, 1e300), pv(T.PARAMETER_DOUBLE, -1e300),
             pv(T.PARAMETER_DOUBLE, 5e-324), pv(T.PARAMETER_STRING, ""), pv(T.PARAMETER_STRING, "abc"),
             pv(T.PARAMETER_DOUBLE_ARRAY, [1.0]), pv(T.PARAMETER_STRING_ARRAY, ["x"])]


def other_types(kind: int, *, but: tuple[int, ...] = ()) -> st.SearchStrategy[ParameterValue]:
    """Values of every type except ``kind`` (and ``but``)."""
    return st.one_of([s for k, s in ANY_OF_TYPE.items() if k != kind and k not in but])


def wrong_values(kind: int, spec: Any | None, fixed: bool) -> list[ParameterValue]:
    """Values that a parameter of ROS type ``kind`` must refuse, from its declaration ``spec`` (a Param, or None).

    ``fixed``: the parameter cannot change at run time (read at start), so every value is wrong: the canonical
    values of every type. Otherwise: values of other types, and the rule's own breakers.
    """
    if fixed:
        return list(CANONICAL)
    # An integer is a number for a real parameter (it is checked against the bounds below, as a real number).
    values = [v for v in CANONICAL if v.type != kind and not (kind == T.PARAMETER_DOUBLE
                                                              and v.type == T.PARAMETER_INTEGER)]
    if kind == T.PARAMETER_DOUBLE:
        values += [pv(kind, v) for v in (math.nan, math.inf, -math.inf, 5e-324)]
        if spec is not None:
            if spec.low is not None:   # below the low bound (halfway to 0 where 0 itself is allowed)
                values.append(pv(kind, spec.low / 2 if spec.zero and spec.low > 0 else
                                 spec.low - max(1.0, abs(spec.low))))
            if spec.high is not None:
                values.append(pv(kind, spec.high + max(1.0, abs(spec.high))))
            if spec.gt is not None and not (spec.zero and spec.gt == 0):
                values.append(pv(kind, float(spec.gt)))
    elif kind == T.PARAMETER_INTEGER and spec is not None:
        for bound, step in ((spec.low, -1), (spec.high, 1)):
            if bound is not None:
                values.append(pv(kind, int(bound) + step))
    elif kind == T.PARAMETER_STRING:
        values.append(pv(kind, ""))
        if spec is not None and spec.choices:
            values.append(pv(kind, "abc"))
        # A NUL cannot travel in a ROS string (it ends there): such breakers are for the rule sweep only.
        values += [pv(kind, b) for b in (spec.breaks if spec is not None else ())
                   if isinstance(b, str) and "\0" not in b]
    return values


UNKNOWN_NAMES = st.text(alphabet=string.ascii_letters + string.digits + "._/", min_size=1, max_size=24)


def names_parameter(reason: str, name: str) -> bool:
    """Whether ``reason`` names ``name`` (as a whole name: 'gap' is not named by 'gap_x' or 'a.gap')."""
    return f"'{name}'" in reason or re.search(rf"(?<![\w.]){re.escape(name)}(?!\w|\.\w)", reason) is not None


# ---- the parameter services of one node ----------------------------------------------------------------------

class ParameterApi:
    """rclpy's parameter services of the node ``target`` (fully qualified), called from the test's node."""

    def __init__(self, executor: Any, node: Any, target: str) -> None:
        self.executor, self.node, self.target = executor, node, target
        self._clients = {srv: node.create_client(srv, f"{target}/{name}") for srv, name in (
            (ListParameters, "list_parameters"), (DescribeParameters, "describe_parameters"),
            (GetParameters, "get_parameters"), (SetParameters, "set_parameters"),
            (SetParametersAtomically, "set_parameters_atomically"))}

    def _call(self, srv: Any, request: Any) -> Any:
        return call_service(self.executor, self.node, self._clients[srv], request, timeout=10)

    def names(self) -> list[str]:
        return list(self._call(ListParameters, ListParameters.Request()).result.names)

    def describe(self, names: list[str]) -> dict[str, Any]:
        return dict(zip(names, self._call(DescribeParameters, DescribeParameters.Request(names=names)).descriptors,
                        strict=True))

    def get(self, names: list[str]) -> dict[str, ParameterValue]:
        return dict(zip(names, self._call(GetParameters, GetParameters.Request(names=names)).values, strict=True))

    def set(self, name: str, value: ParameterValue) -> Any:
        request = SetParameters.Request(parameters=[Parameter(name=name, value=value)])
        return self._call(SetParameters, request).results[0]

    def set_atomically(self, params: list[tuple[str, ParameterValue]]) -> Any:
        request = SetParametersAtomically.Request(parameters=[Parameter(name=n, value=v) for n, v in params])
        return self._call(SetParametersAtomically, request).result


def check_bad_parameters(api: ParameterApi, node: str, *, specs: dict[str, Any], fixed: Callable[[str, Any], bool],
                         alive: Callable[[], None], examples: int,
                         progress: Callable[[], None] = lambda: None, progress_every: int = 1) -> list[str]:
    """Set every parameter of ``api``'s node to wrong values, and unknown names; check each refusal.

    ``fixed(name, descriptor)``: the parameter cannot change at run time. ``alive()`` asserts, after each
    case, that the node still runs (and publishes, where that is quick to see); ``progress()``, after every
    ``progress_every``-th parameter and after the last, that its output advanced (for nodes whose output is slow
    to observe: the recorder reports its count once a second). Returns the names.
    """
    names = api.names()
    assert names, f"{api.target} declares no parameter"
    descriptors = api.describe(names)
    initial = api.get(names)
    def property_of(name: str) -> Callable[[ParameterValue], None]:
        def refused(value: ParameterValue) -> None:
            _count(node)
            result = api.set(name, value)
            what = f"{api.target}: {name} = {show(value)}"
            assert not result.successful, f"{what} was accepted"
            assert names_parameter(result.reason, name), f"{what}: the refusal does not name it: {result.reason!r}"
            assert any(w in result.reason for w in RULE_WORDS), f"{what}: no rule in {result.reason!r}"
            assert api.get([name])[name] == initial[name], f"{what}: the value changed after a refusal"
            assert api.describe([name])[name] == descriptors[name], f"{what}: the descriptor changed"
            alive()
        return refused

    for number, name in enumerate(names, 1):
        descriptor = descriptors[name]
        refused = property_of(name)
        for value in wrong_values(descriptor.type, specs.get(name), fixed(name, descriptor)):
            refused(value)
        if number % progress_every == 0 or number == len(names):
            progress()

    @_settings(examples)
    @example("", pv(T.PARAMETER_DOUBLE, 1.0))
    @example("no_such_parameter", pv(T.PARAMETER_STRING, "x"))
    @example(names[-1] + ".x", pv(T.PARAMETER_NOT_SET))
    @example(names[-1].upper(), pv(T.PARAMETER_BOOL, True))
    @given(UNKNOWN_NAMES, st.sampled_from(CANONICAL))
    def unknown(name: str, value: ParameterValue) -> None:
        if name in names:
            return
        _count(node)
        result = api.set(name, value)
        assert not result.successful, f"{api.target}: unknown parameter {name!r} accepted"
        assert f"'{name}'" in result.reason and "not a parameter" in result.reason, result.reason
        assert name not in api.names(), f"{api.target}: {name!r} was declared"

    unknown()
    assert api.get(names) == initial, f"{api.target}: parameters changed"
    assert api.describe(names) == descriptors, f"{api.target}: descriptors changed"
    alive()
    return names


def check_valid_parameters(api: ParameterApi, node: str, valid: dict[str, st.SearchStrategy[ParameterValue]],
                           alive: Callable[[], None], examples: int) -> None:
    """Valid values are accepted and read back (then the original value is restored)."""
    def property_of(name: str, original: ParameterValue) -> Callable[[ParameterValue], None]:
        def accepted(value: ParameterValue) -> None:
            _count(node, "valid")
            result = api.set(name, value)
            assert result.successful, f"{api.target}: valid {name} = {show(value)} refused: {result.reason}"
            assert api.get([name])[name] == value
            alive()
            assert api.set(name, original).successful, f"{name}: the original value was refused"
        return accepted

    for name, values in valid.items():
        original = api.get([name])[name]
        _settings(examples)(given(values)(property_of(name, original)))()
        assert api.get([name])[name] == original


def trigger(executor: Any, node: Any, service: str) -> Any:
    from std_srvs.srv import Trigger

    client = node.create_client(Trigger, service)
    return call_service(executor, node, client, Trigger.Request(), timeout=10)


def pausing(paused: bool) -> Callable[[dict[str, bool]], bool]:
    """A state-machine step of pause (True) or resume (False): False (refused) when already in that state."""
    def step(state: dict[str, bool]) -> bool:
        if state["paused"] == paused:
            return False
        state["paused"] = paused
        return True
    return step


def resuming(resume: Callable[[], object]) -> Callable[[dict[str, bool]], None]:
    """The clean-up of a state machine run: resume (through ``resume()``) when the model says paused."""
    def step(state: dict[str, bool]) -> None:
        if state["paused"]:
            assert resume().success
            state["paused"] = False
    return step


def check_state_machine(node_name: str, calls: dict[str, Callable[[dict[str, bool]], bool | None]],
                        call: Callable[[str], Any], restore: Callable[[dict[str, bool]], None],
                        alive: Callable[[dict[str, bool]], None], initial: dict[str, bool], examples: int) -> None:
    """Random sequences of Trigger calls against a model of the node's state.

    ``calls[name](state)`` says whether the call is valid in ``state`` and changes ``state`` when it is (None:
    always valid). A call in a wrong state must be refused with a message, and change nothing.
    """
    @_settings(examples)
    @given(st.lists(st.sampled_from(sorted(calls)), min_size=2, max_size=7))
    def sequence(names: list[str]) -> None:
        state = dict(initial)
        for name in names:
            expected = calls[name](state)
            response = call(name)
            _count(node_name, "bad" if expected is False else "valid")
            assert response.message, f"{name}: empty message"
            if expected is False:
                assert not response.success, f"{name} in state {state} accepted: {response.message}"
                assert re.search(r"already|not ", response.message), f"{name}: {response.message!r} names no state"
            else:
                assert response.success, f"{name} in state {state} refused: {response.message}"
            alive(state)
        restore(state)
        alive(state)

    sequence()


# ---- helpers for the nodes ---------------------------------------------------------------------------------

def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class Counter:
    """Messages of one topic received by the test's node; ``wait_more`` waits for new ones."""

    def __init__(self, executor: Any, node: Any, msg_type: Any, topic: str, keep: Callable[[Any], bool] | None = None):
        self.executor, self.count, self.last = executor, 0, None
        self._keep = keep

        def on_message(msg: Any) -> None:
            if self._keep is None or self._keep(msg):
                self.count += 1
                self.last = msg

        node.create_subscription(msg_type, topic, on_message, QoSProfile(depth=100,
                                                                         reliability=ReliabilityPolicy.RELIABLE))

    def wait_more(self, n: int = 1, timeout: float = 10.0) -> bool:
        start = self.count
        return spin_until(self.executor, lambda: self.count >= start + n, timeout)


def _test_node(ros_executor: Any) -> Any:
    import rclpy

    node = rclpy.create_node("bad_input_probe", context=ros_executor.context)
    ros_executor.add_node(node)
    return node


def _watch_motor(ros_executor: Any, proc: Any, who: str) -> tuple[Any, Any, Callable[[], None]]:
    """(probe node, counter of /rig/motor/state once ``proc`` publishes it, ``alive()``).

    ``alive()`` asserts that the process still runs and still publishes; ``who`` names it in the messages.
    """
    from rimd_msgs.msg import MotorState

    node = _test_node(ros_executor)
    motor = Counter(ros_executor, node, MotorState, "/rig/motor/state")
    assert motor.wait_more(5, timeout=30), f"{who} does not publish"

    def alive() -> None:
        assert proc.is_running(), proc.tail()
        assert motor.wait_more(), f"{who} stopped publishing"

    return node, motor, alive


def check_services(executor: Any, node: Any, name: str, namespace: str, covered: set[str]) -> None:
    """The node's own services (not rclpy's parameter and type description ones) are those the test covers."""
    def own() -> set[str]:
        try:
            found = node.get_service_names_and_types_by_node(name, namespace)
        except Exception:  # not discovered yet
            return set()
        return {service for service, types in found
                if not any(t.startswith(("rcl_interfaces/", "type_description_interfaces/")) for t in types)}

    spin_until(executor, lambda: own() >= covered, 10)
    assert own() == covered, f"{namespace}/{name}: services {sorted(own())}, the test covers {sorted(covered)}"


def _simulator(ros_processes: Any, *args: str) -> Any:
    rig = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "real_time_factor:=4.0",
                                   "-p", "motor.initial_frequency:=3.75", "-p", "motor.initial_setpoint:=3.75", *args)
    rig.wait_for_output(r"rig ready", timeout=60)
    return rig


# ---- the simulator -----------------------------------------------------------------------------------------

def test_simulator_refuses_bad_input_and_keeps_running(ros_processes, ros_executor):
    from rimd_msgs.srv import Perturb, SetMotorFrequency
    from rimd_sim.model.contact import CONTACT_LAWS
    from rimd_sim.settings.config import NODE_PARAMETERS, PARAMETERS

    rig = _simulator(ros_processes)
    node, motor, alive = _watch_motor(ros_executor, rig, "the rig")

    check_services(ros_executor, node, "rimd_simulator", "/rig", {
        "/rig/set_motor_frequency", "/rig/perturb", "/rig/reset", "/rig/pause", "/rig/resume",
        "/rig/inject_fault", "/rig/clear_faults"})
    api = ParameterApi(ros_executor, node, "/rig/rimd_simulator")

    def fixed(name: str, descriptor: Any) -> bool:
        # Read-only, or refused at run time whatever the value (the core cannot change them on a running model).
        return (descriptor.read_only or name in ("seed", "use_sim_time") or name.endswith("sample_rate")
                or name.endswith(".reliable"))

    names = check_bad_parameters(api, "simulator", specs={**PARAMETERS, **NODE_PARAMETERS}, fixed=fixed, alive=alive,
                                 examples=2)
    assert set(PARAMETERS) <= set(names)
    initial = api.get(names)

    # A set of several parameters at once with one wrong value changes none of them.
    @_settings(6)
    @given(st.sampled_from(["mass", "contact.stiffness", "motor.ramp_rate", "block_rate", "initial.theta_dot"]),
           st.sampled_from([math.nan, math.inf, -1.0, 1e300]))
    def atomic(bad: str, value: float) -> None:
        _count("simulator")
        before = api.get(["gap", bad])
        result = api.set_atomically([("gap", pv(T.PARAMETER_DOUBLE, 0.001)), (bad, pv(T.PARAMETER_DOUBLE, value))])
        assert not result.successful and names_parameter(result.reason, bad), result.reason
        assert api.get(["gap", bad]) == before
        alive()

    atomic()

    # Valid values are accepted (and restored).
    def floats(low: float, high: float) -> st.SearchStrategy[ParameterValue]:
        return st.floats(low, high, allow_subnormal=False).map(lambda v: pv(T.PARAMETER_DOUBLE, v))

    check_valid_parameters(api, "simulator", {
        "gap": floats(0.0, 0.005), "damping_ratio": floats(0.0, 0.5), "motor.ramp_rate": floats(0.5, 100.0),
        "channels.impact_force.noise_std": floats(0.0, 0.1), "initial.theta_dot": floats(-10.0, 10.0),
        "noise.enabled": st.booleans().map(lambda v: pv(T.PARAMETER_BOOL, v)),
        "contact.model": st.sampled_from(sorted(CONTACT_LAWS)).map(lambda v: pv(T.PARAMETER_STRING, v)),
        "channels.cart_displacement.frame_id": st.text(string.ascii_letters, min_size=1, max_size=12).map(
            lambda v: pv(T.PARAMETER_STRING, v)),
        "real_time_factor": st.sampled_from([2.0, 8.0]).map(lambda v: pv(T.PARAMETER_DOUBLE, v)),
    }, alive, examples=3)

    # ---- services ----
    frequency = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")
    perturb = node.create_client(Perturb, "/rig/perturb")
    applied = re.compile(r"(set_motor_frequency|perturb) at simulation time ")

    def setpoint_is(expected: float) -> None:
        assert motor.wait_more(), "the rig stopped publishing"
        assert motor.last.frequency_setpoint == expected, (motor.last.frequency_setpoint, expected)

    def stamp(kind: str, ns_back: int) -> Time:
        """A start_stamp that is wrong: already passed, negative, malformed, or too far ahead."""
        now = _ns(motor.last.header.stamp)  # the rig has published this: it is past it
        if kind == "passed":
            ns = max(1, now - ns_back)
            return Time(sec=ns // 10**9, nanosec=ns % 10**9)
        if kind == "negative":
            return Time(sec=-1 - ns_back % 2**31, nanosec=0)
        if kind == "nanosec":
            return Time(sec=now // 10**9 + 1, nanosec=10**9 + ns_back % (2**32 - 10**9))
        # Two days ahead of the last state received: beyond the one-day rule however far the rig has run since.
        ns = now + 2 * 86_400 * 10**9 + ns_back
        return Time(sec=min(ns // 10**9, 2**31 - 1), nanosec=ns % 10**9)

    stamps = st.tuples(st.sampled_from(["passed", "negative", "nanosec", "ahead"]), st.integers(1, 10**12))
    bad_frequency = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]),
                              st.floats(max_value=0.0, exclude_max=True, allow_infinity=False),
                              st.floats(min_value=12.0, exclude_min=True, allow_infinity=False))
    bad_ramp = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]),
                         st.floats(max_value=0.0, exclude_max=True, allow_infinity=False),
                         st.floats(min_value=1e4, exclude_min=True, allow_infinity=False))
    log_lines = len(applied.findall(rig.output()))

    @_settings(8)
    @example(("frequency_hz", math.nan))
    @example(("frequency_hz", -1.0))
    @example(("frequency_hz", 12.5))
    @example(("ramp_rate", math.nan))
    @example(("ramp_rate", -1.0))
    @example(("ramp_rate", 1e300))
    @example(("start_stamp", ("passed", 1)))
    @example(("start_stamp", ("nanosec", 0)))
    @given(st.one_of(st.tuples(st.just("frequency_hz"), bad_frequency), st.tuples(st.just("ramp_rate"), bad_ramp),
                     st.tuples(st.just("start_stamp"), stamps)))
    def set_motor_frequency(case: tuple[str, Any]) -> None:
        _count("simulator")
        field, value = case
        request = SetMotorFrequency.Request(frequency_hz=3.75, ramp_rate=0.0)
        if field == "start_stamp":
            request.start_stamp = stamp(*value)
        else:
            setattr(request, field, value)
        response = call_service(ros_executor, node, frequency, request, timeout=10)
        assert not response.success, f"set_motor_frequency {field} = {value!r} accepted: {response.message}"
        assert field in response.message and re.search(r"must|above", response.message), response.message
        assert response.frequency_hz == 3.75, "the refusal does not answer the setpoint in force"
        setpoint_is(3.75)

    set_motor_frequency()

    bad_velocity = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]),
                             st.floats(min_value=10.0, exclude_min=True, allow_infinity=False),
                             st.floats(max_value=-10.0, exclude_max=True, allow_infinity=False))

    @_settings(6)
    @example(("velocity", math.nan))
    @example(("velocity", 1e300))
    @example(("start_stamp", ("passed", 1)))
    @given(st.one_of(st.tuples(st.just("velocity"), bad_velocity), st.tuples(st.just("start_stamp"), stamps)))
    def perturb_refused(case: tuple[str, Any]) -> None:
        _count("simulator")
        field, value = case
        request = Perturb.Request(velocity=0.01)
        if field == "start_stamp":
            request.start_stamp = stamp(*value)
        else:
            request.velocity = value
        response = call_service(ros_executor, node, perturb, request, timeout=10)
        assert not response.success, f"perturb {field} = {value!r} accepted: {response.message}"
        assert field in response.message and "must" in response.message, response.message
        alive()

    perturb_refused()
    alive()
    assert len(applied.findall(rig.output())) == log_lines, "a refused command was applied"

    # Faults (docs/faults.md): every wrong field of /rig/inject_fault is refused naming it; nothing is scheduled.
    from rimd_msgs.srv import InjectFault
    from rimd_sim.instruments.faults import FAULT_KINDS
    from rimd_sim.settings.config import CHANNEL_NAMES

    inject = node.create_client(InjectFault, "/rig/inject_fault")
    not_finite = st.sampled_from([math.nan, math.inf, -math.inf])
    negative = st.floats(max_value=-1e-9, allow_infinity=False, allow_nan=False)

    @_settings(8)
    @example(("channel", "nope"))
    @example(("kind", "melt"))
    @example(("duration", -1.0))
    @example(("magnitude", math.nan))
    @example(("start", 1e-3))   # already passed
    @given(st.one_of(st.tuples(st.just("channel"), _TEXT.filter(lambda t: t not in CHANNEL_NAMES)),
                     st.tuples(st.just("kind"), _TEXT.filter(lambda t: t not in FAULT_KINDS)),
                     st.tuples(st.just("duration"), st.one_of(not_finite, negative)),
                     st.tuples(st.just("magnitude"), not_finite),
                     st.tuples(st.just("start"), st.one_of(not_finite, negative))))
    def inject_refused(case: tuple[str, Any]) -> None:
        _count("simulator")
        field, value = case
        request = InjectFault.Request(channel="impact_force", kind="offset", start=0.0, duration=0.1, magnitude=1.0)
        setattr(request, field, value)
        response = call_service(ros_executor, node, inject, request, timeout=10)
        assert not response.success, f"inject_fault {field} = {value!r} accepted: {response.message}"
        assert f"{field} = " in response.message and "must" in response.message, response.message
        alive()

    inject_refused()
    assert "fault 0 start" not in rig.output(), "a refused fault was applied"
    assert trigger(ros_executor, node, "/rig/clear_faults").success

    # pause / resume / reset in any order: a call in the wrong state is refused and changes nothing.
    def rig_alive(state: dict[str, bool]) -> None:
        assert rig.is_running(), rig.tail()
        if not state["paused"]:
            assert motor.wait_more(), "the rig stopped publishing"

    resume_if_paused = resuming(lambda: trigger(ros_executor, node, "/rig/resume"))

    check_state_machine("simulator", {"pause": pausing(True), "resume": pausing(False), "reset": lambda s: None},
                        lambda name: trigger(ros_executor, node, f"/rig/{name}"), resume_if_paused, rig_alive,
                        {"paused": False}, examples=5)
    setpoint_is(3.75)
    assert api.get(names) == initial, "a parameter changed"
    assert "Traceback" not in rig.output(), rig.tail()


# ---- the recorder ------------------------------------------------------------------------------------------

def test_recorder_refuses_bad_input_and_keeps_recording(ros_processes, ros_executor, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    from rimd_sim.settings.recording import PARAMETERS

    recorder = ros_processes.start_node("rimd_recorder", "--ros-args", "-p", f"output_dir:={tmp_path / 'rec'}",
                                        "-p", "flush_interval:=0.5", "-p", "topics:=['/rig/motor/state']")
    recorder.wait_for_output(r"recording .* into", timeout=30)
    rig = _simulator(ros_processes)
    recorder.wait_for_output(r"recording /rig/motor/state", timeout=30)
    node = _test_node(ros_executor)
    status: list[dict[str, str]] = []

    def on_diagnostics(msg: Any) -> None:
        for s in msg.status:
            if "rimd_recorder" in s.name:
                status.append({kv.key: kv.value for kv in s.values})

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 50)

    def recording(expected_state: str = "recording", timeout: float = 10.0) -> None:
        """The recorder reports ``expected_state``; when recording, the messages it has written grow."""
        assert recorder.is_running(), recorder.tail()
        start = len(status)
        assert spin_until(ros_executor, lambda: len(status) >= start + 1, timeout), "no recorder diagnostics"
        first = status[-1]
        assert first["state"] == expected_state, first
        if expected_state == "recording":
            written = int(first["messages_written"])
            assert spin_until(ros_executor, lambda: int(status[-1]["messages_written"]) > written, timeout), \
                f"the recorder stopped writing: {status[-1]}"

    recording()
    written = [int(status[-1]["messages_written"])]

    def alive() -> None:
        assert recorder.is_running(), recorder.tail()

    def progress() -> None:
        """Since the last look, the recorder reported (1 Hz) that it is recording and wrote more."""
        assert spin_until(ros_executor, lambda: int(status[-1]["messages_written"]) > written[0], 10), \
            f"the recorder stopped writing: {status[-1]}"
        assert status[-1]["state"] == "recording", status[-1]
        written[0] = int(status[-1]["messages_written"])

    check_services(ros_executor, node, "rimd_recorder", "/",
                   {f"/rimd_recorder/{name}" for name in ("start", "stop", "split", "pause", "resume")})
    api = ParameterApi(ros_executor, node, "/rimd_recorder")
    # Every parameter, use_sim_time too, is read at start: any change at run time is refused; but stop_at (rimd
    # experiment sets it while recording), whose wrong values are refused.
    names = check_bad_parameters(api, "recorder", specs=PARAMETERS, fixed=lambda name, d: name != "stop_at",
                                 alive=alive, examples=2,
                                 progress=progress, progress_every=4)
    assert set(PARAMETERS) <= set(names)
    recording()

    # The services in every order: start/stop, pause/resume twice in a row are refused, split always works.
    def toggling(key: str, value: bool) -> Callable[[dict[str, bool]], bool]:
        def step(state: dict[str, bool]) -> bool:
            if state[key] == value:
                return False
            state[key] = value
            return True
        return step

    def restore(state: dict[str, bool]) -> None:
        if not state["recording"]:
            assert trigger(ros_executor, node, "/rimd_recorder/start").success
            state["recording"] = True
        if state["paused"]:
            assert trigger(ros_executor, node, "/rimd_recorder/resume").success
            state["paused"] = False

    check_state_machine("recorder", {"start": toggling("recording", True), "stop": toggling("recording", False),
                                     "pause": toggling("paused", True), "resume": toggling("paused", False),
                                     "split": lambda s: None},
                        lambda name: trigger(ros_executor, node, f"/rimd_recorder/{name}"), restore,
                        lambda state: alive(), {"recording": True, "paused": False}, examples=5)
    recording()
    assert rig.is_running() and "Traceback" not in recorder.output(), recorder.tail()


# ---- the replay --------------------------------------------------------------------------------------------

def test_replay_refuses_bad_input_and_keeps_replaying(ros_processes, ros_executor, tmp_path):
    from harness.rig_mcap import write_rig_mcap
    from rimd_msgs.srv import Burst, PlayNext, Seek, SetRate
    from rimd_sim.ros.nodes.replay import PARAMETERS, ReplayError, check_parameters

    with pytest.raises(ReplayError, match="^file: no recording given"):   # the one rule only the node knows
        check_parameters({})
    _count("replay")

    path = tmp_path / "rig.mcap"
    write_rig_mcap(path, seconds=3)
    replay = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={path}", "-p", "loop:=true")
    replay.wait_for_output(r"replaying \d+ topics", timeout=30)
    node, motor, alive = _watch_motor(ros_executor, replay, "the replay")

    check_services(ros_executor, node, "rimd_replay", "/", {f"/rimd_replay/{name}" for name in (
        "pause", "resume", "toggle_paused", "is_paused", "get_rate", "set_rate", "seek", "play_next", "burst",
        "get_state")})   # get_state takes nothing: no bad input to send it
    api = ParameterApi(ros_executor, node, "/rimd_replay")
    names = check_bad_parameters(api, "replay", specs=PARAMETERS, fixed=lambda name, d: d.read_only, alive=alive,
                                 examples=2)

    # The player's services with wrong values or in the wrong state: refused, nothing changes.
    def call(srv: Any, name: str, request: Any) -> Any:
        _count("replay")
        return call_service(ros_executor, node, node.create_client(srv, f"/rimd_replay/{name}"), request, timeout=10)

    for rate in (0.0, -1.0, math.nan, math.inf, 1e300):
        response = call(SetRate, "set_rate", SetRate.Request(rate=rate))
        assert not response.success and "rate = " in response.message and "must be" in response.message
    for stamp in (Time(sec=100, nanosec=0), Time(sec=2**31 - 1, nanosec=0), Time(sec=1, nanosec=1_500_000_000)):
        response = call(Seek, "seek", Seek.Request(time=stamp))
        assert not response.success and "time" in response.message and "must be" in response.message
    assert not call(PlayNext, "play_next", PlayNext.Request()).success          # playing: refused
    assert call(Burst, "burst", Burst.Request(num_messages=10)).actually_burst == 0
    alive()
    assert set(PARAMETERS) <= set(names)
    check_valid_parameters(api, "replay", {"use_sim_time": st.booleans().map(lambda v: pv(T.PARAMETER_BOOL, v))},
                           alive, examples=2)

    def replay_alive(state: dict[str, bool]) -> None:
        assert replay.is_running(), replay.tail()
        if not state["paused"]:
            assert motor.wait_more(), "the replay stopped publishing"

    resume_if_paused = resuming(lambda: trigger(ros_executor, node, "/rimd_replay/resume"))

    check_state_machine("replay", {"pause": pausing(True), "resume": pausing(False)},
                        lambda name: trigger(ros_executor, node, f"/rimd_replay/{name}"), resume_if_paused,
                        replay_alive, {"paused": False}, examples=5)
    alive()
    assert "Traceback" not in replay.output(), replay.tail()


# ---- the Rerun bridge --------------------------------------------------------------------------------------

def test_rerun_bridge_refuses_bad_input_and_keeps_logging(ros_processes, ros_executor, tmp_path):
    from rimd_sim.viz.bridge_settings import PARAMETERS

    rig = _simulator(ros_processes)
    bridge = ros_processes.start_node("rimd_rerun", "--ros-args", "-p", "sink:=save",
                                      "-p", f"save_path:={tmp_path / 'x.rrd'}", "-p", "status_period:=0.2")
    bridge.wait_for_output(r"rerun bridge ready", timeout=60)
    node = _test_node(ros_executor)
    status = re.compile(r"status: (\d+) messages")

    def logged() -> int:
        counts = status.findall(bridge.output())
        return int(counts[-1]) if counts else 0

    seen = [0]

    def alive(timeout: float = 10.0) -> None:
        """The bridge runs and has logged more messages since the last look (its status line, every 0.2 s)."""
        assert bridge.is_running(), bridge.tail()
        assert spin_until(ros_executor, lambda: logged() > seen[0], timeout), f"the bridge stopped: {bridge.tail()}"
        seen[0] = logged()

    alive(timeout=30)
    check_services(ros_executor, node, "rimd_rerun", "/rig", set())  # none: parameters only
    api = ParameterApi(ros_executor, node, "/rig/rimd_rerun")

    def still_running() -> None:
        assert bridge.is_running() and rig.is_running(), bridge.tail()

    names = check_bad_parameters(api, "rerun", specs=PARAMETERS, fixed=lambda name, d: d.read_only,
                                 alive=still_running, examples=2, progress=alive)
    assert set(PARAMETERS) <= set(names)
    check_valid_parameters(api, "rerun", {"use_sim_time": st.booleans().map(lambda v: pv(T.PARAMETER_BOOL, v))},
                           lambda: None, examples=2)
    alive()
    assert "Traceback" not in bridge.output(), bridge.tail()


