"""ROS 2 nodes of the rig: thin adapters over :mod:`rimd_sim.core`."""
