"""The rig's instruments: sensors, faults, the triggered capture and the streaming simulator RigSimulator."""
