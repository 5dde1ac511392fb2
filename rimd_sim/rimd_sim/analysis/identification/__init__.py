"""Identification of the rig's parameters from a recording (``rimd identify``), experiment design."""
