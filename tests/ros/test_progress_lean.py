"""The lockstep reporter a user's DAQ node imports (rimd_sim.ros.clients.progress) is lean.

Hypotheses:

- importing it loads nothing but the standard library, beyond what rclpy and ``rimd_msgs`` load themselves (the
  rclpy modules a node imports anyway: ``rclpy.node``, ``rclpy.qos``, ``rclpy.duration``), and of the package only
  ``rimd_sim``, ``rimd_sim.ros``, ``rimd_sim.ros.clients``, ``rimd_sim.runtime``, ``rimd_sim.io`` (package modules
  that import nothing), its books ``rimd_sim.runtime.progress`` and its encoder ``rimd_sim.io.cdr_progress`` (the
  standard library's) and itself: no numba, numpy, scipy, mcap, or the twin's core (docs/daq-client.md);
- its reports are the bytes the package's CDR writer (rimd_sim.io.cdr) gives for them, so what goes on the wire
  is the message's layout (tests/io/test_cdr_blocks.py checks them against rclpy's own serialization), a
  controller's two fields (``controls``, ``commands``) included.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys

import pytest

#: What the reporter may load of the package: the package modules on the way, and itself.
ALLOWED = {"rimd_sim", "rimd_sim.ros", "rimd_sim.ros.clients", "rimd_sim.ros.clients.progress", "rimd_sim.runtime",
           "rimd_sim.runtime.progress", "rimd_sim.io", "rimd_sim.io.cdr_progress"}

LOADED = """
import json, sys
import rclpy, rclpy.node, rclpy.qos, rclpy.duration, rimd_msgs.msg   # what a consumer's node loads anyway
before = set(sys.modules)
import rimd_sim.ros.clients.progress
print(json.dumps(sorted(set(sys.modules) - before)))
"""


@pytest.mark.process
def test_the_progress_reporter_loads_only_rclpy_rimd_msgs_and_the_standard_library():
    result = subprocess.run([sys.executable, "-c", LOADED], env=dict(os.environ), capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    extra = json.loads(result.stdout.strip().splitlines()[-1])
    ours = sorted(m for m in extra if m.split(".")[0] == "rimd_sim" and m not in ALLOWED)
    theirs = sorted({m.split(".")[0] for m in extra} - set(sys.stdlib_module_names) - {"rimd_sim"})
    assert not ours, f"rimd_sim.ros.clients.progress loads more of the package than it may: {ours}"
    assert not theirs, f"rimd_sim.ros.clients.progress loads modules beyond the standard library: {theirs}"
    assert "rimd_sim.ros.clients.progress" in extra   # the comparison saw the import


def test_the_reports_are_the_bytes_they_were():
    from rimd_sim.io.cdr import CdrWriter
    from rimd_sim.ros.clients.progress import encode_progress

    def before(consumer, done_ns, instance, topics, leaving, node, controls, commands):   # the package's writer
        names = sorted(topics) if topics else []
        stamps = [divmod(topics[t], 1_000_000_000) for t in names] if topics else []
        done = divmod(min(topics.values()) if topics else done_ns, 1_000_000_000)
        w = CdrWriter().string(consumer).time(*done).strings(names).times(stamps).string(instance)
        return w.boolean(leaving).string(node).boolean(controls).u32(commands).message()

    rng = random.Random(7)

    def text() -> str:
        return "".join(rng.choice("abcxyz/_é✓") for _ in range(rng.randrange(0, 9)))

    for _ in range(3000):
        topics = {text(): rng.randrange(0, 2**31 * 10**9) for _ in range(rng.randrange(0, 5))} \
            if rng.random() < 0.8 else None
        args = (text(), rng.randrange(0, 2**31 * 10**9), text(), topics, rng.random() < 0.5, text(),
                rng.random() < 0.5, rng.randrange(0, 2**32))
        assert encode_progress(*args) == before(*args), args
    with pytest.raises(ValueError, match="NUL"):
        encode_progress("a\0b", 0, "i")
