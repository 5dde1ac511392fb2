"""Unique ROS_DOMAIN_ID leases, so that concurrent tests and test runs on one machine never hear each other.

The leases are the product's own (``rimd_sim.ros.domains``, which the pytest plugin ``rimd_sim.ros.testing`` uses
for users' test suites): an exclusive ``flock`` per id, shared by every process on the machine and released by the
kernel when the holder dies. Re-exported here for the suite's fixtures.
"""

from __future__ import annotations

from rimd_sim.ros.domains import LOCK_DIR, DomainLease, lease_domain_id
from rimd_sim.ros.fixture_settings import DOMAIN_ID_MAX, DOMAIN_ID_MIN

__all__ = ["DOMAIN_ID_MAX", "DOMAIN_ID_MIN", "LOCK_DIR", "DomainLease", "lease_domain_id"]
