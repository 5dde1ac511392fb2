"""Continuation of periodic impacting orbits, with their stability and their bifurcations.

A periodic motion of period ``n`` excitation cycles is a fixed point of ``P^n``, where ``P`` is the
stroboscopic map: it advances a *point* ``x = (theta, theta_dot, m_1 .. m_k)`` (the pendulum and the model's own
modes) by one excitation period ``T = 1 / f`` at a constant motor frequency. This module follows such fixed
points as a parameter ``lambda`` varies (the motor frequency by default, or any numeric parameter of the rig),
computes their Floquet multipliers, and detects and locates where their stability changes.

Method
------
* **Shooting** (:mod:`rimd_sim.analysis.dynamics.fixed_points`): ``G(x, lambda) = P^n(x; lambda) - x`` is
  evaluated with the event-exact integrator at tightened tolerances, its Jacobian and the monodromy matrix
  ``M = dP^n/dx`` by central differences of the flow through the impacts (so the saltation at each switch is in
  the difference). The Floquet multipliers are the eigenvalues of ``M`` at the fixed point; the orbit is stable
  when they all lie inside the unit circle.
* **Pseudo-arclength continuation** (Keller 1977; the predictor-corrector of AUTO, COCO and BifurcationKit.jl's
  ``PALC``): from a point ``z = (x, lambda)`` with unit tangent ``t`` (the null vector of
  ``[dG/dx, dG/dlambda]``), predict ``z + ds t`` and correct by Newton's method on ``G = 0`` together with
  ``t . (z - z_pred) = 0``. The step ``ds`` grows after an easy correction (at most 2 Newton iterations) and
  shrinks after a hard or failed one, or when the multipliers or the number of impacts per period change much
  in one step. Folds are passed (the parameter turns back), unstable orbits are followed.
* **Detection** between two consecutive points of a branch, by the sign changes of test functions (Kuznetsov
  2004, ch. 10; the same as BifurcationKit's): period doubling ``prod(mu_i + 1)``, fold the parameter's
  component of the tangent, Neimark-Sacker ``prod_{i<j}(mu_i mu_j - 1)`` with the crossing pair complex; a
  change of ``prod(mu_i - 1)`` without a turn of the parameter is a branch point. **Grazing** (a non-smooth
  bifurcation: di Bernardo et al. 2008, ch. 4; Nordmark 1991) is where the number of impacts per period
  changes: a non-impacting orbit first touches the stop, or an impacting one gains a new, grazing contact.
* **Location.** The point is refined on the chord between the two points (the corrector solved on the
  hyperplane through ``z_a + s (z_b - z_a)`` normal to the chord): regula falsi (Illinois) on the test function,
  bisection on the impact count for grazing, to :attr:`ContinuationSettings.locate_tolerance` in the parameter.
* **Branch switching at a period doubling**: the period-``2n`` orbit born there is a fixed point of ``P^{2n}``
  whose branch crosses the period-``n`` one at the bifurcation with tangent ``(v, 0)``, ``v`` the eigenvector
  of the multiplier ``-1``. The ``2n`` problem is predicted along ``v`` and corrected on the hyperplane normal
  to it (so the corrector cannot fall back onto the period-``n`` orbit), then continued like any branch. A
  branch that comes back onto a period-``n`` orbit (the other end of a period-doubling "bubble") ends there.

Validity: every point of every branch is checked against the model's valid domain
(:mod:`rimd_sim.model.validity`) over one period of its orbit (largest ``|theta|``, peak force, impacts per
cycle); the chattering guard ends a branch.

References: H. B. Keller (1977), numerical solution of bifurcation and nonlinear eigenvalue problems;
Yu. A. Kuznetsov (2004), Elements of Applied Bifurcation Theory, 3rd ed.; M. di Bernardo, C. J. Budd,
A. R. Champneys, P. Kowalczyk (2008), Piecewise-smooth Dynamical Systems; A. B. Nordmark (1991), J. Sound Vib.
145; P. C. Müller (1995), Z. angew. Math. Mech. 75; H. Dankowicz and F. Schilder (2013), Recipes for
Continuation (COCO's ``hspo`` toolbox of hybrid periodic orbits); R. Veltz, BifurcationKit.jl.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from rimd_sim.analysis.dynamics.fixed_points import (
    FD_STEP,
    FREQUENCY,
    SHOOTING_TOLERANCES,
    FlowFailed,
    Problem,
    Solved,
    correct,
    floquet_multipliers,
    full_point,
    measure_orbit,
    shooting_problem,
    unit_tangent,
)
from rimd_sim.analysis.dynamics.steady import CHAOTIC, check_frequency, steady_orbit
from rimd_sim.errors import AnalysisError, ConfigError
from rimd_sim.model.rig_model import ChatteringError
from rimd_sim.model.validity import CHATTERING, PointMeasures, domain, joined
from rimd_sim.settings.config import SimConfig

__all__ = [
    "BIFURCATION_KINDS", "FD_STEP", "SHOOTING_TOLERANCES", "Bifurcation", "Branch", "BranchPoint",
    "ContinuationResult", "ContinuationSettings", "StartOutsideDomain", "continuation", "fixed_point", "monodromy",
]

#: The kinds of :class:`Bifurcation`.
BIFURCATION_KINDS = ("period_doubling", "fold", "neimark_sacker", "grazing", "branch_point")
#: Largest penetration (m) within which a non-impacting orbit is said to graze the stop.
GRAZE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ContinuationSettings:
    """How a branch is followed (docs/analyses.md, "`rimd continue`", says how to choose them).

    Attributes:
        ds: First arclength step (scaled units: the parameter's range is 50).
        ds_min: Smallest step before a branch is given up.
        ds_max: Largest step.
        newton_tolerance: Largest scaled residual ``|P^n(x) - x|`` of a converged point.
        max_newton: Newton iterations before a step is retried shorter.
        max_points: Points per branch at most.
        max_period: Longest period a branch switch creates (cycles).
        switch: Switch branches at period doublings.
        locate_tolerance: Width (in the parameter) to which a bifurcation is located.
        max_multiplier_change: Largest change of a multiplier in one step (the step is shortened beyond).
    """

    ds: float = 0.25
    ds_min: float = 1e-4
    ds_max: float = 1.0
    newton_tolerance: float = 1e-9
    max_newton: int = 7
    max_points: int = 400
    max_period: int = 8
    switch: bool = True
    locate_tolerance: float = 1e-6
    max_multiplier_change: float = 0.25


@dataclass(frozen=True)
class BranchPoint:
    """A periodic orbit of a branch.

    Attributes:
        parameter: The continuation parameter's value.
        frequency_hz: Motor frequency (Hz).
        point: The fixed point ``(theta, theta_dot, modes...)`` of ``P^n`` (phase 0 of the motor).
        multipliers: Floquet multipliers, largest modulus first.
        stable: All multipliers inside the unit circle.
        orbit: The ``n`` stroboscopic points of the orbit (rows ``(theta, theta_dot)``).
        peak_force_n: Largest peak force of the orbit's impacts over one period (N; 0 without impact).
        impacts_per_period: Impacts per period of ``n`` cycles.
        max_penetration_m: Largest ``delta`` over the period (m; < 0: the orbit does not reach the stop).
        max_abs_theta_rad: Largest ``|theta|`` over the period (rad).
        valid: Whether the orbit lies in the model's valid domain.
        invalid_rule: The rules it broke.
    """

    parameter: float
    frequency_hz: float
    point: np.ndarray
    multipliers: np.ndarray
    stable: bool
    orbit: np.ndarray
    peak_force_n: float
    impacts_per_period: int
    max_penetration_m: float
    max_abs_theta_rad: float
    valid: bool = True
    invalid_rule: str = ""

    @property
    def max_multiplier(self) -> float:
        """Largest multiplier modulus."""
        return float(abs(self.multipliers[0]))


@dataclass(frozen=True)
class Bifurcation:
    """A located bifurcation.

    Attributes:
        kind: One of :data:`BIFURCATION_KINDS`.
        parameter: The parameter's value there.
        frequency_hz: Motor frequency there (Hz).
        period: Period of the branch it lies on (cycles).
        branch: Index of that branch.
        point: The fixed point there.
        multipliers: The multipliers there (largest modulus first).
        detail: In words (the crossing multiplier, the impact counts either side).
        new_branch: Index of the branch switched to (period doubling), or None.
    """

    kind: str
    parameter: float
    frequency_hz: float
    period: int
    branch: int
    point: np.ndarray
    multipliers: np.ndarray
    detail: str
    new_branch: int | None = None


@dataclass(frozen=True)
class Branch:
    """One branch of periodic orbits.

    Attributes:
        index: Its index in :attr:`ContinuationResult.branches`.
        period: Period (excitation cycles).
        points: Its points, in the order followed.
        parent: The branch it was switched from (None for the first).
        end: Why it ended.
    """

    index: int
    period: int
    points: tuple[BranchPoint, ...]
    parent: int | None
    end: str


@dataclass(frozen=True)
class ContinuationResult:
    """Branches and bifurcations of one continuation run.

    Attributes:
        parameter: The continuation parameter (``frequency`` or a parameter name of the configuration).
        start: Start of the range.
        end: End of the range.
        branches: The branches, the first one from the start.
        bifurcations: Located bifurcations, in the order found.
        evaluations: Periods integrated (the cost).
    """

    parameter: str
    start: float
    end: float
    branches: tuple[Branch, ...]
    bifurcations: tuple[Bifurcation, ...]
    evaluations: int = 0

    def of_kind(self, kind: str) -> list[Bifurcation]:
        """The bifurcations of one kind."""
        return [b for b in self.bifurcations if b.kind == kind]


class StartOutsideDomain(AnalysisError):
    """No orbit to start from, and the motion at the start leaves the model's valid domain.

    Attributes:
        invalid_rule: The rules it broke (:mod:`rimd_sim.model.validity`).
    """

    def __init__(self, message: str, invalid_rule: str = ""):
        super().__init__(message)
        self.invalid_rule = invalid_rule


def _point(problem: Problem, solved: Solved, rules) -> tuple[BranchPoint, dict]:
    x, lam = problem.unscale(solved.z)
    mu = floquet_multipliers(solved.mono)
    m = measure_orbit(problem, x, lam)
    verdict = rules.check(PointMeasures(m["max_theta"], m["peak"], m["impacts"] / problem.period))
    bp = BranchPoint(lam, problem.frequency_at(lam), x, mu, bool(np.all(np.abs(mu) < 1.0)), m["orbit"], m["peak"],
                     m["impacts"], m["max_delta"], m["max_theta"], verdict.valid, verdict.invalid_rule)
    return bp, m


@dataclass
class _Node:
    """A converged point with what detection needs."""

    solved: Solved
    tangent: np.ndarray
    point: BranchPoint


def _tests(node: _Node) -> dict[str, float]:
    mu = node.point.multipliers
    prod_pd = float(np.real(np.prod(mu + 1.0)))
    prod_bp = float(np.real(np.prod(mu - 1.0)))
    ns = 1.0
    for i in range(mu.size):
        for j in range(i + 1, mu.size):
            ns *= (mu[i] * mu[j] - 1.0)
    return {"period_doubling": prod_pd, "fold": float(node.tangent[-1]), "branch_point": prod_bp,
            "neimark_sacker": float(np.real(ns))}


#: Test-function values below this are round-off (a sign change between two such values is not a crossing).
TEST_NOISE = 1e-4
#: How close to the unit circle the critical multiplier of a located bifurcation must be (else the test
#: function changed sign across a non-smooth transition, where the multipliers jump: not a bifurcation).
CRITICAL_TOLERANCE = 1e-2


def _critical(kind: str, mu: np.ndarray, tangent: np.ndarray) -> bool:
    if kind == "period_doubling":
        return bool(np.min(np.abs(mu + 1.0)) < CRITICAL_TOLERANCE)
    if kind == "neimark_sacker":
        pair = mu[np.abs(np.imag(mu)) > 1e-9 * np.abs(mu)]
        return bool(pair.size and np.min(np.abs(np.abs(pair) - 1.0)) < CRITICAL_TOLERANCE)
    if kind == "fold":
        return bool(np.min(np.abs(mu - 1.0)) < CRITICAL_TOLERANCE or abs(tangent[-1]) < CRITICAL_TOLERANCE)
    return bool(np.min(np.abs(mu - 1.0)) < CRITICAL_TOLERANCE)


class _Continuer:
    def __init__(self, config: SimConfig, parameter: str, lam_start: float, lam_end: float, frequency_hz: float,
                 settings: ContinuationSettings):
        self.settings = settings
        self.rules = domain(config)
        self.parameter = parameter
        self.lam_lo, self.lam_hi = min(lam_start, lam_end), max(lam_start, lam_end)
        self.lam_start, self.lam_end = lam_start, lam_end
        self.base = shooting_problem(config, parameter, lam_start, lam_end, frequency_hz)
        self.branches: list[Branch] = []
        self.bifurcations: list[Bifurcation] = []

    # ---- one branch ------------------------------------------------------------------------------

    def in_range(self, lam: float) -> bool:
        span = self.lam_hi - self.lam_lo
        return self.lam_lo - 1e-9 * span <= lam <= self.lam_hi + 1e-9 * span

    def node(self, problem: Problem, solved: Solved, prev_t: np.ndarray | None) -> _Node:
        t = unit_tangent(solved.jac, prev_t)
        bp, _ = _point(problem, solved, self.rules)
        return _Node(solved, t, bp)

    def follow(self, problem: Problem, first: _Node, parent: int | None, origin: np.ndarray | None = None
               ) -> int:
        """Follow a branch from ``first`` along its tangent; record it and its bifurcations; return its index."""
        s = self.settings
        index = len(self.branches)
        nodes = [first]
        self.branches.append(Branch(index, problem.period, (first.point,), parent, "following"))
        ds = s.ds
        end = f"{s.max_points} points reached"
        pending: list[tuple[str, _Node, _Node]] = []
        while len(nodes) < s.max_points:
            cur = nodes[-1]
            z_pred = cur.solved.z + ds * cur.tangent
            solved = correct(problem, z_pred, cur.tangent, s.newton_tolerance, s.max_newton)
            if solved is None:
                ds *= 0.5
                if ds < s.ds_min:
                    end = "the corrector failed (step below ds_min)"
                    break
                continue
            lam_new = problem.unscale(solved.z)[1]
            if not self.in_range(lam_new):
                # The end of the range: the point on it, by the corrector with the parameter fixed.
                edge = (self.lam_hi if lam_new > self.lam_hi else self.lam_lo) / problem.lam_scale
                step = solved.z - cur.solved.z
                z_end = cur.solved.z + step * (edge - cur.solved.z[-1]) / step[-1]
                z_end[-1] = edge
                last = correct(problem, z_end, None, s.newton_tolerance, 2 * s.max_newton)
                end = "end of the range"
                if last is not None:
                    try:
                        new = self.node(problem, last, cur.tangent)
                    except ChatteringError:
                        break
                    pending.extend(self.detect(cur, new))
                    nodes.append(new)
                break
            try:
                new = self.node(problem, solved, cur.tangent)
            except ChatteringError:
                end = "the chattering guard fired (outside the valid domain)"
                break
            m_new, m_cur = new.point.multipliers[:2], cur.point.multipliers[:2]
            change = float(np.max(np.abs(m_new - m_cur) / np.maximum(1.0, np.abs(m_cur))))
            if change > s.max_multiplier_change and ds > 4 * s.ds_min:
                ds *= 0.5
                continue
            if origin is not None and problem.period > 1:
                # Back onto an orbit of half the period (the other end of a period-doubling bubble)?
                x, lam = problem.unscale(new.solved.z)
                half = problem.with_period(problem.period // 2)
                try:
                    y = half.flow(x[None, :], np.array([lam]))[0]
                    if np.linalg.norm((y - x) / problem.scale) < 1e-5:
                        end = f"joins a period-{problem.period // 2} orbit (a period doubling's other end)"
                        nodes.append(new)
                        break
                except FlowFailed:
                    pass
            pending.extend(self.detect(cur, new))
            nodes.append(new)
            if solved.iterations <= 2:
                ds = min(ds * 1.5, s.ds_max)
            elif solved.iterations >= 5:
                ds = max(ds / 1.5, s.ds_min)
        if end.startswith("the corrector failed") and len(nodes) >= 2 and nodes[-1].point.impacts_per_period == 0:
            graze = self.graze_ahead(problem, index, nodes[-2], nodes[-1])
            if graze is not None:
                end = "grazing: the orbit touches the stop (the corrector does not pass the non-smooth point)"
        if end.startswith("the corrector failed") and not end.startswith("grazing"):
            tip = nodes[-1].point
            end += (f" after {self.parameter} {tip.parameter:.6g}: the last orbit has {tip.impacts_per_period} "
                    f"impact(s) per period and a largest |multiplier| of {tip.max_multiplier:.3g}; Newton's method "
                    "does not pass a non-smooth point of the branch there (a new contact grazing, a dwell on the "
                    "stop): continue from the other side, or look with rimd bifurcation")
        self.branches[index] = Branch(index, problem.period, tuple(n.point for n in nodes), parent, end)
        for kind, a, b in pending:
            self.locate(problem, index, kind, a, b)
        return index

    def detect(self, a: _Node, b: _Node) -> list[tuple[str, _Node, _Node]]:
        found = []
        if a.point.impacts_per_period != b.point.impacts_per_period:
            found.append(("grazing", a, b))
        reach = 100.0 * FD_STEP * self.base.config.rig.amplitude
        if any(n.point.impacts_per_period == 0 and n.point.max_penetration_m > -reach for n in (a, b)):
            # The differences' perturbations reach the stop: the Jacobian straddles the grazing, its multipliers
            # are not the orbit's.
            return found
        ta, tb = _tests(a), _tests(b)
        for kind in ("period_doubling", "fold", "neimark_sacker", "branch_point"):
            if kind == "neimark_sacker" and min(abs(ta[kind]), abs(tb[kind])) <= TEST_NOISE:
                continue  # conservative orbits (det M = 1): both ends must be clear of the noise
            # A sign change within the test function's noise is none: the undamped pendulum's non-impacting
            # orbits are conservative (det M = 1 exactly, so prod(mu_i mu_j - 1) is round-off).
            if ta[kind] * tb[kind] < 0 and max(abs(ta[kind]), abs(tb[kind])) > TEST_NOISE:
                if kind == "branch_point" and ta["fold"] * tb["fold"] < 0:
                    continue  # the fold's own sign change of det(M - I)
                if kind == "neimark_sacker":
                    crit = [m for m in (a.point.multipliers, b.point.multipliers)
                            if np.any(np.abs(np.imag(m)) > 1e-9 * np.abs(m))]
                    if not crit:
                        continue  # a neutral saddle (two real multipliers with product 1): no bifurcation
                found.append((kind, a, b))
        return found

    # ---- location ---------------------------------------------------------------------------------

    def on_chord(self, problem: Problem, a: _Node, b: _Node, sigma: float, prev_t: np.ndarray) -> _Node | None:
        chord = b.solved.z - a.solved.z
        normal = chord / np.linalg.norm(chord)
        solved = correct(problem, a.solved.z + sigma * chord, normal, self.settings.newton_tolerance,
                          self.settings.max_newton)
        if solved is None:
            return None
        try:
            return self.node(problem, solved, prev_t)
        except ChatteringError:
            return None

    def locate(self, problem: Problem, branch: int, kind: str, a: _Node, b: _Node) -> None:
        s = self.settings
        lo, hi = 0.0, 1.0
        na, nb = a, b
        if kind == "grazing":
            side = a.point.impacts_per_period
            while abs(nb.point.parameter - na.point.parameter) > s.locate_tolerance:
                mid = self.on_chord(problem, a, b, 0.5 * (lo + hi), a.tangent)
                if mid is None:
                    break
                if mid.point.impacts_per_period == side:
                    lo, na = 0.5 * (lo + hi), mid
                else:
                    hi, nb = 0.5 * (lo + hi), mid
            at = nb if nb.point.max_penetration_m >= 0 else na
            detail = (f"impacts per period {a.point.impacts_per_period} -> {b.point.impacts_per_period}; "
                      f"largest penetration {at.point.max_penetration_m:.3g} m")
        else:
            fa, fb = _tests(a)[kind], _tests(b)[kind]
            side = 0
            for _ in range(60):
                if abs(nb.point.parameter - na.point.parameter) <= s.locate_tolerance:
                    break
                sigma = (lo * fb - hi * fa) / (fb - fa) if fb != fa else 0.5 * (lo + hi)
                sigma = min(max(sigma, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
                mid = self.on_chord(problem, a, b, sigma, a.tangent)
                if mid is None:
                    break
                fm = _tests(mid)[kind]
                if fm * fa > 0:
                    lo, fa, na = sigma, fm, mid
                    if side == -1:
                        fb *= 0.5
                    side = -1
                else:
                    hi, fb, nb = sigma, fm, mid
                    if side == 1:
                        fa *= 0.5
                    side = 1
            at = na if abs(fa) <= abs(fb) else nb
            mu = at.point.multipliers
            if not _critical(kind, mu, at.tangent):
                return  # the sign changed across a non-smooth transition (a grazing), not by a crossing
            if kind == "period_doubling":
                detail = f"a real multiplier crosses -1 (nearest {mu[np.argmin(np.abs(mu + 1.0))]:.6g})"
            elif kind == "neimark_sacker":
                detail = f"a complex pair crosses the unit circle (|mu| = {abs(mu[0]):.6g})"
            elif kind == "fold":
                nearest = mu[np.argmin(np.abs(mu - 1.0))]
                detail = f"the parameter turns back; a real multiplier crosses +1 ({nearest:.6g})"
            else:
                detail = "a real multiplier crosses +1 without a fold"
        bif = Bifurcation(kind, at.point.parameter, at.point.frequency_hz, problem.period, branch, at.point.point,
                          at.point.multipliers, detail)
        self.bifurcations.append(bif)
        if kind == "period_doubling" and self.settings.switch and 2 * problem.period <= self.settings.max_period:
            new = self.switch(problem, branch, at)
            if new is not None:
                self.bifurcations[self.bifurcations.index(bif)] = replace(bif, new_branch=new)

    def graze_ahead(self, problem: Problem, branch: int, a: _Node, b: _Node) -> Bifurcation | None:
        """Locate the grazing a non-impacting branch runs into (its corrector failed there).

        The largest penetration ``g`` of the orbit is smooth in the parameter on the non-impacting side: secant
        steps on ``g = 0`` from the last two points, each solved with the parameter fixed, approach the grazing from
        that side (a step goes at most 90 % of the way, so the orbit never impacts) until ``g`` is within
        :data:`GRAZE_TOLERANCE` of 0 or the step is below the location tolerance.
        """
        s = self.settings
        pts = [a, b]
        for _ in range(40):
            p0, p1 = pts[-2].point, pts[-1].point
            g0, g1 = p0.max_penetration_m, p1.max_penetration_m
            if not (g1 < 0 and g1 != g0):
                return None
            if abs(g1) <= GRAZE_TOLERANCE:
                break
            lam_zero = p1.parameter - g1 * (p1.parameter - p0.parameter) / (g1 - g0)
            step = lam_zero - p1.parameter
            if abs(step) <= s.locate_tolerance:
                break
            z = pts[-1].solved.z.copy()
            z[-1] = (p1.parameter + (0.9 if abs(g1) > 1e3 * GRAZE_TOLERANCE else 1.0) * step) / problem.lam_scale
            solved = correct(problem, z, None, s.newton_tolerance, s.max_newton)
            if solved is None:
                break
            try:
                node = self.node(problem, solved, pts[-1].tangent)
            except ChatteringError:
                break
            if node.point.impacts_per_period != 0:
                break
            pts.append(node)
        at = pts[-1]
        if at.point.max_penetration_m < -1e-3 * self.base.config.rig.amplitude:
            return None  # not near the stop: the corrector failed for another reason
        bif = Bifurcation("grazing", at.point.parameter, at.point.frequency_hz, problem.period, branch,
                          at.point.point, at.point.multipliers,
                          f"the non-impacting orbit touches the stop (largest penetration "
                          f"{at.point.max_penetration_m:.3g} m)")
        self.bifurcations.append(bif)
        return bif

    # ---- branch switching -------------------------------------------------------------------------

    def switch(self, problem: Problem, parent: int, at: _Node) -> int | None:
        double = problem.with_period(2 * problem.period)
        for b in self.branches:  # a bubble's other end: its period-2n branch is already followed
            if b.period == double.period and any(
                    np.linalg.norm((p.point - at.point.point) / problem.scale) < 1e-3
                    and abs(p.parameter - at.point.parameter) < 1e-3 * problem.lam_scale for p in b.points):
                return None
        a = at.solved.mono
        mu, vecs = np.linalg.eig(a)
        v = np.real(vecs[:, int(np.argmin(np.abs(mu + 1.0)))])
        v = v / np.linalg.norm(v)
        tan = np.append(v, 0.0)
        z0 = at.solved.z
        for amp in (0.02, 0.08, 0.3, 1.0):
            solved = correct(double, z0 + amp * tan, tan, self.settings.newton_tolerance, self.settings.max_newton)
            if solved is None:
                continue
            x, lam = double.unscale(solved.z)
            try:
                y = problem.flow(x[None, :], np.array([lam]))[0]
            except FlowFailed:
                continue
            if np.linalg.norm((y - x) / problem.scale) < 1e-4 or not self.in_range(lam):
                continue  # fell back onto the period-n orbit, or out of the range
            try:
                first = self.node(double, solved, None)
            except ChatteringError:
                continue
            t = first.tangent
            if t @ (solved.z - z0) < 0:
                t = -t
            first = _Node(first.solved, t, first.point)
            return self.follow(double, first, parent, origin=z0)
        return None


def fixed_point(config: SimConfig, frequency_hz: float, start, *, period: int = 1,
                tolerance: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """The fixed point of ``P^period`` near ``start`` at one frequency, and its Floquet multipliers.

    Args:
        config: Rig configuration (its tolerances are tightened to :data:`SHOOTING_TOLERANCES`).
        frequency_hz: Motor frequency (Hz).
        start: A point ``(theta, theta_dot, modes...)`` near the orbit (modes default to rest).
        period: Period (cycles).
        tolerance: Newton's scaled residual.

    Returns:
        ``(point, multipliers)``: the fixed point (unscaled) and its Floquet multipliers, largest modulus first.

    Raises:
        AnalysisError: When Newton's method does not converge from ``start``.
    """
    f = check_frequency(config, frequency_hz)
    problem = shooting_problem(config, FREQUENCY, f, f + 1.0, f).with_period(period)
    x0 = full_point(config, start)
    solved = correct(problem, problem.scaled(x0, f), None, tolerance, 12)
    if solved is None:
        raise AnalysisError(f"no period-{period} orbit found near {tuple(x0)} at {f:g} Hz (Newton did not converge)")
    x, _ = problem.unscale(solved.z)
    return x, floquet_multipliers(solved.mono)


def monodromy(config: SimConfig, frequency_hz: float, point, *, period: int = 1) -> np.ndarray:
    """The monodromy matrix ``dP^period/dx`` at ``point`` (unscaled), by the continuation's central differences.

    Args:
        config: Rig configuration (its tolerances are tightened to :data:`SHOOTING_TOLERANCES`).
        frequency_hz: Motor frequency (Hz).
        point: ``(theta, theta_dot, modes...)`` (modes default to rest), at motor phase 0.
        period: Period (cycles).

    Returns:
        The square matrix, one row and column per component of the point.
    """
    f = check_frequency(config, frequency_hz)
    problem = shooting_problem(config, FREQUENCY, f, f + 1.0, f).with_period(period)
    x0 = full_point(config, point)
    _, _, mono = problem.evaluate(problem.scaled(x0, f))
    return mono * problem.scale[:, None] / problem.scale[None, :]


def continuation(config: SimConfig, start: float, end: float, *, parameter: str = FREQUENCY,
                 frequency_hz: float | None = None, period: int | None = None, initial=None,
                 settings: ContinuationSettings | None = None) -> ContinuationResult:
    """Follow the periodic orbit found at ``start`` to ``end`` (module docstring), switching at period doublings.

    Args:
        config: Rig configuration (any model of the registry).
        start: The parameter's first value (Hz for the frequency).
        end: Its last value.
        parameter: ``frequency`` (the motor's, default) or a numeric parameter of the configuration
            (``gap``, ``mass``, ``damping_ratio``, ``contact.stiffness``...), then at ``frequency_hz``.
        frequency_hz: The motor frequency when the parameter is not the frequency.
        period: Period of the orbit to start from (cycles); default: the attractor's found at ``start`` from
            ``initial`` (or rest) after a transient.
        initial: A point near the orbit to start from, ``(theta, theta_dot[, modes...])``; default: the attractor's.
        settings: The continuation's settings.

    Returns:
        The branches followed and the bifurcations located on them.

    Raises:
        ConfigError: For a bad range, parameter or frequency.
        AnalysisError: When no periodic orbit is found at the start.
    """
    settings = settings or ContinuationSettings()
    if not (math.isfinite(start) and math.isfinite(end)) or start == end:
        raise ConfigError("range", (start, end), "must be two different finite values")
    if parameter == FREQUENCY:
        check_frequency(config, start)
        check_frequency(config, end)
        f0 = float(start)
    else:
        if frequency_hz is None:
            raise ConfigError("frequency", None, f"is needed when the continuation parameter is {parameter!r}")
        f0 = check_frequency(config, frequency_hz)
        config.with_parameters({parameter: float(start)})  # names and checks the parameter
        config.with_parameters({parameter: float(end)})
    c = _Continuer(config, parameter, float(start), float(end), f0, settings)
    cfg0 = c.base.config_at(start)
    starts = []   # (period, point) tried in turn
    invalid_rules: set[str] = set()
    attractor = "not searched (period and start given)"
    if period is not None and initial is not None:
        starts.append((int(period), initial))
    else:
        th0, om0 = (0.0, 0.0) if initial is None else tuple(np.asarray(initial, dtype=float).ravel()[:2])
        try:
            orbit = steady_orbit(cfg0, f0, theta0=th0, theta_dot0=om0, transient_cycles=400, measure_cycles=48,
                                 max_period=settings.max_period)
        except ChatteringError as error:
            attractor = f"the chattering guard fired ({error})"
            invalid_rules.add(CHATTERING)
        else:
            attractor = (f"{orbit.label}" + ("" if orbit.valid else
                                            f", outside the model's valid domain ({orbit.invalid_rule})"))
            invalid_rules.update(orbit.invalid_rule.split(";") if orbit.invalid_rule else ())
            if orbit.label != CHAOTIC and (period is None or orbit.period in (0, period)):
                starts.append((period or max(orbit.period, 1), orbit.final_state))
        if period in (None, 1):
            # The linear forced response, theta = Theta sin(Omega t): the non-impacting orbit of the linearised
            # pendulum (found this way also where no damping lets a transient die out).
            rig = cfg0.rig
            omega = 2.0 * math.pi * f0
            theta_amp = rig.amplitude * omega ** 2 / rig.length / (rig.omega_n ** 2 - omega ** 2)
            starts.append((1, (0.0, theta_amp * omega)))
    if any(p < 1 for p, _ in starts):
        raise ConfigError("period", period, "must be >= 1")
    solved = None
    for period, guess in starts:
        problem = c.base.with_period(int(period))
        solved = correct(problem, problem.scaled(full_point(cfg0, guess), start), None,
                          settings.newton_tolerance, 12)
        if solved is not None:
            break
    if solved is None:
        tried = "; ".join(f"period {p} from {tuple(round(float(v), 6) for v in np.ravel(g)[:2])}" for p, g in starts)
        message = (f"no periodic orbit found at the start ({parameter} = {start:g}): the motion from rest is "
                   f"{attractor}; tried {tried or 'nothing'} (Newton's method did not converge); give --period and a "
                   f"start near an orbit")
        if invalid_rules:
            raise StartOutsideDomain(message, joined(invalid_rules))
        raise AnalysisError(message)
    direction = np.zeros(solved.z.size)
    direction[-1] = 1.0 if end > start else -1.0
    first = c.node(problem, solved, None)
    t = first.tangent if first.tangent @ direction > 0 else -first.tangent
    c.follow(problem, _Node(first.solved, t, first.point), None)
    return ContinuationResult(parameter, float(start), float(end), tuple(c.branches), tuple(c.bifurcations),
                              c.base.evaluations[0])
