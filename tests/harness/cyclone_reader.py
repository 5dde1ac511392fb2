"""A DAQ reader of the rig on Eclipse Cyclone DDS (the ``cyclonedds`` package), as a lab's non-ROS client is.

    python cyclone_reader.py OUT.json --seconds S [--lockstep NAME] [--depth 200] [--timeout T]

No rclpy, no Fast DDS: the message types are written by hand from ``rimd_msgs/msg/*.msg`` as IDL structs with the
names ROS 2 gives them on DDS (``rimd_msgs/msg/SampleBlock`` is ``rimd_msgs::msg::dds_::SampleBlock_`` on topic
``rt/rig/cart/displacement``). It reads the four channels (reliable, keep last ``--depth``, volatile, as a lab's
reader on rmw_cyclonedds_cpp subscribes with depth 200) and ``/rig/session`` (transient local), prints
``cyclone reader ready`` once each channel's reader has matched the rig's writer, and exits 0 once every channel
has delivered ``--seconds`` s of samples counted from the first block it got, having written ``OUT.json``: per
topic each block's ``[first_index, len(samples), stamp_ns, sample_rate, arrival_ns]`` in arrival order (arrival: the
wall clock when the reader took it), Cyclone's count of samples it declared lost (the hole of a late first heartbeat
is not one of them), and the sessions heard (``/rig/session``: it waits for one).

With ``--lockstep NAME`` it is a lockstep consumer the way a client in another language is: it publishes
``rimd_msgs/msg/ConsumerProgress`` itself on ``rt/rig/progress`` (docs/rig.md, "Pacing: lockstep"): a join report
(every channel done through zero) once its readers and its progress writer are matched, then per channel the stamp
of the last block taken, and a last report with ``leaving`` when it is done.

The domain is ``ROS_DOMAIN_ID``. Cyclone is held to the loopback interface (its own ``CYCLONEDDS_URI``), with
unicast discovery to 127.0.0.1: the test suite never leaves loopback, and the rig's Fast DDS participants answer
there. ``--trace FILE``: Cyclone's trace of the wire, to see when each writer's heartbeats come.
"""

# (no `from __future__ import annotations`: cyclonedds reads the IDL structs' annotations as types)

import argparse
import json
import os
import sys
import time
import uuid
from dataclasses import dataclass

from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint32, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

CHANNELS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force")

#: Cyclone on loopback only: no multicast, unicast discovery to this host's participants (Fast DDS's and Cyclone's
#: well-known ports for participant indices up to MaxAutoParticipantIndex).
LOOPBACK_CONFIG = """<CycloneDDS><Domain Id="any">
  <General><Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast></General>
  <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>
    <Peers><Peer address="127.0.0.1"/></Peers></Discovery>{tracing}
</Domain></CycloneDDS>"""
#: Cyclone's own trace of the wire (DATA, HEARTBEAT, ACKNACK, GAP, discovery), with ``--trace FILE``.
TRACING = "<Tracing><Verbosity>finest</Verbosity><OutputFile>{path}</OutputFile></Tracing>"


# The ROS 2 messages as DDS sees them (field order and types of the .msg files; names as rosidl makes them).
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class SampleBlock(IdlStruct, typename="rimd_msgs::msg::dds_::SampleBlock_"):
    header: Header
    first_index: uint64
    sample_rate: float64
    samples: sequence[float64]
    unit: str
    range_min: float64
    range_max: float64
    saturated_count: uint32


@dataclass
class RigSession(IdlStruct, typename="rimd_msgs::msg::dds_::RigSession_"):
    header: Header
    run_id: str
    reason: str
    sequence: uint32
    start_stamp: Time
    simulation_time: float64
    time_base: str
    real_time_factor: float64
    lockstep: bool
    seed: uint64
    config_hash: str
    node: str


@dataclass
class ConsumerProgress(IdlStruct, typename="rimd_msgs::msg::dds_::ConsumerProgress_"):
    consumer: str
    done_through: Time
    topics: sequence[str]
    topics_done_through: sequence[Time]
    instance: str
    leaving: bool
    node: str
    controls: bool
    commands: uint32


def ns(t: Time) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def to_time(value: int) -> Time:
    return Time(*divmod(value, 1_000_000_000))


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--seconds", type=float, required=True, help="seconds of samples per channel to read")
    parser.add_argument("--lockstep", default="", help="report progress under this name (a lockstep consumer)")
    parser.add_argument("--depth", type=int, default=200, help="the readers' keep-last depth")
    parser.add_argument("--timeout", type=float, default=120.0, help="give up after this many seconds (exit 1)")
    parser.add_argument("--trace", default="", help="write Cyclone's trace of everything it does to this file")
    args = parser.parse_args()

    # Read when the participant is made; a CYCLONEDDS_URI of the user's would take the reader off loopback.
    os.environ["CYCLONEDDS_URI"] = LOOPBACK_CONFIG.format(tracing=TRACING.format(path=args.trace) if args.trace else "")

    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    reliable = Policy.Reliability.Reliable(duration(milliseconds=100))
    data_qos = Qos(reliable, Policy.History.KeepLast(args.depth), Policy.Durability.Volatile)
    readers = {name: DataReader(participant, Topic(participant, "rt" + name, SampleBlock), qos=data_qos)
               for name in CHANNELS}
    session_reader = DataReader(participant, Topic(participant, "rt/rig/session", RigSession), qos=Qos(
        reliable, Policy.History.KeepLast(1), Policy.Durability.TransientLocal))
    progress = None
    if args.lockstep:
        # Reliable, transient local, keep last 1 (rimd_msgs/msg/ConsumerProgress.msg): each report is the whole
        # progress, so the last one is enough, and it reaches a subscription matched after it was written.
        progress = DataWriter(participant, Topic(participant, "rt/rig/progress", ConsumerProgress), qos=Qos(
            reliable, Policy.History.KeepLast(1), Policy.Durability.TransientLocal))
    instance = uuid.uuid4().hex

    waitset = WaitSet(participant)
    for reader in (*readers.values(), session_reader):
        waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))

    deadline = time.monotonic() + args.timeout
    blocks: dict[str, list[list]] = {name: [] for name in CHANNELS}
    sessions: list[dict] = []
    done: dict[str, int] = {}
    ready = joined = False

    def report(leaving: bool = False) -> None:
        names = sorted(done)
        progress.write(ConsumerProgress(
            consumer=args.lockstep, done_through=to_time(min(done.values()) if done else 0), topics=names,
            topics_done_through=[to_time(done[n]) for n in names], instance=instance, leaving=leaving, node="",
            controls=False, commands=0))

    def finished() -> bool:
        if not sessions:   # the run's identity (transient local): its start_stamp is the time grid's origin
            return False
        for name in CHANNELS:
            got = blocks[name]
            if not got or (got[-1][0] + got[-1][1] - got[0][0]) / got[0][3] < args.seconds:
                return False
        return True

    while not finished():
        if time.monotonic() > deadline:
            print(f"cyclone reader: timed out after {args.timeout:g} s; blocks per channel: "
                  f"{ {n: len(b) for n, b in blocks.items()} }", flush=True)
            return 1
        if not ready and all(r.get_subscription_matched_status().current_count > 0 for r in readers.values()):
            ready = True
            print("cyclone reader ready", flush=True)
        if progress is not None and ready and not joined \
                and progress.get_publication_matched_status().current_count > 0:
            # The join, every channel done through zero (nothing taken yet), once Cyclone has matched the rig's
            # writers: it drops a block from a writer it has not discovered yet, and never asks for it again.
            done.update(dict.fromkeys(CHANNELS, 0))
            report()
            joined = True
        waitset.wait(duration(milliseconds=50))
        took = False
        for name, reader in readers.items():
            for sample in reader.take(N=1000):
                stamp = ns(sample.header.stamp)
                blocks[name].append([int(sample.first_index), len(sample.samples), stamp, float(sample.sample_rate),
                                     time.time_ns()])
                done[name] = stamp
                took = True
        for s in session_reader.take(N=10):
            sessions.append({"run_id": s.run_id, "reason": s.reason, "start_stamp_ns": ns(s.start_stamp),
                             "time_base": s.time_base, "lockstep": bool(s.lockstep)})
        if took and joined:
            report()

    if progress is not None and joined:
        report()
        report(leaving=True)
        progress.wait_for_acks(duration(seconds=2))
    lost = {name: reader.get_sample_lost_status().total_count for name, reader in readers.items()}
    with open(args.out, "w", encoding="utf-8") as out:
        json.dump({"blocks": blocks, "lost": lost, "sessions": sessions}, out)
    print(f"cyclone reader: done; blocks per channel: { {n: len(b) for n, b in blocks.items()} }", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
