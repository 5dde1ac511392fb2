"""Offline analyses of the rig model (no ROS): frequency sweeps and what is derived from them."""
