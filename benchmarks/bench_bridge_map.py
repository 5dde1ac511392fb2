"""CPU of the Rerun bridge's mapping per second of rig data, in one process, warm: the composed rig's bridge path.

The live rig's bridge (docs/rerun.md) takes each block as the bytes the simulator serialized, reads it in place
(``rimd_sim.io.cdr.read_block``; the impact events through rclpy's deserializer, as the bridge does) and hands it
to :class:`rimd_sim.viz.rerun_map.RigMapper`, which batches ``batch_blocks`` (10) blocks per send. This bench runs
exactly that path on --seconds of the default rig's messages (``SimulatorRuntime`` on the default config/rimd.yaml,
stepped without waiting: the same bytes as at real time), into an .rrd file sink, and prints the CPU it took (all
threads of the process: the mapping, pyarrow, the Rerun SDK's own threads encoding and writing) as % of one core
at real time, and the parts: reading the bytes, the channels, the truth (phase plane, Poincare, motor), the events.

It is the bridge's share of ``bench_rig.py``'s composed rig without the rig's wake-ups and the other threads'
interference (the live share is larger: a thread woken every few ms runs its work from cold caches).

``--display-interval S`` maps the channels as the live bridge's display stream (each channel's min and max sample
per S seconds: ``display_interval``, docs/rerun.md; the bridge's default is 0.005); the default 0 maps every sample,
as ``rimd rig --rerun-full-rate`` and ``rimd rerun`` do (and as a checkout without the display stream does).

With ``--compare DIR`` (another checkout), the same measurement runs from this tree and from DIR's package
alternately (fresh processes, ``--rounds`` each), and the median ratio DIR / this is printed (> 1: this tree is
cheaper): a before/after of one run on a shared machine.

Run (after ``source env.sh``):
    python benchmarks/bench_bridge_map.py [--seconds 30] [--display-interval 0.005] [--compare DIR [--rounds 5]]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "rimd_sim" / "config" / "rimd.yaml"
PARTS = ("read", "channels", "truth", "events")


def rig_messages(seconds: float) -> list[tuple[str, bytes]]:
    """``(topic relative to /rig, serialized bytes)`` of ``seconds`` of the default rig, in publishing order."""
    import yaml

    from rimd_sim.runtime.simulator import SimulatorRuntime, load_settings

    document = yaml.safe_load(CONFIG.read_text())
    params = next(v["ros__parameters"] for k, v in document.items() if k.endswith("rimd_simulator"))
    flat: dict = {}

    def walk(d: dict, prefix: str = "") -> None:
        for k, v in d.items():
            walk(v, f"{prefix}{k}.") if isinstance(v, dict) else flat.__setitem__(prefix + k, v)

    walk(params)
    config, settings = load_settings(flat)
    clock = [100.0]
    out: list[tuple[str, bytes]] = []
    rt = SimulatorRuntime(config, settings, send=lambda key, data: out.append((key, data)), clock=lambda: clock[0],
                          wall_ns=lambda: 1_764_000_000_000_000_000 + round((clock[0] - 100.0) * 1e9))
    rt.start()
    blocks, done = round(seconds * config.block_rate), 0
    while done < blocks:   # one motor state per block published
        before = len(out)
        rt.step()
        done += sum(1 for key, _ in out[before:] if key == "motor/state")
        clock[0] += 1.0 / config.block_rate
    return out


def measure(seconds: float, display_interval: float = 0.0) -> dict:
    """The bridge's path on ``seconds`` of messages: CPU s in all and per part (one untimed second first).

    ``display_interval`` > 0: the channels as the display stream (given to the mapper only then, so that a checkout
    without it measures at full rate).
    """
    import rerun as rr
    from rclpy.serialization import deserialize_message

    from rimd_msgs.msg import ImpactEvent
    from rimd_sim.io.cdr import read_block
    from rimd_sim.viz.rerun_map import CHANNELS, EVENTS_TOPIC, TRUTH_TOPIC, RigMapper

    messages = rig_messages(seconds + 1.0)
    kinds = {ch.topic: "rimd_msgs/msg/SampleBlock" for ch in CHANNELS} | {TRUTH_TOPIC: "rimd_msgs/msg/RigState"}
    with tempfile.TemporaryDirectory(prefix="bench_bridge_map_") as tmp:
        rec = rr.RecordingStream("bench_bridge_map")
        rec.save(str(Path(tmp) / "map.rrd"))
        display = {"display_interval": display_interval} if display_interval > 0 else {}
        mapper = RigMapper(rec, batch=10, min_interval=0.0, **display)
        mapper.log_static()
        clock = time.thread_time
        # the first second of messages untimed (up to a block's end): the caches and the SDK warm up
        warm = next(i for i, (key, _) in enumerate(messages)
                    if key == "motor/state" and i > len(messages) / (seconds + 1))
        for chunk in (messages[:warm], messages[warm:]):
            parts = dict.fromkeys(PARTS, 0.0)
            start = time.process_time()
            for topic, data in chunk:
                kind = kinds.get(topic)
                if kind is not None:
                    t0 = clock()
                    view = read_block(data, kind)
                    t1 = clock()
                    mapper.log_message(topic, view)
                    parts["read"] += t1 - t0
                    parts["truth" if topic == TRUTH_TOPIC else "channels"] += clock() - t1
                elif topic == EVENTS_TOPIC:
                    t0 = clock()
                    mapper.log_message(topic, deserialize_message(data, ImpactEvent))
                    parts["events"] += clock() - t0
            mapper.flush()
            rec.flush()
            total = time.process_time() - start
        rec.disconnect()
    return {"seconds": seconds, "cpu_s": total, "display_interval": display_interval} | parts


def percent(result: dict, key: str = "cpu_s") -> float:
    return 100.0 * result[key] / result["seconds"]


def run_tree(tree: Path, seconds: float, display_interval: float = 0.0) -> dict:
    """:func:`measure` in a fresh process importing ``tree``'s package."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree / "rimd_sim"), env.get("PYTHONPATH")]))
    out = subprocess.run([sys.executable, __file__, "--seconds", str(seconds), "--display-interval",
                          str(display_interval), "--json-line"], env=env,
                         capture_output=True, text=True, check=True, timeout=900).stdout
    return json.loads(out.strip().splitlines()[-1])


def show(label: str, result: dict) -> None:
    print(f"  {label:8s} {percent(result):5.2f} % of a core at real time (read {percent(result, 'read'):.2f}, "
          f"channels {percent(result, 'channels'):.2f}, truth {percent(result, 'truth'):.2f}, "
          f"events {percent(result, 'events'):.2f}; the rest: the SDK's threads)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="seconds of rig data mapped (default 30)")
    parser.add_argument("--compare", type=Path, default=None, metavar="DIR", help="another checkout, alternately")
    parser.add_argument("--rounds", type=int, default=5, help="with --compare: runs of each tree (default 5)")
    parser.add_argument("--display-interval", type=float, default=0.0, metavar="S",
                        help="map the channels as the display stream, min and max per S s (default 0: every sample)")
    parser.add_argument("--json-line", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.display_interval < 0:
        parser.error("--display-interval must be >= 0")
    if args.json_line:
        print(json.dumps(measure(args.seconds, args.display_interval)))
        return
    stream = (f"display stream, min and max per {args.display_interval:g} s" if args.display_interval > 0
              else "every sample")
    print(f"bench_bridge_map: {args.seconds:g} s of the default rig's messages ({stream}), "
          f"load {os.getloadavg()[0]:.2f}")
    if args.compare is None:
        show("this", run_tree(ROOT, args.seconds, args.display_interval))
        return
    results: dict[str, list[dict]] = {"this": [], "compare": []}
    for _ in range(args.rounds):
        for label, tree in (("this", ROOT), ("compare", args.compare.resolve())):
            results[label].append(run_tree(tree, args.seconds, args.display_interval))
            show(label, results[label][-1])
    for label, runs in results.items():
        print(f"  {label:8s} median {statistics.median(percent(r) for r in runs):.2f} %")
    ratios = [c["cpu_s"] / t["cpu_s"] for t, c in zip(results["this"], results["compare"], strict=True)]
    print(f"  ratio compare/this: median {statistics.median(ratios):.2f} (per round: "
          f"{', '.join(f'{r:.2f}' for r in ratios)}; > 1: this tree is cheaper); load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
