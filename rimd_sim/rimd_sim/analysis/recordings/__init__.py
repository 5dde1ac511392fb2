"""Analyses of a recording (``rimd analyze``): its reading, impacts, contact pulse, faults, report."""
