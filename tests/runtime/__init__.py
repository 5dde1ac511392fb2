"""In-process tests of the nodes' ROS-free runtimes (rimd_sim.runtime): no DDS, fake clocks."""
