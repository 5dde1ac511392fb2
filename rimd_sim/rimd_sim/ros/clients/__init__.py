"""Clients of a running rig over ROS 2: its services, its status, lockstep progress reports, experiments."""
