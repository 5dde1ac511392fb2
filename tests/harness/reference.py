"""An independent reference integration of the rig model with ``scipy.integrate.solve_ivp``.

Written from the paper's equations (docs/physics.md), sharing no code with ``rimd_sim.model``: the
pendulum on the cart at constant motor frequency, spring-dashpot contact, Filippov switching with
terminal directed events (contact starts when delta rises through 0; it ends when the force falls
through 0 or delta falls through 0; after a release with delta > 0 the hammer re-contacts when the force
rises through 0). DOP853 with tight tolerances; peak force from the dense output of each contact segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


@dataclass
class RefImpact:
    t_start: float
    peak_force: float
    impact_velocity: float


def simulate(*, frequency: float, gap: float, duration: float, mass: float = 0.15, zeta: float = 0.088,
             amplitude: float = 1.044e-3, f_n: float = 1.763, k: float = 5.5e6, c: float = 1.2e3, g: float = 9.81,
             rtol: float = 1e-10, atol: float = 1e-12) -> list[RefImpact]:
    """Integrate from rest at a constant motor frequency; return the impacts.

    The defaults are the values of config/rimd.yaml (the paper's rig), written here, not read from the twin.
    """
    length = g / (2 * math.pi * f_n) ** 2
    w = 2 * math.pi * frequency
    wn = 2 * math.pi * f_n

    def force(th, om):
        return k * (length * math.sin(th) - gap) + c * length * om * math.cos(th)

    def f_free(t, y):
        th, om = y
        return [om, amplitude * w * w / length * math.cos(th) * math.sin(w * t) - g / length * math.sin(th)
                - 2 * zeta * wn * om]

    def f_contact(t, y):
        dy = f_free(t, y)
        dy[1] -= force(y[0], y[1]) / (mass * length)
        return dy

    def ev_delta(t, y):
        return length * math.sin(y[0]) - gap

    def ev_force(t, y):
        return force(y[0], y[1])

    impacts: list[RefImpact] = []
    t, y = 0.0, np.zeros(2)
    contact = False
    open_impact = False
    while t < duration:
        if contact:
            e1 = lambda t, y: ev_force(t, y)  # noqa: E731
            e1.terminal, e1.direction = True, -1
            e2 = lambda t, y: ev_delta(t, y)  # noqa: E731
            e2.terminal, e2.direction = True, -1
            sol = solve_ivp(f_contact, (t, duration), y, method="DOP853", rtol=rtol, atol=atol, events=(e1, e2),
                            dense_output=True, max_step=1e-4)
            ts = np.linspace(sol.t[0], sol.t[-1], 4001)
            ys = sol.sol(ts)
            peak = max(force(a, b) for a, b in zip(ys[0], ys[1], strict=True))
            impacts[-1].peak_force = max(impacts[-1].peak_force, peak)
            t, y = sol.t[-1], sol.y[:, -1]
            if sol.status == 1:
                contact = False
                if len(sol.t_events[1]) and (not len(sol.t_events[0]) or sol.t_events[1][0] <= sol.t_events[0][0]):
                    open_impact = False
        else:
            if ev_delta(t, y) > 0 and open_impact:
                e1 = lambda t, y: ev_force(t, y)  # noqa: E731
                e1.terminal, e1.direction = True, 1
                e2 = lambda t, y: ev_delta(t, y)  # noqa: E731
                e2.terminal, e2.direction = True, -1
                sol = solve_ivp(f_free, (t, duration), y, method="DOP853", rtol=rtol, atol=atol, events=(e1, e2),
                                max_step=5e-3)
                t, y = sol.t[-1], sol.y[:, -1]
                if sol.status == 1:
                    if len(sol.t_events[0]) and (not len(sol.t_events[1]) or sol.t_events[0][0] < sol.t_events[1][0]):
                        contact = True
                    else:
                        open_impact = False
                continue
            e = lambda t, y: ev_delta(t, y)  # noqa: E731
            e.terminal, e.direction = True, 1
            sol = solve_ivp(f_free, (t, duration), y, method="DOP853", rtol=rtol, atol=atol, events=e, max_step=5e-3)
            t, y = sol.t[-1], sol.y[:, -1]
            if sol.status == 1:
                contact = True
                open_impact = True
                v = length * y[1] * math.cos(y[0])
                impacts.append(RefImpact(t, c * v, v))
    return impacts


def steady_peak(impacts: list[RefImpact], frequency: float, t_from: float, t_to: float) -> tuple[float, float]:
    """Largest peak force and impacts per excitation cycle over ``[t_from, t_to)``."""
    sel = [i for i in impacts if t_from <= i.t_start < t_to]
    peak = max((i.peak_force for i in sel), default=0.0)
    return peak, len(sel) / ((t_to - t_from) * frequency)
