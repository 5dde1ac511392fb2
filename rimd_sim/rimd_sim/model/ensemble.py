"""Ensemble kernel: many constant-frequency trajectories in one compiled call, each stopped when its motion is known.

The maps (``rimd peterka``, ``rimd basins``) classify thousands of trajectories. Driving each through
:class:`~rimd_sim.model.rig_model.RigModel` costs Python bookkeeping per trajectory and a fixed number of cycles
whether the motion settled after 20 cycles or never. This module runs a whole batch of cells (an array of
frequencies and starts, one parameter vector per gap) inside numba, reusing the compiled driver of the model
(:data:`rimd_sim.model.rig_model.MODELS`, any of them) unchanged (its ``advance``, one excitation cycle at a time:
the integrator never shortens a step to land on a stop time, so the trajectory is bit-identical to a
``RigModel`` run from the same start, however it is cut). The compiled loop is built once per model, at its
first use, like the driver.

Early stopping (the rules)
--------------------------
The stroboscopic point of cycle ``c`` is the state at ``t = c / f`` in the non-dimensional coordinates of
:mod:`rimd_sim.analysis.dynamics.steady` (``u = l sin(theta) / A0``, ``v = l theta' cos(theta) / (A0 Omega)``),
paired with the number of impacts that start in cycle ``c``. Two methods (:data:`STOP_METHODS`, the rule's
``method``): ``window``, a fixed confirmation window (the default of :class:`StopRule`, so of every map but the
Peterka map), and ``contraction``, the Peterka map's default.

``contraction``: a convergence test on the stroboscopic (Poincare) map, without a fixed confirmation window.
After each cycle ``c``, for the smallest period ``n <= max_period`` for which it holds, the trajectory stops when

* the impact counts of the last two blocks of ``h = max(block, 2 n)`` cycles (``block`` 4) repeat with period
  ``n``;
* the repetition ``e_i = max(|u_i - u_{i-n}|, |v_i - v_{i-n}|)`` of the latest block is at most ``stop_tolerance``
  (1e-4), and shrinks: its largest value is at most ``contraction`` (0.5) times the largest of the block before,
  the ratio ``q`` of a geometric convergence; a saddle passage or a chaotic motion grows or holds instead;
* the remaining drift of each point to its limit, bounded by the geometric tail ``e (h / n) q / (1 - q)``, is at
  most ``stop_tolerance`` (or the latest repetition is below 1e-12, exact).

The window classified is then the latest block and the period before it (``h + n >= 3 n`` cycles), by the rule
of :func:`~rimd_sim.analysis.dynamics.steady.classify`, whose points are within ``stop_tolerance`` of their limit:
so a motion still converging with alternating points (near a period doubling) is not taken for ``2/2``, its
period-1 repetition being converged too before it is classified. A motion without impact for ``quiet_cycles``
(12) cycles stops as ``no impact`` when its period-1 repetition shrinks between the two halves (ratio at most
0.9: without impact it is a damped oscillation about its forced response) and either its remaining drift is at
most ``quiet_tolerance`` (1e-2) or its largest reach in the last half (``l sin|theta| / A0`` from the driver's
running ``|theta|`` per call, times 1.02 for the ends of the steps) is short of the stop (``gap / A0``) by more
than ``2 (1 + Omega / omega_n)`` times that drift (a drift in ``v`` is an amplitude ``Omega / omega_n`` times as
large in ``u``). The
running maximum is read per call and restored after it, so the valid domain's largest ``|theta|`` is unchanged.
No floor of cycles: a motion that starts on its attractor (a continuation) stops after ``2 h + n`` cycles (9 for a
period 1). Trajectories that never converge run to the cap, as with ``window``; there, a window classified as
period ``n`` whose repetition at a divisor ``m`` of ``n`` shrinks geometrically to within the tolerance
(:func:`_limit_period`: a period-``m`` orbit near its period doubling, approached slowly with alternating points)
is classified as the period-``m`` orbit it converges to.

``window``, the confirmation window: after each cycle, once at least ``min_cycles`` cycles have run, the trajectory
stops when, for some period ``n <= max_period`` (12),

* every point of the last ``L = max(min_window, confirm * n)`` cycles lies within ``stop_tolerance`` (in
  ``u`` and in ``v``) of the point of the same phase in the period just before them (cycle ``c - L - n`` +
  ``(i - c + L + n) mod n``): not only one period back, so that a slow drift accumulates over the window and
  is seen, and
* the impact count of each of those cycles equals that of the same cycle of that first period.

Defaults: ``min_cycles`` 30, ``min_window`` 24, ``confirm`` 4 (so a period-12 motion is seen 5 times, 60
cycles), ``stop_tolerance = tolerance / 10`` = 1e-4. Why: a stable periodic motion converges geometrically,
so once its points repeat to a tenth of the classification tolerance over 24 cycles (or 4 periods) the rest
of the run only repeats them; a trajectory that merely passes near an unstable periodic orbit (a saddle)
drifts away exponentially and does not hold a 1e-4 repetition over that many cycles; and a slowly decaying
transient (light damping, or near a period doubling, where the points alternate about a fixed point and
approach it slowly, so that points two cycles apart nearly repeat while the motion is still period 1) fails
the comparison with the window's first period until it has decayed. The window is then classified with
the rule of :func:`rimd_sim.analysis.dynamics.steady.classify` (smallest period within ``tolerance``, p impacts in n
cycles), over the last ``L + n`` cycles.

Otherwise the trajectory runs to the cap, ``max_cycles``, and the last ``measure_cycles`` cycles are classified
as a fixed-length run would classify them (chaotic cells run to the cap; their Lyapunov check stays available
through ``rimd poincare``). With the cap equal to a fixed run's length the capped cells get exactly that run's
class.

Codes returned per cell: ``period`` (0 for no impact or non-periodic), ``impacts`` p, ``kind`` (0 periodic or
no impact, 1 non-periodic, 2 integration failed), ``cycles`` whose points were used (at most the cap when it
stopped early, the cap + 1 when it ran to the cap), the final stroboscopic state ``(theta, theta_dot)`` and
the step count. And what the model's valid domain (:mod:`rimd_sim.model.validity`) needs, over the cell's
whole run: the largest ``|theta|`` at the ends of the steps (the driver's ``F_THMAX``), the largest peak force
of its impacts (0 without impact), the impacts per cycle of the classified window (NaN for a failed cell) and
the driver's status (``ST_OK``, or the failure: ``ST_ZENO`` is the chattering guard). Tracking them costs a
comparison per impact record: the integration is untouched, so every other output is the same. And, to tell
attractors of one class apart (``rimd basins``' attractor ids), the last ``max_period`` stroboscopic points
``(u, v)`` of the classified window (NaN for a failed cell, or before cycle 0) and the largest peak force of
the impacts started in that window. And, for the maps that report it (``rimd map``), the largest impact velocity
of the impacts started in that window: the record's ``R_VELOCITY``, the penetration rate ``delta_dot`` at
contact onset (``open_record`` in :mod:`rimd_sim.model.kernel`), positive when the hammer approaches the stop, so
the approach speed (m/s); 0 without impact, NaN for a failed cell. Read from the same records as the peak, it
costs one comparison more per record.

A cell starts with the model's own modes at rest (a continuation too: it goes on from the
previous cell's ``(theta, theta_dot)``, as ``steady_orbit`` from an orbit's ``final_state``).
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass
from functools import cache

import numpy as np

import rimd_sim.model.kernel as k
from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import MODELS
from rimd_sim.model.validity import PointMeasures

__all__ = [
    "KIND_CHAOTIC", "KIND_FAILED", "KIND_PERIODIC", "STOP_METHODS", "EnsembleResult", "StopRule", "run_cells",
]

KIND_PERIODIC, KIND_CHAOTIC, KIND_FAILED = 0, 1, 2
#: The early-stopping methods (module docstring): the fixed confirmation window (``rimd map`` and ``rimd basins``),
#: and the convergence test on the stroboscopic map (the Peterka map).
STOP_METHODS = ("window", "contraction")
#: Repetition below which the ``contraction`` method takes points as converged without a ratio (exact repeats).
EXACT = 1e-12
#: A no-impact motion stops when its largest reach, times ``QUIET_PEAK`` (the reach is read at the ends of the
#: steps, short of the true peak), is clear of the stop by ``QUIET_MARGIN`` times its remaining drift.
QUIET_PEAK = 1.02
QUIET_MARGIN = 2.0
#: Largest ratio between the two blocks of such a motion (without impact it is a damped oscillation about its
#: forced response: the ratio only sizes the remaining drift, the margin or ``quiet_tolerance`` decides).
QUIET_CONTRACTION = 0.9

_jit = k._jit


class StopRule:
    """The early-stopping rule (module docstring) and the cap.

    Attributes:
        min_cycles: Cycles always run before a stop is considered.
        max_cycles: The cap (cycles); 0 for none other than ``measure_cycles`` after ``min_cycles``.
        measure_cycles: Cycles classified at the cap.
        min_window: Shortest confirmation window (cycles) of the ``window`` method.
        confirm: Periods in the confirmation window (at least) of the ``window`` method.
        max_period: Longest period looked for (cycles).
        tolerance: Classification tolerance (non-dimensional).
        stop_tolerance: Repetition required to stop early (non-dimensional); for the ``contraction`` method, the
            bound on the points' remaining drift to their limit, and on their latest repetition.
        early: False runs every trajectory to the cap (a fixed-length run).
        method: ``contraction`` (the convergence test on the stroboscopic map) or ``window`` (the fixed
            confirmation window): :data:`STOP_METHODS`, module docstring.
        block: Shortest block of the ``contraction`` method (cycles); a block is ``max(block, 2 n)`` cycles.
        contraction: Largest ratio between the latest block's repetition and the block's before it.
        quiet_cycles: Cycles without impact (two blocks) after which the ``contraction`` method stops on a
            no-impact motion whose points converge.
        quiet_tolerance: Bound on the remaining drift of such a no-impact motion's points.
    """

    def __init__(self, *, min_cycles: int = 30, max_cycles: int = 192, measure_cycles: int = 72,
                 min_window: int = 24, confirm: int = 4, max_period: int = 12, tolerance: float = 1e-3,
                 stop_tolerance: float | None = None, early: bool = True, method: str = "window", block: int = 4,
                 contraction: float = 0.5, quiet_cycles: int = 12, quiet_tolerance: float = 1e-2) -> None:
        if method not in STOP_METHODS:
            raise ConfigError("stop", method, f"must be one of {', '.join(STOP_METHODS)}")
        self.min_cycles = int(min_cycles)
        self.max_cycles = int(max_cycles)
        self.measure_cycles = int(measure_cycles)
        self.min_window = int(min_window)
        self.confirm = int(confirm)
        self.max_period = int(max_period)
        self.tolerance = float(tolerance)
        self.stop_tolerance = float(tolerance / 10.0 if stop_tolerance is None else stop_tolerance)
        self.early = bool(early)
        self.method = method
        self.block = int(block)
        self.contraction = float(contraction)
        self.quiet_cycles = int(quiet_cycles)
        self.quiet_tolerance = float(quiet_tolerance)

    def vector(self) -> np.ndarray:
        """The rule as the float vector the compiled loop reads."""
        return np.array([self.min_cycles, self.max_cycles, self.measure_cycles, self.min_window, self.confirm,
                         self.max_period, self.tolerance, self.stop_tolerance, 1.0 if self.early else 0.0,
                         float(STOP_METHODS.index(self.method)), self.block, self.contraction, self.quiet_cycles,
                         self.quiet_tolerance])

    def __repr__(self) -> str:  # noqa: D105
        return (f"StopRule(min_cycles={self.min_cycles}, max_cycles={self.max_cycles}, "
                f"measure_cycles={self.measure_cycles}, min_window={self.min_window}, confirm={self.confirm}, "
                f"max_period={self.max_period}, tolerance={self.tolerance}, "
                f"stop_tolerance={self.stop_tolerance}, early={self.early}, method={self.method!r}, "
                f"block={self.block}, contraction={self.contraction}, quiet_cycles={self.quiet_cycles}, "
                f"quiet_tolerance={self.quiet_tolerance})")


@dataclass(eq=False)
class EnsembleResult:
    """Per-cell outputs of :func:`run_cells` (arrays of one entry per cell; the codes of the module docstring)."""

    period: np.ndarray
    impacts: np.ndarray
    kind: np.ndarray
    cycles: np.ndarray
    final: np.ndarray   # (theta, theta_dot) per cell
    steps: np.ndarray
    max_abs_theta: np.ndarray | None = None   # rad, over the whole run
    peak_force: np.ndarray | None = None      # N, the largest impact of the run, 0 without impact
    impacts_per_cycle: np.ndarray | None = None   # over the classified window, NaN when failed
    status: np.ndarray | None = None          # the driver's status: k.ST_OK, k.ST_ZENO (chattering), ...
    points: np.ndarray | None = None          # (cells, max_period, 2): the window's last (u, v) points
    window_peak: np.ndarray | None = None     # N, the largest impact started in the classified window, 0 without
    window_velocity: np.ndarray | None = None  # m/s, the largest impact velocity of that window, 0 without

    def measures(self) -> list[PointMeasures]:
        """Per cell, what the model's valid domain checks (:meth:`~rimd_sim.model.validity.ValidityDomain.check`).

        A cell the chattering guard stopped has no measures (as a sweep point: its run stopped there); another
        failed cell is checked on what it ran before the failure.
        """
        assert self.max_abs_theta is not None and self.peak_force is not None
        assert self.impacts_per_cycle is not None and self.status is not None
        out = []
        for th, f, rate, st in zip(self.max_abs_theta.tolist(), self.peak_force.tolist(),
                                   self.impacts_per_cycle.tolist(), self.status.tolist(), strict=True):
            out.append(PointMeasures(chattering=True) if st == k.ST_ZENO else PointMeasures(th, f, rate))
        return out

    def labels(self) -> list[str]:
        """The class labels of :mod:`rimd_sim.analysis.dynamics.steady` (``p/n``, ``no impact``, ...)."""
        out = []
        for period, p, kind in zip(self.period.tolist(), self.impacts.tolist(), self.kind.tolist(), strict=True):
            if kind == KIND_FAILED:
                out.append("integration failed")
            elif kind == KIND_CHAOTIC:
                out.append("chaotic/non-periodic" if p > 0 else "no impact")
            else:
                out.append("no impact" if p == 0 else f"{p}/{period}")
        return out


# ---- compiled loop, built once per model --------------------------------------------------------------------


@_jit
def _classify_window(u, v, counts, lo, hi, max_period, tol):
    """:func:`rimd_sim.analysis.dynamics.steady.classify` over cycles ``lo .. hi - 1``: ``(period, impacts, kind)``."""
    length = hi - lo
    mp = max(1, min(max_period, length // 3))
    total = 0
    for i in range(lo, hi):
        total += counts[i]
    for n in range(1, mp + 1):
        ok = True
        for i in range(lo + n, hi):
            if counts[i] != counts[i - n] or math.hypot(u[i] - u[i - n], v[i] - v[i - n]) > tol:
                ok = False
                break
        if ok:
            p = 0
            for i in range(hi - n, hi):
                p += counts[i]
            return (0 if p == 0 else n), p, KIND_PERIODIC
    if total == 0:
        return 0, 0, KIND_PERIODIC
    return 0, total, KIND_CHAOTIC


@_jit
def _limit_period(u, v, counts, hi, n, measure, tol):
    """The period a motion classified as period ``n`` at its cap converges to: a divisor ``m`` of ``n``, or ``n``.

    Near a period doubling a period-``m`` orbit's multiplier is close to -1: its points alternate about it and
    approach it slowly, so that a window of ``measure`` cycles repeats within ``tol`` at period ``2 m`` while
    still far from repeating at ``m``. For the smallest proper divisor ``m`` of ``n`` whose impact counts repeat
    over the three blocks of ``b = min(measure, (hi - m) // 3)`` cycles before cycle ``hi``, the largest
    repetition ``hypot(u_i - u_{i-m}, v_i - v_{i-m})`` of each block, ``E1 > E2 > E3``, is extrapolated as a
    geometric sequence (Aitken's delta-squared: ``E3 - (E3 - E2)^2 / (E3 - 2 E2 + E1)``); when that limit is at
    most ``tol`` the motion converges to the period-``m`` orbit, and ``m`` is returned. A period-``n`` orbit's
    repetition at ``m`` tends to its nonzero distance instead, and a chaotic one's does not shrink block after block.
    """
    for m in range(1, n):
        if n % m != 0:
            continue
        b = min(measure, (hi - m) // 3)
        if b < max(4, 2 * n):
            return n
        lo = hi - 3 * b
        e1 = 0.0
        e2 = 0.0
        e3 = 0.0
        ok = True
        for i in range(lo, hi):
            if counts[i] != counts[i - m]:
                ok = False
                break
            e = math.hypot(u[i] - u[i - m], v[i] - v[i - m])
            if i < lo + b:
                e1 = max(e1, e)
            elif i < lo + 2 * b:
                e2 = max(e2, e)
            else:
                e3 = max(e3, e)
        if not ok or not e1 > e2 > e3:
            continue
        curve = e3 - 2.0 * e2 + e1
        if curve > 0.0 and e3 - (e3 - e2) ** 2 / curve <= tol:
            return m
    return n


@_jit
def _settled(u, v, counts, c, max_period, min_window, confirm, stol):
    """Smallest period ``n`` repeated over the confirmation window ending at cycle ``c - 1``, or 0; and ``L``."""
    for n in range(1, max_period + 1):
        length = max(min_window, confirm * n)
        if length + n > c:
            return 0, 0
        ok = True
        base = c - length - n  # first period of the window: every later point is compared with its phase there
        for i in range(c - length, c):
            r = base + (i - base) % n
            if counts[i] != counts[r] or abs(u[i] - u[r]) > stol or abs(v[i] - v[r]) > stol:
                ok = False
                break
        if ok:
            return n, length
    return 0, 0


@_jit
def _blocks(u, v, c, n, h):
    """Largest repetition ``max(|du|, |dv|)`` over period ``n`` in the two blocks of ``h`` cycles before ``c``.

    Returns ``(older, latest)``.
    """
    ea = 0.0
    eb = 0.0
    for i in range(c - 2 * h, c):
        e = max(abs(u[i] - u[i - n]), abs(v[i] - v[i - n]))
        if i < c - h:
            ea = max(ea, e)
        else:
            eb = max(eb, e)
    return ea, eb


@_jit
def _converged(u, v, counts, reach, c, max_period, block, qmax, stol, quiet, quiet_tol, u_stop, spread):
    """The ``contraction`` test after cycle ``c - 1`` (module docstring): ``(n, lo)``, or ``(0, 0)``.

    ``n`` is the period found (-1 for a no-impact motion), ``lo`` the first cycle of the window to classify.
    ``reach`` holds per cycle the largest ``l sin|theta| / A0`` reached, ``u_stop`` is the stop's ``gap / A0``
    and ``spread`` ``1 + Omega / omega_n`` (a repetition in ``v`` as a change of the amplitude in ``u``).
    """
    if quiet > 0 and c >= quiet + 1:
        ok = True
        for i in range(c - quiet, c):
            if counts[i] != 0:
                ok = False
                break
        if ok:
            h = quiet // 2
            ea, eb = _blocks(u, v, c, 1, h)
            if eb < EXACT:
                return -1, c - quiet
            q = eb / ea if ea > 0.0 else 1.0
            if q <= QUIET_CONTRACTION:
                tail = eb * h * q / (1.0 - q)
                if tail <= quiet_tol:
                    return -1, c - quiet
                # Clear of the stop by more than the motion can still change (twice its remaining drift).
                top = 0.0
                for i in range(c - h, c):
                    top = max(top, reach[i])
                if u_stop - QUIET_PEAK * top > QUIET_MARGIN * spread * tail:
                    return -1, c - quiet
    for n in range(1, max_period + 1):
        h = max(block, 2 * n)
        if 2 * h + n > c:
            return 0, 0
        ok = True
        for i in range(c - 2 * h, c):
            if counts[i] != counts[i - n]:
                ok = False
                break
        if not ok:
            continue
        ea, eb = _blocks(u, v, c, n, h)
        if eb < EXACT:
            return n, c - h - n
        if eb > stol or ea <= 0.0:
            continue
        q = eb / ea
        # The remaining drift of each point to its limit, the latest repetitions shrinking by q per block.
        if q <= qmax and eb * (h / n) * q / (1.0 - q) <= stol:
            return n, c - h - n
    return 0, 0


@_jit
def _window_out(u, v, peaks, lo, hi, pts):
    """The largest peak of cycles ``lo .. hi - 1``.

    And the last ``pts.shape[0]`` points ``(u, v)`` of cycles up to ``hi - 1`` into ``pts`` (NaN before cycle 0).
    """
    m = pts.shape[0]
    for j in range(m):
        idx = hi - m + j
        if idx >= 0:
            pts[j, 0] = u[idx]
            pts[j, 1] = v[idx]
        else:
            pts[j, 0] = math.nan
            pts[j, 1] = math.nan
    return _window_max(peaks, lo, hi)


@_jit
def _window_max(values, lo, hi):
    """The largest of ``values`` over cycles ``lo .. hi - 1``, at least 0."""
    top = 0.0
    for i in range(lo, hi):
        if values[i] > top:
            top = values[i]
    return top


@_jit
def _rate(counts, lo, hi):
    """Impacts per cycle over cycles ``lo .. hi - 1``."""
    total = 0
    for i in range(lo, hi):
        total += counts[i]
    return total / (hi - lo)


@cache
def _loop(name: str) -> types.ModuleType:
    """The compiled loop over the cells of model ``name``, built at its first use.

    (:func:`rimd_sim.model.kernel.build_driver` says why the functions reach one another through a namespace.)
    """
    drv = MODELS[name].driver
    n_state = drv.N_STATE
    n_strobe = k.N_STROBE + drv.N_MODES
    ns = k._namespace(drv.__name__ + "_ensemble", f"The loop over the cells of the {name!r} model.")
    loop = ns
    compiled = k.jit_for(f"_loop.{name}")
    allocating = k.jit_for(f"_loop.{name}", allocates=True)   # run_cells makes the cells' workspace

    @compiled
    def init_cell(p, fs, ist, ya, yb, f, theta0, theta_dot0, h_first, imp_buf):
        """The state of ``RigModel`` at t = 0: the motor at constant ``f``, the hammer at the given state.

        The model's own modes start at rest.
        """
        for i in range(fs.shape[0]):
            fs[i] = 0.0
        for i in range(ist.shape[0]):
            ist[i] = 0
        for i in range(n_state):
            ya[i] = 0.0
        ya[0] = theta0
        ya[1] = theta_dot0
        for i in range(n_state):
            yb[i] = ya[i]
        fs[k.F_H] = min(1e-4, h_first)
        fs[k.F_HFREE] = p[k.P_HMAX]
        fs[k.F_HCONT] = p[k.P_HCONT0]
        fs[k.F_VIMP] = p[k.P_VMIN]
        fs[k.F_ZT0] = -1.0
        fs[k.F_MW0] = f
        fs[k.F_MWSET] = f
        fs[k.F_MTEND] = np.inf
        ist[k.I_MODE] = k.FREE
        ist[k.I_NEEDF] = 1
        ist[k.I_STRK] = 0
        ist[k.I_IMPOUT] = 0
        drv.resync(p, fs, ist, ya, yb, imp_buf)

    @compiled
    def run_one(p, f, theta0, theta_dot0, rule, fs, ist, ya, yb, fa, Q, u, v, th_s, om_s, counts, imp_out, st_out,
                ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out, tr_next, tr_stop, tr_base, tr_out, peaks, vels,
                pts, reach):
        """One trajectory.

        Returns ``(period, impacts, kind, cycles, theta, theta_dot, steps, max_abs_theta, peak_force,
        impacts_per_cycle, status, window_peak, window_velocity)``; the window's last points in ``pts``.
        """
        min_cycles = int(rule[0])
        cap = int(rule[1])
        measure = int(rule[2])
        min_window = int(rule[3])
        confirm = int(rule[4])
        max_period = int(rule[5])
        tol = rule[6]
        stol = rule[7]
        early = rule[8] > 0.0
        contraction = rule[9] > 0.0
        block = int(rule[10])
        qmax = rule[11]
        quiet = int(rule[12])
        quiet_tol = rule[13]
        loop.init_cell(p, fs, ist, ya, yb, f, theta0, theta_dot0, p[k.P_HMAX], imp_out)
        fs[k.F_THMAX] = abs(ya[0])   # the start counts, as in RigModel.advance
        peak = 0.0
        length_l = p[k.P_L]
        a0 = p[k.P_A0]
        omega = 2.0 * math.pi * f
        for i in range(cap + 2):
            counts[i] = 0
            peaks[i] = 0.0
            vels[i] = 0.0
            reach[i] = 0.0
        u_stop = p[k.P_GAP] / a0
        spread = 1.0 + omega / p[k.P_WN]
        seg = 0.0   # the largest |theta| since the last cycle completed (contraction only)
        # Point of cycle c: state at c / f (emitted once the integration passes it). Impacts of cycle c are final
        # once the integration has passed (c + 1.5) / f (a contact lasts milliseconds), as in steady_orbit.
        c_done = 0  # cycles 0 .. c_done - 1 have their point and impact count final
        while True:
            t_stop = (c_done + 1.5) / f
            ist[k.I_IMPOUT] = 0
            ist[k.I_STROUT] = 0
            keep = fs[k.F_THMAX]
            if contraction:
                fs[k.F_THMAX] = 0.0   # the driver's running max, read per call and restored after it
            status = drv.advance(p, fs, ist, ya, yb, fa, Q, t_stop, ch_rate, ch_qty, ch_next, ch_stop, ch_base,
                                 ch_out, 1.0, tr_next, tr_stop, tr_base, tr_out, imp_out, st_out)
            if contraction:
                seg = max(seg, fs[k.F_THMAX])
                fs[k.F_THMAX] = max(keep, fs[k.F_THMAX])
            for j in range(ist[k.I_STROUT]):
                cyc = int(st_out[j, k.S_CYCLE])
                if cyc <= cap + 1:
                    th = st_out[j, k.S_THETA]
                    om = st_out[j, k.S_OMEGA]
                    th_s[cyc] = th
                    om_s[cyc] = om
                    u[cyc] = length_l * math.sin(th) / a0
                    v[cyc] = length_l * om * math.cos(th) / (a0 * omega)
            for j in range(ist[k.I_IMPOUT]):
                cyc = int(imp_out[j, k.R_CYCLE])
                if 0 <= cyc <= cap + 1:
                    counts[cyc] += 1
                    if imp_out[j, k.R_PEAK] > peaks[cyc]:
                        peaks[cyc] = imp_out[j, k.R_PEAK]
                    if imp_out[j, k.R_VELOCITY] > vels[cyc]:
                        vels[cyc] = imp_out[j, k.R_VELOCITY]
                if imp_out[j, k.R_PEAK] > peak:
                    peak = imp_out[j, k.R_PEAK]
            if status == k.ST_STROBE_FULL or status == k.ST_IMPACTS_FULL:
                continue
            if status != k.ST_OK:
                for j in range(pts.shape[0]):
                    pts[j, 0] = math.nan
                    pts[j, 1] = math.nan
                return (0, 0, KIND_FAILED, c_done, th_s[max(c_done - 1, 0)], om_s[max(c_done - 1, 0)],
                        ist[k.I_NSTEP], fs[k.F_THMAX], peak, math.nan, status, math.nan, math.nan)
            c_done += 1
            if contraction:
                reach[c_done - 1] = length_l * math.sin(min(seg, 0.5 * math.pi)) / a0
                seg = 0.0
            if early and min_cycles <= c_done <= cap:
                if contraction:
                    n, lo = _converged(u, v, counts, reach, c_done, max_period, block, qmax, stol, quiet, quiet_tol,
                                       u_stop, spread)
                else:
                    n, length = _settled(u, v, counts, c_done, max_period, min_window, confirm, stol)
                    lo = c_done - length - n
                if n != 0:
                    period, imp, kind = _classify_window(u, v, counts, lo, c_done, max_period, tol)
                    w_peak = _window_out(u, v, peaks, lo, c_done, pts)
                    return (period, imp, kind, c_done, th_s[c_done], om_s[c_done], ist[k.I_NSTEP], fs[k.F_THMAX],
                            peak, _rate(counts, lo, c_done), status, w_peak, _window_max(vels, lo, c_done))
            if c_done > cap:
                # The fixed-length window of RigModel-based runs (transient cap - measure cycles, then measure
                # cycles): points and impacts of cycles cap - measure + 1 .. cap.
                period, imp, kind = _classify_window(u, v, counts, cap - measure + 1, cap + 1, max_period, tol)
                if early and contraction and kind == KIND_PERIODIC and period > 1:
                    m = _limit_period(u, v, counts, cap + 1, period, measure, tol)
                    if m != period:
                        imp = 0
                        for i in range(cap + 1 - m, cap + 1):
                            imp += counts[i]
                        period = m
                w_peak = _window_out(u, v, peaks, cap - measure + 1, cap + 1, pts)
                return (period, imp, kind, c_done, th_s[cap], om_s[cap], ist[k.I_NSTEP], fs[k.F_THMAX], peak,
                        _rate(counts, cap - measure + 1, cap + 1), status, w_peak,
                        _window_max(vels, cap - measure + 1, cap + 1))

    @allocating
    def run_cells(params, gap_index, freqs, theta0, theta_dot0, chain, fb_theta, fb_theta_dot, rule, out_i, out_f,
                  out_pts):
        """Run every cell; ``chain[i]`` true starts cell ``i`` from the final state of cell ``i - 1``."""
        cap = int(rule[1])
        fs = np.zeros(k.N_FSTATE)
        ist = np.zeros(k.N_ISTATE, dtype=np.int64)
        ya = np.zeros(n_state)
        yb = np.zeros(n_state)
        fa = np.zeros(n_state)
        Q = np.zeros((n_state, 4))
        u = np.zeros(cap + 2)
        v = np.zeros(cap + 2)
        th_s = np.zeros(cap + 2)
        om_s = np.zeros(cap + 2)
        counts = np.zeros(cap + 2, dtype=np.int64)
        peaks = np.zeros(cap + 2)
        vels = np.zeros(cap + 2)
        reach = np.zeros(cap + 2)
        imp_out = np.empty((256, k.N_RECORD))
        st_out = np.empty((8, n_strobe))
        ch_rate = np.zeros(0)
        ch_qty = np.zeros(0, dtype=np.int64)
        ch_next = np.zeros(0, dtype=np.int64)
        ch_stop = np.zeros(0, dtype=np.int64)
        ch_base = np.zeros(0, dtype=np.int64)
        ch_out = np.zeros((0, 0))
        tr_next = np.zeros(1, dtype=np.int64)
        tr_stop = np.zeros(1, dtype=np.int64)
        tr_base = np.zeros(1, dtype=np.int64)
        tr_out = np.zeros((k.N_TRUTH, 0))
        prev_th = 0.0
        prev_om = 0.0
        for i in range(freqs.shape[0]):
            th0 = theta0[i]
            om0 = theta_dot0[i]
            if chain[i] and i > 0:
                th0 = prev_th
                om0 = prev_om
            (period, imp, kind, cycles, th_end, om_end, steps, th_max, peak, rate, status, w_peak,
             w_vel) = loop.run_one(
                params[gap_index[i]], freqs[i], th0, om0, rule, fs, ist, ya, yb, fa, Q, u, v, th_s, om_s, counts,
                imp_out, st_out, ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out, tr_next, tr_stop, tr_base,
                tr_out, peaks, vels, out_pts[i], reach)
            out_i[i, 0] = period
            out_i[i, 1] = imp
            out_i[i, 2] = kind
            out_i[i, 3] = cycles
            out_i[i, 4] = steps
            out_i[i, 5] = status
            out_f[i, 0] = th_end
            out_f[i, 1] = om_end
            out_f[i, 2] = th_max
            out_f[i, 3] = peak
            out_f[i, 4] = rate
            out_f[i, 5] = w_peak
            out_f[i, 6] = w_vel
            if kind == KIND_FAILED:
                # A continuation goes on from the fallback state after a failure (the pool path: the final state
                # from rest at the same frequency).
                prev_th = fb_theta[i]
                prev_om = fb_theta_dot[i]
            else:
                prev_th = th_end
                prev_om = om_end

    ns.init_cell = init_cell
    ns.run_one = run_one
    ns.run_cells = run_cells
    return ns


def run_cells(model: str, params: np.ndarray, gap_index, freqs, theta0, theta_dot0, rule: StopRule, chain=None,
              fallback=None) -> EnsembleResult:
    """Run a batch of cells of one model in one compiled call.

    Args:
        model: The model's name in :data:`rimd_sim.model.rig_model.MODELS` (``structure.model``).
        params: The model's parameter vectors, one row per gap
            (:meth:`rimd_sim.model.rig_model.PhysicsModel.params` of each configuration).
        gap_index: Row of ``params`` per cell.
        freqs: Motor frequency per cell (Hz, constant from t = 0, phase 0).
        theta0: Initial angle per cell (rad).
        theta_dot0: Initial rate per cell (rad/s).
        rule: The stopping rule and cap.
        chain: Per cell, start from the final state of the previous cell instead (a continuation); default none.
        fallback: ``(theta, theta_dot)`` arrays: where a chained cell's predecessor failed, the state to go on
            from (default: that cell's own start).
    """
    if model not in MODELS:
        raise ConfigError("structure.model", model, f"must be one of {', '.join(MODELS)}")
    freqs = np.ascontiguousarray(freqs, dtype=np.float64)
    n = freqs.shape[0]
    if chain is None:
        chain = np.zeros(n, dtype=np.bool_)
    fb_th, fb_om = (theta0, theta_dot0) if fallback is None else fallback
    out_i = np.zeros((n, 6), dtype=np.int64)
    out_f = np.zeros((n, 7))
    out_pts = np.zeros((n, max(1, rule.max_period), 2))
    _loop(model).run_cells(np.ascontiguousarray(params, dtype=np.float64),
                           np.ascontiguousarray(gap_index, dtype=np.int64), freqs,
                           np.ascontiguousarray(theta0, dtype=np.float64),
                           np.ascontiguousarray(theta_dot0, dtype=np.float64),
                           np.ascontiguousarray(chain, dtype=np.bool_),
                           np.ascontiguousarray(fb_th, dtype=np.float64), np.ascontiguousarray(fb_om, dtype=np.float64),
                           rule.vector(), out_i, out_f, out_pts)
    return EnsembleResult(out_i[:, 0], out_i[:, 1], out_i[:, 2], out_i[:, 3], out_f[:, :2], out_i[:, 4],
                          out_f[:, 2], out_f[:, 3], out_f[:, 4], out_i[:, 5], out_pts, out_f[:, 5], out_f[:, 6])
