"""Contact laws of the paper's Eq. 1, in a registry keyed by name, written once for the kernel and for Python.

Each law gives the compressive force ``F(delta, delta_dot)`` (N, > 0 pushes the hammer out of the stop)
while the hammer is in contact with the force sensor. ``delta = l sin(theta) - gap`` is the penetration
(m) and ``delta_dot`` its rate (m/s). The Filippov switching rule (paper Eqs. 7-11) is the same for all
laws: contact starts when ``delta`` crosses 0 upwards, and ends when the law's force crosses 0 downwards
(which, with a dashpot, can happen while ``delta`` is still positive) or ``delta`` returns to 0.

The formulas are written once, in the compiled :func:`law_force`, which selects a law by its integer ``code``
(``p[P_LAW]``) and is inlined into the models' physics. :data:`CONTACT_LAWS` and :func:`contact_force` call the
same function from Python, with a parameter vector holding the law's code and parameters.

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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rimd_sim.model.jit import kernel_jit
from rimd_sim.model.layout import N_PARAM, P_C, P_E, P_K, P_LAW, P_N
from rimd_sim.settings.config import CONTACT_MODELS

__all__ = ["CONTACT_LAWS", "ContactLaw", "contact_force", "law_force"]


@kernel_jit(inline=True)
def spow(x, n):
    """Signed power ``sign(x) |x|^n``."""
    if x >= 0.0:
        return x**n
    return -((-x) ** n)


@kernel_jit(inline=True)
def law_force(delta, ddelta, p, vimp):
    """Force of the law ``p[P_LAW]`` with the parameters of ``p``, unclipped (may be negative near a switch).

    The one definition of the formulas of the table above, with ``k = p[P_K]``, ``c = p[P_C]``, ``n = p[P_N]``,
    ``e = p[P_E]``; ``vimp`` is the impact velocity of the open contact (m/s, > 0), read by the
    Lankarani-Nikravesh law. The laws share one function, inlined into every call of the models' physics,
    because every further inlined function adds to the compile time of each caller.
    """
    code = int(p[P_LAW])
    if code == 0:
        return p[P_K] * delta + p[P_C] * ddelta
    dn = spow(delta, p[P_N])
    if code == 1:
        return p[P_K] * dn
    if code == 2:
        return dn * (p[P_K] + p[P_C] * ddelta)
    e = p[P_E]
    return p[P_K] * dn * (1.0 + 0.75 * (1.0 - e * e) * ddelta / vimp)


def _law(code: int) -> Callable[[float, float, float, float, float, float, float], float]:
    """The law ``code`` as a Python function ``force(delta, delta_dot, k, c, n, e, v_impact)`` of :func:`law_force`."""

    def force(delta: float, delta_dot: float, k: float, c: float, n: float, e: float, v_impact: float) -> float:
        p = np.zeros(N_PARAM)
        p[P_LAW] = code
        p[P_K] = k
        p[P_C] = c
        p[P_N] = n
        p[P_E] = e
        return float(law_force(float(delta), float(delta_dot), p, float(v_impact)))

    return force


@dataclass(frozen=True)
class ContactLaw:
    """A named contact law.

    Attributes:
        name: Registry key.
        code: Integer by which the compiled driver selects the law (``p[P_LAW]``).
        formula: The law in words.
        uses: Parameter names (``contact.*``) the law reads.
        force: ``force(delta, delta_dot, k, c, n, e, v_impact)``: :func:`law_force`, the function the driver runs.
    """

    name: str
    code: int
    formula: str
    uses: tuple[str, ...]
    force: Callable[[float, float, float, float, float, float, float], float]


CONTACT_LAWS: dict[str, ContactLaw] = {
    law.name: law
    for law in (
        ContactLaw("spring_dashpot", 0, "k*delta + c*delta_dot", ("stiffness", "damping"), _law(0)),
        ContactLaw("hertz", 1, "k*delta^n", ("stiffness", "exponent"), _law(1)),
        ContactLaw("hunt_crossley", 2, "k*delta^n + c*delta^n*delta_dot", ("stiffness", "damping", "exponent"),
                   _law(2)),
        ContactLaw("lankarani_nikravesh", 3, "k*delta^n*(1 + 3(1-e^2)/4 * delta_dot/v_impact)",
                   ("stiffness", "exponent", "restitution", "min_impact_velocity"), _law(3)),
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
