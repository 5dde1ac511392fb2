"""ROS 2 nodes of the rig: thin adapters over the ROS-free layers."""
