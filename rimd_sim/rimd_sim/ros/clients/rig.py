"""A client of a running rig: its services in one line each, from a program, a verb or a test.

:class:`RigClient` owns a node in an rclpy context of its own (on the caller's ``ROS_DOMAIN_ID``, or on the
domain given), so it never disturbs an rclpy the caller already uses. Each call waits for the service and its
answer, both within one timeout (the client's, or the call's own ``timeout``), and returns the rig's response;
:class:`rimd_sim.errors.CommandError` says when there is no rig or no answer in time, naming the service and the
domain. A ``check`` given to the client runs at every turn of its waits (the pytest plugin's raises at once when
a process of the rig has exited, instead of waiting out the timeout). The one-shot verbs (``rimd motor``,
``rimd perturb``, ``rimd inject``, ``rimd pause``...) and the pytest plugin's
:class:`rimd_sim.ros.rig_handle.RigHandle` stand on it.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from rimd_sim.errors import CommandError

if TYPE_CHECKING:
    from rclpy.context import Context

__all__ = ["RigClient", "TRIGGERS"]

#: The environment variable rcl takes a context's discovery range from.
DISCOVERY_RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
#: Seconds a client gives a service it has just found to match it in turn, before its first request.
SERVICE_SETTLE_S = 0.5
#: The rig's Trigger services, by the name users type.
TRIGGERS = ("pause", "resume", "reset", "clear_faults")


def _srv(name: str) -> Any:
    def load() -> Any:
        import std_srvs.srv

        import rimd_msgs.srv

        return getattr(rimd_msgs.srv, name, None) or getattr(std_srvs.srv, name)
    return load


#: The rig's services by name, their types loaded on use (rclpy's message modules are imported lazily).
_SERVICE_TYPES = {"set_motor_frequency": _srv("SetMotorFrequency"), "perturb": _srv("Perturb"),
                  "inject_fault": _srv("InjectFault"), **{name: _srv("Trigger") for name in TRIGGERS}}


@contextlib.contextmanager
def _discovery_range(value: str | None) -> Iterator[None]:
    """``ROS_AUTOMATIC_DISCOVERY_RANGE`` set to ``value`` meanwhile (None: left as it is); restored after."""
    if value is None:
        yield
        return
    before = os.environ.get(DISCOVERY_RANGE_ENV)
    os.environ[DISCOVERY_RANGE_ENV] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(DISCOVERY_RANGE_ENV, None)
        else:
            os.environ[DISCOVERY_RANGE_ENV] = before


def stamp(seconds: float | None) -> Any:
    """A ``builtin_interfaces/Time`` of ``seconds`` (zero for None: the next block boundary)."""
    from builtin_interfaces.msg import Time

    ns = 0 if seconds is None else round(seconds * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class RigClient:
    """The rig's services, called from a node of this client's own. A context manager; ``close`` is idempotent.

    Args:
        domain_id: The ROS domain (default: ``ROS_DOMAIN_ID``, else 0).
        namespace: The rig's namespace (``/rig``).
        timeout: Seconds a call may take, the service found and its answer received (a call may give its own).
        name: The client node's name.
        check: Called at every turn of the client's waits (about every 50 ms); what it raises ends the wait.
        discovery_range: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` of the client's context (``LOCALHOST``, ``SUBNET``...;
            default: this process's environment). A rig started on ``LOCALHOST`` (the pytest plugin's) hears
            only participants on that range: a client on the default range is found by it only at its periodic
            announcement, seconds later.
    """

    def __init__(self, *, domain_id: int | None = None, namespace: str = "/rig", timeout: float = 10.0,
                 name: str = "rimd_client", check: Callable[[], None] | None = None,
                 discovery_range: str | None = None) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.namespace = namespace.rstrip("/")
        self.timeout = timeout
        self.check = check
        self.domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0) if domain_id is None else domain_id
        self.context: Context | None = rclpy.Context()   # None once closed
        with _discovery_range(discovery_range):   # rcl reads it when the context is initialised
            rclpy.init(context=self.context, domain_id=self.domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context, start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: dict[str, Any] = {}
        self._ready_at: dict[str, float] = {}   # when this client first saw each service (monotonic s)

    def __enter__(self) -> RigClient:
        """The client."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the client."""
        self.close()

    def close(self) -> None:
        """Destroy the node and shut the context down (idempotent)."""
        if self.context is not None:
            self.executor.shutdown()
            self.node.destroy_node()
            self.context.try_shutdown()
            self.context = None

    def spin_until(self, condition: Callable[[], bool], timeout: float) -> bool:
        """Spin until ``condition()`` holds or ``timeout`` seconds passed; return the condition.

        The client's ``check`` runs at every turn: what it raises ends the wait.
        """
        deadline = time.monotonic() + timeout
        while not condition():
            if self.check is not None:
                self.check()
            if time.monotonic() >= deadline:
                return condition()
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))
        return True

    def _name(self, service: str) -> str:
        """The full name of ``service`` (relative names are in the rig's namespace)."""
        return service if service.startswith("/") else f"{self.namespace}/{service}"

    def _service_client(self, service: str, srv_type: Any = None) -> tuple[str, Any]:
        """The client of ``service`` (made once; default type: the rig's service of that name), and its full name."""
        name = self._name(service)
        client = self._clients.get(name)
        if client is None:
            if srv_type is None:
                srv_type = _SERVICE_TYPES[service.rsplit("/", 1)[-1]]()
            client = self._clients[name] = self.node.create_client(srv_type, name)
        return name, client

    def _client(self, service: str, srv_type: Any, timeout: float) -> tuple[str, Any]:
        name, client = self._service_client(service, srv_type)
        if not self.spin_until(client.service_is_ready, timeout):
            raise CommandError(f"no rig: service {name} not available after {timeout:g} s on ROS_DOMAIN_ID "
                               f"{self.domain_id} (start it with `rimd rig`, on the same ROS_DOMAIN_ID)")
        self._ready_at.setdefault(name, time.monotonic())
        return name, client

    def _let_the_service_see_us(self, name: str) -> None:
        """Wait until :data:`SERVICE_SETTLE_S` has passed since this client first saw the service.

        Discovery is two-sided: the client sees the service before the service may have matched the client's reader
        of responses, and Fast DDS's service gives up on a response after 100 ms without that match ("failed to send
        response (timeout)"): the request is then served and its answer lost. Only a client that has just found the
        service waits (a one-shot command); one that found it a moment ago does not.
        """
        left = self._ready_at[name] + SERVICE_SETTLE_S - time.monotonic()
        if left > 0:
            self.spin_until(lambda: False, left)

    def service_ready(self, service: str, srv_type: Any = None) -> bool:
        """Whether ``service`` is served now, as far as this client has discovered (no wait)."""
        return bool(self._service_client(service, srv_type)[1].service_is_ready())

    def wait_for_service(self, service: str, srv_type: Any = None, timeout: float | None = None) -> None:
        """Wait (bounded) until ``service`` is served (default type: the rig's service of that name).

        Args:
            service: Its name (relative names are in the rig's namespace).
            srv_type: Its type.
            timeout: Seconds (default: the client's).

        Raises:
            CommandError: No such service within the timeout (no rig), naming it and the domain.
        """
        self._client(service, srv_type, self.timeout if timeout is None else timeout)

    def call(self, service: str, srv_type: Any, request: Any, timeout: float | None = None) -> Any:
        """Call ``service`` (relative names are in the rig's namespace) and return the response.

        Args:
            service: Its name.
            srv_type: Its type.
            request: The request.
            timeout: Seconds for the whole call, the service found and its answer received (default: the
                client's).

        Raises:
            CommandError: No such service within the timeout (no rig), or no answer within it; the message names
                the service and the domain.
        """
        limit = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        name, client = self._client(service, srv_type, limit)
        self._let_the_service_see_us(name)
        future = client.call_async(request)
        if not self.spin_until(future.done, max(0.0, deadline - time.monotonic())):
            client.remove_pending_request(future)
            raise CommandError(f"{name} did not answer within {limit:g} s on ROS_DOMAIN_ID {self.domain_id}")
        return future.result()

    def motor(self, frequency_hz: float, ramp_rate: float = 0.0, at: float | None = None, *,
              timeout: float | None = None) -> Any:
        """``set_motor_frequency``: ramp to ``frequency_hz`` (at stamp ``at`` s, else the next block boundary)."""
        from rimd_msgs.srv import SetMotorFrequency

        return self.call("set_motor_frequency", SetMotorFrequency, SetMotorFrequency.Request(
            frequency_hz=float(frequency_hz), ramp_rate=float(ramp_rate), start_stamp=stamp(at)), timeout)

    def perturb(self, velocity: float, at: float | None = None, *, timeout: float | None = None) -> Any:
        """``perturb``: add ``velocity`` (m/s) to the hammer (at stamp ``at`` s)."""
        from rimd_msgs.srv import Perturb

        return self.call("perturb", Perturb, Perturb.Request(velocity=float(velocity), start_stamp=stamp(at)),
                         timeout)

    def inject(self, channel: str, kind: str, *, start: float = 0.0, after: float = 0.0, duration: float = 0.0,
               magnitude: float = 0.0, timeout: float | None = None) -> Any:
        """``inject_fault`` (docs/faults.md): at simulation time ``start``, or ``after`` s from now."""
        from rimd_msgs.srv import InjectFault

        return self.call("inject_fault", InjectFault, InjectFault.Request(
            channel=channel, kind=kind, start=float(start), after=float(after), duration=float(duration),
            magnitude=float(magnitude)), timeout)

    def trigger(self, name: str, *, timeout: float | None = None) -> Any:
        """One of the rig's Trigger services: ``pause``, ``resume``, ``reset``, ``clear_faults``."""
        from std_srvs.srv import Trigger

        if name not in TRIGGERS:
            raise CommandError(f"{name!r} is not one of the rig's Trigger services ({', '.join(TRIGGERS)})")
        return self.call(name, Trigger, Trigger.Request(), timeout)
