"""Recordings: rosbag2-compatible MCAP writing and reading (no rclpy), used by the recorder and replay nodes."""
