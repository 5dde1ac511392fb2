"""Runnable examples that ship with the package (docs/daq-client.md)."""
