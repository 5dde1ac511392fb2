"""Visualisation of the rig: the mapping from rig messages to Rerun, its sinks, and offline sources.

Nothing here imports rclpy: the same code serves the ``rimd_rerun`` node and ``rimd rerun REC.mcap``.
"""
