"""The pure core of the RIMD twin: configuration, model, instruments, simulator. Never imports rclpy."""

from __future__ import annotations

from rimd_sim.core.config import (
    CHANNEL_NAMES,
    ChannelConfig,
    ContactParams,
    IntegratorParams,
    MotorParams,
    RigParams,
    SimConfig,
    load_config,
)
from rimd_sim.core.contact import CONTACT_LAWS, ContactLaw, contact_force
from rimd_sim.core.errors import CommandError, ConfigError, IntegrationError, RimdError
from rimd_sim.core.model import TRUTH_FIELDS, Impact, ModelOutput, MotorState, RigModel, StroboPoint

__all__ = [
    "CHANNEL_NAMES",
    "CONTACT_LAWS",
    "TRUTH_FIELDS",
    "ChannelConfig",
    "CommandError",
    "ConfigError",
    "ContactLaw",
    "ContactParams",
    "Impact",
    "IntegrationError",
    "IntegratorParams",
    "ModelOutput",
    "MotorParams",
    "MotorState",
    "RigModel",
    "RigParams",
    "RimdError",
    "SimConfig",
    "StroboPoint",
    "contact_force",
    "load_config",
]
