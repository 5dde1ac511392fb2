"""Test harness shared by the test suite: ROS domain leases, managed subprocesses, rclpy helpers.

The fixtures in ``tests/conftest.py`` wrap these; tests normally use the fixtures.
"""
