"""What the middleware alone costs at the rig's traffic: the floor under bench_rig.py's figures.

A publisher process sends the default rig's messages at real time, already serialized (the simulator's
channel blocks are CDR bytes encoded once, so this is only rclpy's ``publish`` and Fast DDS): per block,
100 blocks/s, the four channel blocks (20, 20, 200 and 200 samples), a truth block (10 samples of 10
arrays and 10 flags) and a motor state, on 6 reliable topics of depth 110: 600 messages/s, 0.49 MB/s.
Subscriber processes take them as the rig's recorder and Rerun bridge do (raw subscriptions taken every
20 ms by ``rimd_sim.ros.nodes.polling.PolledSubscriptions``, events executor) and do nothing with them. The same
Fast DDS profile as the nodes (``rimd_sim/nodes/fastdds_profiles.xml``), a ROS domain of its own, localhost.

Printed: for 0, 1 and 2 subscribers (the rig has two, the recorder and the bridge), the CPU of the publisher
and of each subscriber in % of one core over --seconds (utime + stime from /proc), and the messages each
subscriber received. With two subscribers the publisher's figure is the least the simulator can cost at
real time on the machine that runs it, with rclpy and Fast DDS, before it computes anything.

Run (after ``source env.sh``, the machine otherwise idle): python benchmarks/bench_dds_floor.py [--seconds 30]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TOPICS = ("cart", "rimd", "acc", "force", "truth", "motor")
CLK_TCK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    text = Path(f"/proc/{pid}/stat").read_text()
    fields = text[text.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def _qos():
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=110, reliability=ReliabilityPolicy.RELIABLE)


def publisher(seconds: float, subscribers: int) -> None:
    import array

    import numpy as np
    import rclpy
    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import MotorState, RigState, SampleBlock
    from rimd_sim.io.cdr import SampleBlockEncoder

    rclpy.init()
    node = rclpy.create_node("bench_dds_floor_pub")
    types = {"truth": RigState, "motor": MotorState}
    pubs = {t: node.create_publisher(types.get(t, SampleBlock), f"/bench_dds_floor/{t}", _qos()) for t in TOPICS}
    deadline = time.monotonic() + 30
    while any(p.get_subscription_count() < subscribers for p in pubs.values()) and time.monotonic() < deadline:
        time.sleep(0.05)
    encoders = {t: (SampleBlockEncoder(t, 100.0 * n, "m", -1.0, 1.0), n)
                for t, n in (("cart", 20), ("rimd", 20), ("acc", 200), ("force", 200))}
    truth = RigState(sample_rate=1000.0, in_contact=[False] * 10)
    for name in ("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity", "rimd_acceleration",
                 "penetration", "contact_force", "motor_phase", "motor_frequency"):
        setattr(truth, name, array.array("d", np.random.default_rng(0).random(10)))
    motor = MotorState(frequency=3.75, frequency_setpoint=3.75)
    rng = np.random.default_rng(1)
    print("ready", flush=True)
    start, k = time.monotonic(), 0
    while time.monotonic() - start < seconds:
        delay = start + k / 100.0 - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        for topic, (encoder, n) in encoders.items():
            pubs[topic].publish(encoder.encode(k // 100, (k % 100) * 10_000_000, k * n, rng.random(n), 0))
        truth.first_index = 10 * k
        pubs["truth"].publish(serialize_message(truth))
        pubs["motor"].publish(serialize_message(motor))
        k += 1
    rclpy.shutdown()


def subscriber(seconds: float) -> None:
    import rclpy
    from rclpy.experimental import EventsExecutor

    from rimd_msgs.msg import MotorState, RigState, SampleBlock
    from rimd_sim.ros.nodes.polling import PolledSubscriptions, PollingNode

    class Sink(PollingNode):
        def __init__(self) -> None:
            super().__init__(f"bench_dds_floor_sub_{os.getpid()}")
            self.count = 0
            self._polled = PolledSubscriptions(self, 0.02)
            types = {"truth": RigState, "motor": MotorState}
            for t in TOPICS:
                self._polled.create(types.get(t, SampleBlock), f"/bench_dds_floor/{t}", _qos(), self.on)

        def on(self, data: bytes, info: dict) -> None:
            self.count += 1

    rclpy.init()
    sink = Sink()
    executor = EventsExecutor()
    executor.add_node(sink)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    print(f"received {sink.count}", flush=True)
    rclpy.shutdown()


def measure(count: int, seconds: float, env: dict[str, str]) -> dict:
    me = [sys.executable, str(Path(__file__).resolve())]
    subs = [subprocess.Popen([*me, "--role", "sub", "--seconds", str(seconds + 15)], env=env, text=True,
                             stdout=subprocess.PIPE) for _ in range(count)]
    pub = subprocess.Popen([*me, "--role", "pub", "--seconds", str(seconds), "--subscribers", str(count)], env=env,
                           text=True, stdout=subprocess.PIPE)
    assert pub.stdout is not None
    pub.stdout.readline()   # "ready": every subscriber matched
    time.sleep(1.0)         # settle, then measure a window inside the publishing
    window = max(1.0, seconds - 3.0)
    before = [cpu_seconds(p.pid) for p in (pub, *subs)]
    time.sleep(window)
    after = [cpu_seconds(p.pid) for p in (pub, *subs)]
    pub.wait(seconds + 60)
    received = [int(s.communicate(timeout=seconds + 60)[0].split()[-1]) for s in subs]
    cpu = [100.0 * (a - b) / window for a, b in zip(after, before, strict=True)]
    return {"publisher": cpu[0], "subscribers": cpu[1:], "received": received}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="publishing time per case (default 30)")
    parser.add_argument("--role", choices=("pub", "sub"), help=argparse.SUPPRESS)
    parser.add_argument("--subscribers", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "pub":
        publisher(args.seconds, args.subscribers)
        return
    if args.role == "sub":
        subscriber(args.seconds)
        return
    sys.path.insert(0, str(REPO / "tests"))
    import rimd_sim.ros.nodes
    from harness.domains import lease_domain_id

    lease = lease_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(Path(rimd_sim.ros.nodes.__file__).with_name("fastdds_profiles.xml")))
    try:
        print(f"bench_dds_floor: 600 messages/s (the default rig's), {args.seconds:g} s per case, "
              f"ROS_DOMAIN_ID {lease.domain_id}")
        print(f"  {'subscribers':>11} {'publisher CPU %':>16} {'each subscriber CPU %':>22}  messages received")
        for count in (0, 1, 2):
            r = measure(count, args.seconds, env)
            print(f"  {count:>11} {r['publisher']:>16.1f} {', '.join(f'{c:.1f}' for c in r['subscribers']) or '-':>22}"
                  f"  {', '.join(str(n) for n in r['received']) or '-'}", flush=True)
    finally:
        lease.release()


if __name__ == "__main__":
    main()
