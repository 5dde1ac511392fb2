"""Contact laws of the paper's Eq. 1, in a registry keyed by name.

Each law gives the compressive force ``F(delta, delta_dot)`` (N, > 0 pushes the hammer out of the stop)
while the hammer is in contact with the force sensor. ``delta = l sin(theta) - gap`` is the penetration
(m) and ``delta_dot`` its rate (m/s). The Filippov switching rule (paper Eqs. 7-11) is the same for all
laws: contact starts when ``delta`` crosses 0 upwards, and ends when the law's force crosses 0 downwards
(which, with a dashpot, can happen while ``delta`` is still positive) or ``delta`` returns to 0.

The integrator evaluates the laws inside a compiled kernel by their integer ``code``; the Python
callables here are the reference used by tests and documentation.

=================== ====== =========================================================================
name                code   force
=================== ====== =========================================================================
spring_dashpot      0      ``k delta + c delta_dot`` (the paper's identified law, Table 2)
hertz               1      ``k delta^n``
hunt_crossley       2      ``k delta^n + c delta^n delta_dot``
lankarani_nikravesh 3      ``k delta^n [1 + 3 (1 - e^2) / 4 * delta_dot / v_impact]``
=================== ====== =========================================================================

For ``delta < 0`` (used only while the root finder brackets a switch) ``delta^n`` is extended as
``sign(delta) |delta|^n`` so every law is smooth across its own zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from rimd_sim.settings.config import CONTACT_MODELS

__all__ = ["CONTACT_LAWS", "ContactLaw", "contact_force"]


def _spow(x: float, n: float) -> float:
    return math.copysign(abs(x) ** n, x)


@dataclass(frozen=True)
class ContactLaw:
    """A named contact law.

    Attributes:
        name: Registry key.
        code: Integer used by the compiled kernel.
        formula: The law in words.
        uses: Parameter names (``contact.*``) the law reads.
        force: Reference implementation ``force(delta, delta_dot, k, c, n, e, v_impact)``.
    """

    name: str
    code: int
    formula: str
    uses: tuple[str, ...]
    force: Callable[[float, float, float, float, float, float, float], float]


CONTACT_LAWS: dict[str, ContactLaw] = {
    law.name: law
    for law in (
        ContactLaw(
            "spring_dashpot", 0, "k*delta + c*delta_dot", ("stiffness", "damping"),
            lambda d, dd, k, c, n, e, v: k * d + c * dd,
        ),
        ContactLaw(
            "hertz", 1, "k*delta^n", ("stiffness", "exponent"),
            lambda d, dd, k, c, n, e, v: k * _spow(d, n),
        ),
        ContactLaw(
            "hunt_crossley", 2, "k*delta^n + c*delta^n*delta_dot", ("stiffness", "damping", "exponent"),
            lambda d, dd, k, c, n, e, v: _spow(d, n) * (k + c * dd),
        ),
        ContactLaw(
            "lankarani_nikravesh", 3, "k*delta^n*(1 + 3(1-e^2)/4 * delta_dot/v_impact)",
            ("stiffness", "exponent", "restitution", "min_impact_velocity"),
            lambda d, dd, k, c, n, e, v: k * _spow(d, n) * (1.0 + 0.75 * (1.0 - e * e) * dd / v),
        ),
    )
}

if [(law.name, law.code) for law in CONTACT_LAWS.values()] != [(name, i) for i, name in enumerate(CONTACT_MODELS)]:
    raise RuntimeError("the contact-law registry and settings.config.CONTACT_MODELS disagree on names or codes")


def contact_force(model: str, delta: float, delta_dot: float, *, stiffness: float, damping: float = 0.0,
                  exponent: float = 1.5, restitution: float = 1.0, impact_velocity: float = 1.0) -> float:
    """Evaluate a contact law's force (N) at a penetration and rate, without the Filippov clipping.

    Args:
        model: Registry key.
        delta: Penetration (m).
        delta_dot: Penetration rate (m/s).
        stiffness: ``k``.
        damping: ``c``.
        exponent: ``n``.
        restitution: ``e``.
        impact_velocity: ``v_impact`` (m/s, > 0) of the Lankarani-Nikravesh law.
    """
    return CONTACT_LAWS[model].force(delta, delta_dot, stiffness, damping, exponent, restitution, impact_velocity)
