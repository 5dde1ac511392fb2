"""The fault scenario of the fault tests: every sensor fault kind on the force channel, one after another.

Each entry: (kind, start s, duration s, magnitude, the finding of :mod:`rimd_sim.analysis.recordings.faultscan` that
shows it). The clock drift comes last: its clock offset stays after it ends.
"""

from __future__ import annotations

CHANNEL = "impact_force"
SEED = 11
END_S = 6.5   # simulation time covered by the runs

SEQUENCE = [
    ("dropout", 0.5, 0.2, 0.0, "gap"),
    ("block_loss", 0.8, 0.2, 0.9, "gap"),
    ("delay", 1.1, 0.2, 0.1, "late"),
    ("stuck", 1.4, 0.2, 0.0, "stuck"),
    ("offset", 1.7, 0.2, 5.0, "level"),
    ("gain", 2.0, 0.2, 3.0, "noise"),
    ("spike", 2.3, 0.2, 1000.0, "outliers"),
    ("noise_burst", 2.6, 0.2, 1.0, "noise"),
    ("saturate", 2.9, 0.2, 0.02, "saturated"),
    ("disconnect", 3.2, 0.2, 0.0, "rail"),
    ("clock_drift", 3.6, 2.0, 10000.0, "drift"),
]


def entries() -> list[str]:
    """The scenario as the simulator's ``faults`` parameter."""
    return [f"channel={CHANNEL} kind={k} start={s} duration={d} magnitude={m}" for k, s, d, m, _ in SEQUENCE]


def settings() -> dict:
    """The simulator's parameters of the fault runs (besides the seed and the faults), with the capture."""
    return {"capture.enabled": True, "motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75}
