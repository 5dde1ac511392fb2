"""The ROS-free cores of the nodes: pacing and lockstep, a consumer's progress, the recorder's session, the player."""
