"""Bounded helpers for rclpy in the test process: spin until a condition holds, call a service."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.client import Client
from rclpy.executors import Executor
from rclpy.node import Node

SPIN_STEP_S = 0.05


def spin_until(executor: Executor, condition: Callable[[], bool], timeout: float) -> bool:
    """Spin ``executor`` until ``condition()`` is true or ``timeout`` s passed; return the condition."""
    deadline = time.monotonic() + timeout
    while not condition():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return condition()
        executor.spin_once(timeout_sec=min(SPIN_STEP_S, remaining))
    return True


def call_service(executor: Executor, node: Node, client: Client, request: Any, timeout: float) -> Any:
    """Call ``client`` with ``request`` and return the response, waiting at most ``timeout`` s in all.

    Raises:
        TimeoutError: The service did not appear or did not answer in time.
    """
    deadline = time.monotonic() + timeout
    if not spin_until(executor, client.service_is_ready, timeout):
        raise TimeoutError(
            f"service {client.srv_name} not available within {timeout} s (node {node.get_name()})"
        )
    future = client.call_async(request)
    if not spin_until(executor, future.done, max(0.0, deadline - time.monotonic())):
        client.remove_pending_request(future)
        raise TimeoutError(f"service {client.srv_name} did not answer within {timeout} s")
    return future.result()
