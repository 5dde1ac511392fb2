"""rimd_msgs: the interfaces are built, have exactly the contract's fields in order, and round-trip CDR."""

from __future__ import annotations

import math

import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from rimd_msgs.msg import ImpactEvent, MotorState, RigState, SampleBlock
from rimd_msgs.srv import Perturb, SetMotorFrequency

FIELDS = {
    SampleBlock: [("header", "std_msgs/Header"), ("first_index", "uint64"), ("sample_rate", "double"),
                  ("samples", "sequence<double>"), ("unit", "string"), ("range_min", "double"),
                  ("range_max", "double"), ("saturated_count", "uint32")],
    ImpactEvent: [("header", "std_msgs/Header"), ("duration", "double"), ("peak_force", "double"),
                  ("impulse", "double"), ("impact_velocity", "double"), ("max_penetration", "double"),
                  ("excitation_frequency", "double"), ("excitation_phase", "double"),
                  ("cycle_index", "uint64"), ("index", "uint64")],
    MotorState: [("header", "std_msgs/Header"), ("frequency_setpoint", "double"), ("frequency", "double"),
                 ("phase", "double"), ("cycle_index", "uint64"), ("ramp_rate", "double"),
                 ("cart_position", "double")],
    RigState: [("header", "std_msgs/Header"), ("first_index", "uint64"), ("sample_rate", "double"),
               *[(name, "sequence<double>") for name in (
                   "theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity",
                   "rimd_acceleration", "penetration", "contact_force", "motor_phase", "motor_frequency")],
               ("in_contact", "sequence<boolean>")],
    # start_stamp: added to the first request fields; zero keeps their behaviour (the next block boundary).
    SetMotorFrequency.Request: [("frequency_hz", "double"), ("ramp_rate", "double"),
                                ("start_stamp", "builtin_interfaces/Time")],
    SetMotorFrequency.Response: [("success", "boolean"), ("message", "string"), ("frequency_hz", "double"),
                                 ("effective_stamp", "builtin_interfaces/Time")],
    Perturb.Request: [("velocity", "double"), ("start_stamp", "builtin_interfaces/Time")],
    Perturb.Response: [("success", "boolean"), ("message", "string"),
                       ("effective_stamp", "builtin_interfaces/Time")],
}


@pytest.mark.parametrize("message_type", list(FIELDS), ids=lambda t: t.__qualname__)
def test_fields_are_the_contract(message_type):
    assert list(message_type.get_fields_and_field_types().items()) == FIELDS[message_type]


def _header(sec: int, nanosec: int, frame_id: str) -> Header:
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


ROUND_TRIP_CASES = [
    SampleBlock(header=_header(12, 500_000_000, "accelerometer"), first_index=2**40 + 3, sample_rate=20_000.0,
                samples=[0.0, -1.5e-3, 9.81, math.inf], unit="m/s^2", range_min=-490.5, range_max=490.5,
                saturated_count=1),
    ImpactEvent(header=_header(3, 1, "force_sensor"), duration=1.2e-3, peak_force=82.4, impulse=0.05,
                impact_velocity=0.21, max_penetration=2e-5, excitation_frequency=3.75,
                excitation_phase=2 * math.pi - 1e-9, cycle_index=17, index=2**63),
    MotorState(header=_header(0, 10_000_000, "motor"), frequency_setpoint=7.25, frequency=7.0,
               phase=1.0, cycle_index=4, ramp_rate=0.5, cart_position=-1e-3),
    RigState(header=_header(1, 0, "rig"), first_index=1000, sample_rate=1000.0, theta=[0.1, 0.2],
             theta_dot=[1.0, -1.0], cart_position=[1e-3, 0.0], rimd_position=[0.0075, 0.0149],
             rimd_velocity=[0.07, -0.07], rimd_acceleration=[-9.0, 3.0], penetration=[-1e-3, 2e-6],
             contact_force=[0.0, 11.0], motor_phase=[0.0, 6.28], motor_frequency=[3.0, 3.0],
             in_contact=[False, True]),
    SetMotorFrequency.Request(frequency_hz=3.75, ramp_rate=0.0),
    SetMotorFrequency.Response(success=False, message="frequency_hz must be finite, got nan",
                               frequency_hz=2.5, effective_stamp=Time(sec=5, nanosec=7)),
    Perturb.Request(velocity=-0.3),
    Perturb.Response(success=True, message="ok", effective_stamp=Time(sec=9, nanosec=0)),
]


@pytest.mark.parametrize("message", ROUND_TRIP_CASES, ids=lambda m: type(m).__qualname__)
def test_cdr_round_trip(message):
    data = serialize_message(message)
    assert isinstance(data, bytes) and len(data) > 4
    assert deserialize_message(data, type(message)) == message


def test_default_values_are_empty():
    block = SampleBlock()
    assert list(block.samples) == [] and block.first_index == 0 and block.unit == ""


def test_field_checks_are_opt_in_on_jazzy():
    """Jazzy's message classes check values only with check_fields=True or ROS_PYTHON_CHECK_FIELDS=1."""
    with pytest.raises(AssertionError, match="unsigned integer"):
        SampleBlock(check_fields=True, first_index=-1)
    with pytest.raises(AssertionError, match="'unit' field must be of type 'str'"):
        SampleBlock(check_fields=True, unit=3)
