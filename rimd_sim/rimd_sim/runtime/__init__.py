"""The ROS-free cores of the nodes: pacing and lockstep, the recorder's session, the player, playback control."""
