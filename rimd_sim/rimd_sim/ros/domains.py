"""Machine-wide leases of ROS domain ids, and the environment of a process on a leased domain.

A lease (:func:`lease_domain_id`) is an exclusive ``flock`` on ``<tmp>/rimd-ros-domain-locks/<id>.lock``. The lock
files are shared by every process on the machine (parallel test runs, pytest-xdist workers, parallel CI jobs), so
two holders never get the same id, and the kernel releases a lease when its holder dies. A rig on a leased domain,
with discovery kept on this machine (:func:`ros_environment`), hears no other rig.
"""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
from pathlib import Path

from rimd_sim.errors import UnavailableError
from rimd_sim.ros.fixture_settings import (
    DOMAIN_RANGE_ENV,
    DOMAIN_RANGE_INI,
    ROS_DOMAIN_ID_LIMIT,
    configured_domain_range,
)

__all__ = ["LOCK_DIR", "DomainLease", "lease_domain_id", "ros_environment"]

#: Where the lock files are, one per domain id.
LOCK_DIR = Path(tempfile.gettempdir()) / "rimd-ros-domain-locks"
_lease_counter = itertools.count()


class DomainLease:
    """An exclusively held ROS_DOMAIN_ID; a context manager, ``release()`` is safe to call twice.

    Args:
        domain_id: The leased id.
        lock_file: The descriptor of its lock file, holding the ``flock``; closing it releases the lease.
    """

    def __init__(self, domain_id: int, lock_file: int) -> None:
        self.domain_id = domain_id
        self._lock_file: int | None = lock_file

    def release(self) -> None:
        """Give the domain back (closing the descriptor drops the lock)."""
        if self._lock_file is not None:
            os.close(self._lock_file)
            self._lock_file = None

    def __enter__(self) -> DomainLease:
        """Return the lease."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Release the lease."""
        self.release()


def lease_domain_id(*, lock_dir: Path = LOCK_DIR, domain_range: tuple[int, int] | None = None) -> DomainLease:
    """Take the first free domain id of the range, from a start that differs per process.

    Args:
        lock_dir: Where the lock files are (one per id, shared by every range).
        domain_range: (first, last), both included; default :func:`configured_domain_range` without an ini file
            (``RIMD_DOMAIN_RANGE``, else 1..100).

    Raises:
        UnavailableError: Every id of the range is held by someone else.
        InputError: ``RIMD_DOMAIN_RANGE`` is refused (no range given).
    """
    first, last = configured_domain_range() if domain_range is None else domain_range
    if not 0 <= first <= last <= ROS_DOMAIN_ID_LIMIT:
        raise ValueError(f"domain_range {domain_range!r}: must be (first, last) with 0 <= first <= last <= "
                         f"{ROS_DOMAIN_ID_LIMIT}")
    lock_dir.mkdir(mode=0o777, parents=True, exist_ok=True)
    span = last - first + 1
    start = (os.getpid() * 7 + next(_lease_counter)) % span
    for offset in range(span):
        domain_id = first + (start + offset) % span
        descriptor = os.open(lock_dir / f"{domain_id}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            continue
        return DomainLease(domain_id, descriptor)
    raise UnavailableError(f"all ROS domain ids {first}..{last} are leased (lock files in {lock_dir}); a wider range: "
                           f"{DOMAIN_RANGE_ENV} or the ini key {DOMAIN_RANGE_INI} (docs/testing.md)")


def ros_environment(domain_id: int, log_dir: Path) -> dict[str, str]:
    """This process's environment on ``domain_id``, discovery kept on this machine, ROS logs in ``log_dir``.

    The variables that would send discovery elsewhere (static peers, a discovery server, the localhost-only switch
    that ``ROS_AUTOMATIC_DISCOVERY_RANGE`` replaces) are left out, and so is the ROS wheels' bootstrap marker, so
    that a child process bootstraps as it does when started from a shell.
    """
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY", "ROS_DISCOVERY_SERVER",
                        "_ROS_WHEELS_BOOTSTRAP_COMPLETE")}
    env.update({"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                "ROS_LOG_DIR": str(log_dir), "PYTHONUNBUFFERED": "1", "RCUTILS_COLORIZED_OUTPUT": "0"})
    return env
