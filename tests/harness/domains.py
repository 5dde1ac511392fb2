"""Unique ROS_DOMAIN_ID leases, so that concurrent tests and test runs on one machine never hear each other.

A lease is an exclusive ``flock`` on ``<tmp>/rimd-ros-domain-locks/<id>.lock``: it is shared by every
process on the machine (two ``make test`` in two clones, pytest-xdist workers), and the kernel releases it
when the holder dies, so a crashed run never leaks a domain. Ids are taken from 1..100 (0, the default
domain, is left to people running the rig by hand), starting from a point that depends on the process id
and a counter, so consecutive tests of one run also use different domains.
"""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
from pathlib import Path

DOMAIN_ID_MIN = 1
DOMAIN_ID_MAX = 100
LOCK_DIR = Path(tempfile.gettempdir()) / "rimd-ros-domain-locks"

_lease_counter = itertools.count()


class DomainLease:
    """An exclusively held ROS_DOMAIN_ID; a context manager, ``release()`` is safe to call twice."""

    def __init__(self, domain_id: int, lock_file: int) -> None:
        """Hold ``domain_id`` through the already-locked file descriptor ``lock_file``."""
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


def lease_domain_id(*, lock_dir: Path = LOCK_DIR) -> DomainLease:
    """Take the first free domain id, searching from a start point that differs per process and call.

    Raises:
        RuntimeError: Every id in DOMAIN_ID_MIN..DOMAIN_ID_MAX is held by someone else.
    """
    lock_dir.mkdir(mode=0o777, parents=True, exist_ok=True)
    span = DOMAIN_ID_MAX - DOMAIN_ID_MIN + 1
    start = (os.getpid() * 7 + next(_lease_counter)) % span
    for offset in range(span):
        domain_id = DOMAIN_ID_MIN + (start + offset) % span
        descriptor = os.open(lock_dir / f"{domain_id}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            continue
        return DomainLease(domain_id, descriptor)
    raise RuntimeError(
        f"all ROS domain ids {DOMAIN_ID_MIN}..{DOMAIN_ID_MAX} are leased (lock files in {lock_dir})"
    )
