"""The model's declared valid domain: named rules every point of every analysis is checked against.

The paper's model (docs/physics.md) is a pendulum hanging on wires, hitting a force sensor through a contact law
identified from single impacts of about 100 N. Outside some bounds its equations still integrate, but what they
give is no longer the rig's physics: a pendulum spinning over its pivot, meganewton contact forces, an endless
sequence of micro-contacts. An analysis point whose run leaves this domain is *marked* with the rule it broke
(its name, bound and unit), never silently reported as a result; the verbs say so on their last line and exit
with status 3 (docs/analyses.md, "The model's valid domain").

The rules (:func:`domain` builds them for a configuration):

* ``pendulum_angle``: ``|theta| <= 90 deg`` over the whole run of the point. The hammer hangs on wires and the
  model's impact line is ``l sin(theta)`` (paper Eqs. 4-5: penetration ``l sin(theta) - gap``): beyond 90 deg
  the hammer would stand above its pivot, which wires cannot hold (they go slack), and ``sin(theta)`` turns back,
  so the stop would be met again from the far side of the pivot. Checked at the end of every integration step
  (steps are at most ``integrator.max_step`` long).
* ``contact_force``: the largest contact force of the run's impacts (the force sensor's reading) at most the
  force sensor's compression range, ``channels.impact_force.range_max`` (2224 N for the PCB 208C03 of
  config/rimd.yaml). Above it the instrument saturates, so the twin can no longer be compared with a
  measurement, and the force is 20-30 times the forces the contact law was identified at (paper Table 2, Fig. 8:
  about 80-120 N): the law is extrapolated far out of its identification.
* ``chattering``: the integrator's chattering guard (docs/physics.md, Integrator: more than
  ``ZENO_MAX_EVENTS`` = 400 switches within ``ZENO_WINDOW`` = 1 ms) fired: a Zeno accumulation of contacts the
  event-driven Filippov model cannot resolve. The point's run stops there; its measures are not available.
* ``impacts_per_cycle``: at most :data:`MAX_IMPACTS_PER_CYCLE` (10) impacts per excitation cycle, over the
  cycles the analysis measures. Each impact is a separation and a return to the stop; the rig's and the
  paper's motions have at most a few per cycle (Table 1, Figs 9-12: 1/1, 1/2, 2/2 ...); tens per cycle are a
  near-Zeno cascade of micro-impacts below the guard's rate, where the rigid-stop model with a law identified
  from single impacts does not hold.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from rimd_sim.settings.config import SimConfig

__all__ = [
    "CHATTERING", "CONTACT_FORCE", "IMPACTS_PER_CYCLE", "MAX_ANGLE", "MAX_IMPACTS_PER_CYCLE", "PENDULUM_ANGLE",
    "RULE_NAMES", "PointMeasures", "Rule", "ValidityDomain", "Verdict", "domain", "force_bound", "joined",
]

PENDULUM_ANGLE = "pendulum_angle"
CONTACT_FORCE = "contact_force"
CHATTERING = "chattering"
IMPACTS_PER_CYCLE = "impacts_per_cycle"
#: The rules' names in the domain's order (the order of :func:`domain` and of every ``invalid_rule`` field).
RULE_NAMES = (PENDULUM_ANGLE, CONTACT_FORCE, CHATTERING, IMPACTS_PER_CYCLE)

#: Largest pendulum angle magnitude of the model's geometry (rad): the hammer level with its pivot.
MAX_ANGLE = math.pi / 2.0
#: Largest plausible number of impacts per excitation cycle (see the module docstring).
MAX_IMPACTS_PER_CYCLE = 10.0


@dataclass(frozen=True)
class Rule:
    """One rule of the valid domain.

    Attributes:
        name: Stable name (``pendulum_angle``, ``contact_force``, ``chattering``, ``impacts_per_cycle``).
        quantity: What is bounded, in words.
        bound: The largest value allowed (in ``unit``); NaN for a rule without a bound (``chattering``).
        unit: Unit of ``bound``.
        why: Why the model does not hold beyond it.
    """

    name: str
    quantity: str
    bound: float
    unit: str
    why: str

    def describe(self) -> str:
        """The broken rule in a few characters: ``contact_force > 2224 N``, ``chattering``."""
        if math.isnan(self.bound):
            return self.name
        if self.name == PENDULUM_ANGLE:
            return f"|theta| > {math.degrees(self.bound):g} deg"
        return f"{self.name} > {self.bound:g}{' ' + self.unit if self.unit else ''}"

    def as_dict(self) -> dict:
        """The rule for a summary file."""
        return {"name": self.name, "quantity": self.quantity, "bound": None if math.isnan(self.bound) else self.bound,
                "unit": self.unit, "why": self.why}


@dataclass(frozen=True)
class PointMeasures:
    """What an analysis measured on one point's run, as the rules need it.

    Attributes:
        max_abs_theta: Largest ``|theta|`` over the run (rad), NaN when not measured.
        peak_force: Largest contact force of the run's impacts (N), 0 without impact, NaN when not measured.
        impacts_per_cycle: Impacts per excitation cycle over the measured cycles, NaN when not measured.
        chattering: Whether the integrator's chattering guard stopped the run.
    """

    max_abs_theta: float = math.nan
    peak_force: float = math.nan
    impacts_per_cycle: float = math.nan
    chattering: bool = False


@dataclass(frozen=True)
class Verdict:
    """Whether one point lies in the valid domain, and the rules it broke.

    Attributes:
        rules: Names of the broken rules, in the domain's order (empty when valid).
    """

    rules: tuple[str, ...] = ()

    @classmethod
    def of(cls, invalid_rule: str) -> Verdict:
        """The verdict an ``invalid_rule`` field holds."""
        return cls(tuple(invalid_rule.split(";"))) if invalid_rule else VALID

    @property
    def valid(self) -> bool:
        """No rule broken."""
        return not self.rules

    @property
    def invalid_rule(self) -> str:
        """The broken rules as one field (``contact_force;pendulum_angle``), ``""`` when valid."""
        return ";".join(self.rules)


VALID = Verdict()


@dataclass(frozen=True)
class ValidityDomain:
    """The rules of one configuration (:func:`domain`)."""

    rules: tuple[Rule, ...]

    def rule(self, name: str) -> Rule:
        """The rule named ``name``."""
        return next(r for r in self.rules if r.name == name)

    def check(self, m: PointMeasures) -> Verdict:
        """The rules ``m`` breaks (a measure that is NaN breaks none)."""
        broken = []
        for r in self.rules:
            if r.name == PENDULUM_ANGLE:
                bad = m.max_abs_theta > r.bound
            elif r.name == CONTACT_FORCE:
                bad = m.peak_force > r.bound
            elif r.name == IMPACTS_PER_CYCLE:
                bad = m.impacts_per_cycle > r.bound
            else:
                bad = m.chattering
            if bad:
                broken.append(r.name)
        return Verdict(tuple(broken)) if broken else VALID

    def report(self, verdicts) -> dict:
        """The ``validity`` entry of a summary file: counts per rule and the rules themselves.

        One pass over ``verdicts`` (any iterable), counting each distinct set of broken rules; the counts per rule
        come from those few sets.
        """
        counts = Counter(v.rules for v in verdicts)
        by_rule = {r.name: sum(n for rules, n in counts.items() if r.name in rules) for r in self.rules}
        return {"points": sum(counts.values()), "invalid": sum(n for rules, n in counts.items() if rules),
                "by_rule": {name: n for name, n in by_rule.items() if n},
                "rules": [r.as_dict() for r in self.rules]}

    def sentence(self, verdicts, points: str = "points") -> str:
        """``3 of 40 points outside the model's valid domain (contact_force > 2224 N: 3)``, or ``""`` if none.

        ``points`` names what the verdicts are of (a map's ``cells``, ``initial conditions``).
        """
        rep = self.report(verdicts)
        if not rep["invalid"]:
            return ""
        rules = ", ".join(f"{self.rule(name).describe()}: {n}" for name, n in rep["by_rule"].items())
        return f"{rep['invalid']} of {rep['points']} {points} outside the model's valid domain ({rules})"


def joined(names) -> str:
    """Rule names (any order, repeats allowed) as one ``invalid_rule`` field, in the domain's order."""
    present = set(names)
    return ";".join(name for name in RULE_NAMES if name in present)


def force_bound(config: SimConfig) -> float:
    """The ``contact_force`` bound of ``config`` (N): the force sensor's compression range."""
    return next(c.range_max for c in config.channels if c.name == "impact_force")


def domain(config: SimConfig) -> ValidityDomain:
    """The model's valid domain for ``config`` (module docstring), its rules in :data:`RULE_NAMES`' order."""
    return ValidityDomain((
        Rule(PENDULUM_ANGLE, "largest |theta| over the run", MAX_ANGLE, "rad",
             "the hammer hangs on wires and meets the stop along l sin(theta): past 90 deg it would stand above "
             "its pivot (slack wires) and sin(theta) turns back"),
        Rule(CONTACT_FORCE, "largest contact force of the run's impacts", force_bound(config), "N",
             "the force sensor's compression range (channels.impact_force.range_max): above it the instrument "
             "saturates and the contact law, identified at about 100 N, is extrapolated"),
        Rule(CHATTERING, "the integrator's chattering guard (400 switches within 1 ms)", math.nan, "",
             "a Zeno accumulation of contacts the event-driven Filippov model cannot resolve; the run stops"),
        Rule(IMPACTS_PER_CYCLE, "impacts per excitation cycle over the measured cycles", MAX_IMPACTS_PER_CYCLE, "",
             "tens of impacts per cycle are a near-Zeno cascade of micro-impacts, outside a rigid-stop model "
             "identified from single impacts"),
    ))
