"""The fixed points of the stroboscopic map: ``G(x, lambda) = P^n(x; lambda) - x``, its Jacobian and Newton's method.

``P`` advances a point ``x = (theta, theta_dot, m_1 .. m_k)`` (the pendulum and the model's own modes) by one
excitation period ``T = 1 / f`` at a constant motor frequency; a periodic motion of ``n`` cycles is a fixed point of
``P^n``. The continuation (:mod:`rimd_sim.analysis.dynamics.continuation`) follows such points as a parameter
``lambda`` varies; this module holds the problem it solves.

* **Shooting.** ``G`` is evaluated with the event-exact integrator every other analysis uses
  (:func:`rimd_sim.model.shooting.flow_points` runs a batch of starts in one compiled call), at tightened
  tolerances (:data:`SHOOTING_TOLERANCES`). The unknowns are scaled (:func:`shooting_problem`): ``theta`` by
  ``A0 / l``, ``theta_dot`` by ``Omega A0 / l``, the parameter by a fiftieth of the range.
* **Jacobian and monodromy matrix by central differences of the flow through the impacts.** Each column of
  ``dP^n/dx`` (and ``dP^n/dlambda``) is ``(P^n(x + h e_j) - P^n(x - h e_j)) / 2h``; a perturbed run crosses the
  switching surfaces (contact onset ``delta = 0``, release ``F = 0``) where its own dynamics puts it, so the jumps
  of the linearised flow at the switches (the saltation matrices of a tangent-linear method, Müller 1995; di
  Bernardo et al. 2008, ch. 2) are in the difference, without a formula per contact law. The step ``h`` is
  :data:`FD_STEP` in scaled units: the truncation error is ``O(h^2)`` ~ 1e-10, and the integrator's error enters
  as its *variation* between neighbouring runs (their step sequences coincide), well below 1e-6.
  tests/analysis/dynamics/test_continuation.py checks the multipliers against an independent monodromy matrix
  built from ``RigModel`` runs (to 1e-4) and against the exact ``exp(A T)`` of the linear oscillator. The Floquet
  multipliers are the eigenvalues of ``M = dP^n/dx`` at the fixed point; the orbit is stable when they all lie
  inside the unit circle.
* **Corrector.** Newton's method on ``G = 0`` together with one linear condition ``normal . (z - z_pred) = 0``
  (:func:`correct`): the pseudo-arclength condition, a chord's normal, or the parameter held fixed.

References: P. C. Müller (1995), Z. angew. Math. Mech. 75; M. di Bernardo, C. J. Budd, A. R. Champneys,
P. Kowalczyk (2008), Piecewise-smooth Dynamical Systems.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.steady import constant_frequency
from rimd_sim.analysis.peaks import sampled_peak
from rimd_sim.errors import ConfigError, IntegrationError
from rimd_sim.model import kernel as k
from rimd_sim.model.rig_model import RigModel, model_for
from rimd_sim.model.shooting import flow_points
from rimd_sim.settings.config import SimConfig

__all__ = ["FD_STEP", "FREQUENCY", "SHOOTING_TOLERANCES", "FlowFailed", "Problem", "Solved", "correct",
           "floquet_multipliers", "full_point", "measure_orbit", "shooting_problem", "unit_tangent"]

#: Integrator tolerances of the shooting runs (the continuation's accuracy rests on them; module docstring).
SHOOTING_TOLERANCES = {"integrator.rtol": 1e-10, "integrator.atol": 1e-12}
#: Central-difference step of the Jacobian, in scaled units (module docstring).
FD_STEP = 1e-5
#: The name of the motor frequency as the continuation parameter.
FREQUENCY = "frequency"


class FlowFailed(IntegrationError):
    """A shooting run failed (the chattering guard, a non-finite state); the corrector takes it as no convergence."""

    def __init__(self, status: int = k.ST_OK):
        super().__init__(f"a shooting run stopped with the driver's status {status}")
        self.status = status


@dataclass
class Problem:
    """``G(x, lambda) = P^n(x) - x`` in scaled coordinates."""

    config: SimConfig          # tolerances tightened
    parameter: str
    frequency_hz: float        # fixed frequency when the parameter is another one
    period: int
    scale: np.ndarray          # of the point
    lam_scale: float
    evaluations: list = field(default_factory=lambda: [0])
    _params: dict = field(default_factory=dict)

    @property
    def model(self) -> str:
        """The model's name (:data:`rimd_sim.model.rig_model.MODELS`)."""
        return self.config.rig.structure.model

    def config_at(self, lam: float) -> SimConfig:
        """The configuration at parameter value ``lam`` (the same one when the parameter is the frequency)."""
        if self.parameter == FREQUENCY:
            return self.config
        return self.config.with_parameters({self.parameter: float(lam)})

    def params_at(self, lam: float) -> np.ndarray:
        """The model's parameter vector at ``lam``, kept for the next call (at most 4096 kept)."""
        key = float(lam) if self.parameter != FREQUENCY else 0.0
        p = self._params.get(key)
        if p is None:
            cfg = self.config_at(lam)
            p = model_for(cfg).params(cfg)
            if len(self._params) > 4096:
                self._params.clear()
            self._params[key] = p
        return p

    def frequency_at(self, lam: float) -> float:
        """The motor frequency (Hz) at ``lam``."""
        return float(lam) if self.parameter == FREQUENCY else self.frequency_hz

    def with_period(self, period: int) -> Problem:
        """The same problem for ``P^period``, sharing the evaluation count and the parameter vectors."""
        return Problem(self.config, self.parameter, self.frequency_hz, period, self.scale, self.lam_scale,
                        self.evaluations, self._params)

    def unscale(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """``(x, lambda)`` of the scaled ``z``."""
        return z[:-1] * self.scale, float(z[-1] * self.lam_scale)

    def scaled(self, x: np.ndarray, lam: float) -> np.ndarray:
        """The scaled ``z`` of ``(x, lambda)``."""
        return np.append(np.asarray(x, dtype=float) / self.scale, lam / self.lam_scale)

    def flow(self, xs: np.ndarray, lams: np.ndarray, periods: int | None = None) -> np.ndarray:
        """``P^periods`` (default ``P^n``) of each point ``xs[i]`` at ``lams[i]``, in one compiled call.

        Raises:
            FlowFailed: When a run stops short (the chattering guard, a non-finite state).
        """
        periods = self.period if periods is None else periods
        params = np.array([self.params_at(lam) for lam in lams])
        freqs = np.array([self.frequency_at(lam) for lam in lams])
        out, status = flow_points(self.model, params, freqs, xs, periods)
        self.evaluations[0] += len(lams) * periods
        bad = status != k.ST_OK
        if bad.any():
            raise FlowFailed(int(status[bad][0]))
        return out

    def evaluate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(G, [dG/dxi, dG/dlambda], M)`` at scaled ``z``: residual, Jacobian (scaled) and monodromy matrix."""
        d = z.size - 1
        x, lam = self.unscale(z)
        h = FD_STEP
        xs = [x]
        lams = [lam]
        for j in range(d):
            for sgn in (1.0, -1.0):
                xp = x.copy()
                xp[j] += sgn * h * self.scale[j]
                xs.append(xp)
                lams.append(lam)
        # The parameter's column: central, or one-sided at a bound of the parameter (a gap of 0).
        offsets = [h, -h]
        for i, off in enumerate(offsets):
            try:
                self.params_at(lam + off * self.lam_scale)
            except ConfigError:
                offsets[i] = 0.0
        if offsets == [0.0, 0.0]:
            raise ConfigError(self.parameter, lam, "has no valid neighbour for the derivative")
        for off in offsets:
            xs.append(x)
            lams.append(lam + off * self.lam_scale)
        out = self.flow(np.array(xs), np.array(lams))
        g = (out[0] - x) / self.scale
        jac = np.empty((d, d + 1))
        for j in range(d):
            jac[:, j] = (out[1 + 2 * j] - out[2 + 2 * j]) / (2.0 * h) / self.scale
        jac[:, d] = (out[1 + 2 * d] - out[2 + 2 * d]) / (offsets[0] - offsets[1]) / self.scale
        monodromy_scaled = jac[:, :d].copy()
        jac[:, :d] -= np.eye(d)
        return g, jac, monodromy_scaled


def shooting_problem(config: SimConfig, parameter: str, lam_start: float, lam_end: float,
                     frequency_hz: float) -> Problem:
    """The period-1 problem of a continuation from ``lam_start`` to ``lam_end`` (module docstring, "Shooting").

    ``config``'s tolerances are tightened to :data:`SHOOTING_TOLERANCES`. The point is scaled by ``A0 / l`` and
    ``Omega A0 / l`` (``Omega`` at ``lam_start`` for the frequency, else at ``frequency_hz``), the modes by
    ``1e-3 A0`` and ``2 pi 1e3`` times that; the parameter by a fiftieth of the range.
    """
    cfg = config.with_parameters(SHOOTING_TOLERANCES)
    rig = cfg.rig
    theta_scale = rig.amplitude / rig.length
    f_ref = lam_start if parameter == FREQUENCY else frequency_hz
    n_modes = model_for(cfg).n_modes
    scale = np.array([theta_scale, theta_scale * 2.0 * math.pi * f_ref]
                     + [rig.amplitude * 1e-3, rig.amplitude * 1e-3 * 2.0 * math.pi * 1e3] * (n_modes // 2))
    lam_scale = abs(lam_end - lam_start) / 50.0
    return Problem(cfg, parameter, frequency_hz, 1, scale, lam_scale)


def floquet_multipliers(a: np.ndarray) -> np.ndarray:
    """The eigenvalues of the monodromy matrix ``a``, largest modulus first."""
    mu = np.linalg.eigvals(a)
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def unit_tangent(jac: np.ndarray, prev: np.ndarray | None) -> np.ndarray:
    """Unit null vector of ``jac`` (d x d+1), oriented along ``prev``."""
    if prev is None:
        _, _, vt = np.linalg.svd(jac)
        t = vt[-1]
    else:
        t = np.linalg.solve(np.vstack([jac, prev]), np.append(np.zeros(jac.shape[0]), 1.0))
    t = t / np.linalg.norm(t)
    if prev is not None and t @ prev < 0:
        t = -t
    return t


@dataclass
class Solved:
    """A converged point: scaled ``z``, the Jacobian ``[dG/dx, dG/dlambda]`` and monodromy matrix there, iterations."""

    z: np.ndarray
    jac: np.ndarray
    mono: np.ndarray
    iterations: int


def correct(problem: Problem, z_pred: np.ndarray, normal: np.ndarray | None, tol: float, max_iter: int
             ) -> Solved | None:
    """Newton on ``G = 0`` and ``normal . (z - z_pred) = 0`` (``normal`` None: the parameter fixed)."""
    z = z_pred.copy()
    d = z.size - 1
    if normal is None:
        normal = np.zeros(d + 1)
        normal[-1] = 1.0
    step_norm = math.inf
    for it in range(max_iter + 1):
        try:
            g, jac, mono = problem.evaluate(z)
        except (FlowFailed, ConfigError):
            return None
        res = float(np.linalg.norm(g))
        if res <= tol * max(1.0, float(np.linalg.norm(z[:-1]))) and step_norm <= 1e2 * tol * max(
                1.0, float(np.linalg.norm(z))):
            return Solved(z, jac, mono, it)
        if it == max_iter or not math.isfinite(res):
            return None
        a = np.vstack([jac, normal])
        rhs = -np.append(g, normal @ (z - z_pred))
        try:
            dz = np.linalg.solve(a, rhs)
        except np.linalg.LinAlgError:
            return None
        step_norm = float(np.linalg.norm(dz))
        z = z + dz
        # A converged residual with a tiny correction still needs the Jacobian at the corrected point: the loop
        # evaluates it and returns there.
    return None


def measure_orbit(problem: Problem, x: np.ndarray, lam: float) -> dict:
    """One period of the orbit through ``x`` run by :class:`RigModel`: its stroboscopic points, impacts, extremes.

    Two periods are run from the fixed point and the second is measured, so that an impact in progress at the
    start (the point taken mid-contact) is counted once, at its onset.
    """
    n = problem.period
    f = problem.frequency_at(lam)
    cfg = constant_frequency(problem.config_at(lam), f, float(x[0]), float(x[1])).with_parameters(
        {"truth.sample_rate": float(min(2.0e6, 2000.0 * f))})
    model = RigModel(cfg, channels=False, truth=True, strobe=True, initial_modes=tuple(x[2:]))
    model.advance(n / f)
    out = model.advance((2 * n + 0.5) / f)
    orbit = np.array([[s.theta, s.theta_dot] for s in out.strobe if n <= s.cycle_index < 2 * n])
    impacts = [i for i in out.impacts if n <= i.cycle_index < 2 * n]
    assert out.truth is not None
    first, rows = out.truth
    times = (first + np.arange(rows.shape[1])) / cfg.truth_rate
    inside = times < 2 * n / f
    delta = rows[k.T_DELTA][inside]
    dmax = sampled_peak(delta)
    return {
        "orbit": orbit,
        "impacts": len(impacts),
        "peak": max((i.peak_force for i in impacts), default=0.0),
        "max_delta": dmax,
        "max_theta": float(np.max(np.abs(rows[k.T_THETA][inside]))) if inside.any() else float(abs(x[0])),
    }


def full_point(config: SimConfig, start) -> np.ndarray:
    """``start`` as a whole point ``(theta, theta_dot, modes...)``: the modes at rest when only the first two given."""
    n_modes = model_for(config).n_modes
    x = np.zeros(2 + n_modes)
    start = np.asarray(start, dtype=float).ravel()
    if start.size not in (2, 2 + n_modes):
        raise ConfigError("start", tuple(start), f"must be (theta, theta_dot) or the full point of {2 + n_modes}")
    x[:start.size] = start
    return x
