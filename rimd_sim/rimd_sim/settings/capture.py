"""The triggered capture's settings (node parameters ``capture.*`` of the simulator).

The capture itself (:class:`~rimd_sim.instruments.capture.TriggeredCapture`) lives with the instruments.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from rimd_sim.settings.params import build, group, param

__all__ = ["ACC_CHANNEL", "FORCE_CHANNEL", "CaptureConfig", "CaptureSettings"]

#: Extra model channels: (name, quantity of the channel named).
FORCE_CHANNEL = "capture_force"
ACC_CHANNEL = "capture_acceleration"

@dataclass(frozen=True)
class CaptureConfig:
    """The capture's settings: node parameters ``capture.*`` of the simulator (read at start)."""

    enabled: bool = param(False, "publish a triggered capture of force and acceleration for each impact",
                          read_only=True)
    sample_rate: float = param(1.0e6, "capture sample rate", unit="Hz", ge=20_000, le=1.0e7, read_only=True)
    pre_trigger: float = param(1.0e-4, "time kept before the trigger", unit="s", ge=0, le=0.1, read_only=True)
    post_trigger: float = param(1.0e-3, "time kept from the trigger on", unit="s", gt=0, le=0.1, read_only=True)
    threshold: float = param(5.0, "trigger level on the rising force", unit="N", gt=0, read_only=True)

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> CaptureConfig:
        """From node parameters (``capture.*``), validated; other names are ignored.

        Raises:
            ConfigError: Naming the parameter and its rule.
        """
        return build(CaptureSettings, {k: v for k, v in values.items() if k.startswith("capture.")}).capture

    def extra_channels(self) -> tuple[tuple[str, Fraction, str], ...]:
        """The model's extra channels for this capture (none when disabled)."""
        if not self.enabled:
            return ()
        rate = Fraction(repr(self.sample_rate))
        return ((FORCE_CHANNEL, rate, "impact_force"), (ACC_CHANNEL, rate, "rimd_acceleration_in_contact"))


@dataclass(frozen=True)
class CaptureSettings:
    """The capture as a group of the simulator node's parameters (``capture.*``)."""

    capture: CaptureConfig = group(CaptureConfig, "capture.")
