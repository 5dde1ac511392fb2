"""Recordings without ROS: the MCAP writer and the damage-tolerant reader, CDR, message definitions, cropping."""
