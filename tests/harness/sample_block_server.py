"""A stand-in rig for the multi-process DDS test: publishes SampleBlock, serves SetMotorFrequency.

Run as a script with ROS arguments, e.g. ``python sample_block_server.py --ros-args -r __ns:=/rig``.
It publishes blocks of ``BLOCK_SIZE`` samples on ``test/samples`` (relative, so namespaces apply) from a
wall timer. Sample n is ``clip(AMPLITUDE * sin(2 pi f n / SAMPLE_RATE))``, where f is the frequency in
force for sample n; it changes at the first sample of the next block after a SetMotorFrequency request on
``set_motor_frequency`` is accepted, and the response's ``effective_stamp`` is that sample's time.
The test recomputes every sample with :func:`expected_sample` from the same module.
"""

from __future__ import annotations

import math
import sys

import rclpy
from builtin_interfaces.msg import Time
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from rimd_msgs.msg import SampleBlock
from rimd_msgs.srv import SetMotorFrequency

SAMPLE_RATE = 2000.0  # Hz
BLOCK_SIZE = 20  # samples, one block per 10 ms of sample time
AMPLITUDE = 1.0  # m
RANGE = (-0.9, 0.9)  # m, instrument range: the sine saturates at its peaks
INITIAL_FREQUENCY = 3.0  # Hz
MAX_FREQUENCY = 20.0  # Hz
FRAME_ID = "test_laser"


def expected_sample(index: int, frequency: float) -> float:
    """Return sample ``index`` of a channel running at ``frequency`` Hz, clipped to RANGE."""
    raw = AMPLITUDE * math.sin(2.0 * math.pi * frequency * index / SAMPLE_RATE)
    return min(max(raw, RANGE[0]), RANGE[1])


def stamp_of(index: int) -> Time:
    """Return the exact time of sample ``index`` (SAMPLE_RATE divides 1e9 ns)."""
    nanoseconds = index * int(1e9 / SAMPLE_RATE)
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


class SampleBlockServer(Node):
    """Publishes sample blocks and accepts frequency changes."""

    def __init__(self) -> None:
        """Create the publisher, the service and the timer."""
        super().__init__("sample_block_server")
        self._next_index = 0
        self._frequency = INITIAL_FREQUENCY
        self._publisher = self.create_publisher(SampleBlock, "test/samples", 100)
        self._service = self.create_service(SetMotorFrequency, "set_motor_frequency", self._on_set_frequency)
        self._timer = self.create_timer(BLOCK_SIZE / SAMPLE_RATE, self._publish_block)

    def _publish_block(self) -> None:
        raw = [
            AMPLITUDE * math.sin(2.0 * math.pi * self._frequency * n / SAMPLE_RATE)
            for n in range(self._next_index, self._next_index + BLOCK_SIZE)
        ]
        block = SampleBlock()
        block.header.stamp = stamp_of(self._next_index)
        block.header.frame_id = FRAME_ID
        block.first_index = self._next_index
        block.sample_rate = SAMPLE_RATE
        block.samples = [expected_sample(n, self._frequency)
                         for n in range(self._next_index, self._next_index + BLOCK_SIZE)]
        block.unit = "m"
        block.range_min, block.range_max = RANGE
        block.saturated_count = sum(1 for value in raw if not RANGE[0] <= value <= RANGE[1])
        self._publisher.publish(block)
        self._next_index += BLOCK_SIZE

    def _on_set_frequency(self, request: SetMotorFrequency.Request,
                          response: SetMotorFrequency.Response) -> SetMotorFrequency.Response:
        frequency = request.frequency_hz
        if not math.isfinite(frequency):
            response.success, response.message = False, f"frequency_hz must be finite, got {frequency}"
        elif frequency < 0.0:
            response.success, response.message = False, f"frequency_hz must be >= 0, got {frequency}"
        elif frequency > MAX_FREQUENCY:
            response.success = False
            response.message = f"frequency_hz {frequency} is above the maximum {MAX_FREQUENCY} Hz"
        else:
            self._frequency = frequency
            response.success, response.message = True, f"frequency set to {frequency} Hz"
        response.frequency_hz = self._frequency
        response.effective_stamp = stamp_of(self._next_index)
        self.get_logger().info(f"set_motor_frequency({frequency}): {response.message}")
        return response


def main() -> int:
    """Run the server until SIGINT/SIGTERM; exit status 0 on a clean shutdown."""
    # The product's stop handling (rimd_sim.nodes._run): with rclpy's own handlers a SIGINT between two
    # spin_once calls shuts the context down under the executor (RCLError, exit status 1).
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from rimd_sim.nodes._run import spin_until_stopped
    from rimd_sim.nodes._stop import install_stop_handlers

    stop = install_stop_handlers()
    rclpy.init(args=sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    node = SampleBlockServer()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    domain_id = node.context.get_domain_id()
    print(f"sample_block_server ready: namespace {node.get_namespace()}, domain {domain_id}", flush=True)
    try:
        spin_until_stopped(executor, stop)
    except ExternalShutdownException:
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
