"""Events: the switches of the Filippov contact, located inside a step on its dense output.

A step's end state and dense output are searched for the earliest switch (:func:`event_functions`'
``detect_event``): in FREE mode ``delta`` rising through 0 (contact starts), a double crossing inside the step
(found from the cubic Hermite of ``delta``, :func:`hermite_peak`) and, after a release with ``delta > 0``, the
law's force rising through 0 (re-contact) or ``delta`` returning to 0 (the impact is over); in CONTACT mode the
force falling through 0 or ``delta`` falling through 0. Crossings are located by the Illinois method to the
event tolerance (``find_root``). While a model's modes ring in free flight near the stop, ``delta`` is sampled
eight times per ringing period (``ring_scan``, ``scan_onset``, ``scan_release``), so that a re-contact on the ring
is not stepped over. Modes change only at located events (:mod:`rimd_sim.model.records`), never by testing a
sign inside the right-hand side.
"""

from __future__ import annotations

import math

from rimd_sim.model.contact import law_force
from rimd_sim.model.integration import dense_theta
from rimd_sim.model.jit import jit_for, kernel_jit
from rimd_sim.model.layout import (
    EV_CLOSE,
    EV_ENTER,
    EV_EXIT,
    EV_EXIT_CLOSE,
    EV_NONE,
    EV_REENTER,
    F_VIMP,
    FREE,
    P_EVTOL,
    P_GAP,
    P_L,
    RING_NEGLIGIBLE,
    RING_SAMPLES_MAX,
)
from rimd_sim.model.numerics import sincos


@kernel_jit()
def hermite_peak(d0, d1, s0, s1):
    """Location in ``(0, 1)`` of the maximum of the cubic Hermite with values d0, d1 and slopes s0, s1.

    The slopes are per unit step fraction. Returns -1 when the cubic has no interior maximum.
    """
    # p(x) = d0 + s0 x + a x^2 + b x^3
    a = 3.0 * (d1 - d0) - 2.0 * s0 - s1
    b = 2.0 * (d0 - d1) + s0 + s1
    # p'(x) = s0 + 2 a x + 3 b x^2 = 0
    if b == 0.0:
        if a >= 0.0:
            return -1.0
        x = -s0 / (2.0 * a)
        return x if 0.0 < x < 1.0 else -1.0
    disc = a * a - 3.0 * b * s0
    if disc < 0.0:
        return -1.0
    r = math.sqrt(disc)
    for x in ((-a - r) / (3.0 * b), (-a + r) / (3.0 * b)):
        if 0.0 < x < 1.0 and 2.0 * a + 6.0 * b * x < 0.0:
            return x
    return -1.0


def event_functions(scope: str, phys, drv, rings: bool) -> tuple:
    """Compile one model's event search, the functions ``event_value`` .. ``detect_event`` below.

    Returns ``(event_value, find_root, ring_scan, scan_onset, scan_release, onset, detect_event)``.

    Args:
        scope: The compiled functions' qualified-name scope (:func:`rimd_sim.model.jit.jit_for`).
        phys: The namespace of the model's physics.
        drv: The driver's namespace (the compiled functions reach one another through it).
        rings: Whether the model's modes ring in free flight (its physics' ``RINGS``).
    """
    compiled = jit_for(scope)

    @compiled
    def event_value(kind, mode, ya, Q, h, x, p, fs):
        """Value of event function ``kind`` (0: delta, 1: law force) at fraction ``x`` of the step."""
        d, dd = phys.penetration(phys.dense_point(mode, ya, Q, h, x, p), p)
        if kind == 0:
            return d
        return law_force(d, dd, p, fs[F_VIMP])

    @compiled
    def find_root(kind, mode, ya, Q, h, lo, glo, hi, ghi, p, fs):
        """Illinois regula falsi for a sign change of event ``kind`` in ``[lo, hi]`` (fractions of the step).

        Returns the end of the final bracket on the far side of the crossing, so the event state is on the
        new side of the switching surface (or on it).
        """
        tol = p[P_EVTOL] / h
        side = 0
        for _ in range(200):
            if hi - lo <= tol:
                break
            x = (lo * ghi - hi * glo) / (ghi - glo)
            if not (lo < x < hi):
                x = 0.5 * (lo + hi)
            g = drv.event_value(kind, mode, ya, Q, h, x, p, fs)
            if (g > 0.0) == (glo > 0.0) and g != 0.0:
                lo = x
                glo = g
                if side == -1:
                    ghi *= 0.5
                side = -1
            else:
                hi = x
                ghi = g
                if side == 1:
                    glo *= 0.5
                side = 1
        return hi

    @compiled
    def ring_scan(ya, yb, Q, h, p):
        """Samples of ``delta`` the free step needs while the modes ring near the stop (0: none); the bound.

        The pendulum's part of ``delta`` over the step is bounded by its ends, middle and spread; the ring's by
        ``ring_amplitude``. Eight samples per ringing period, at most ``RING_SAMPLES_MAX``.
        """
        amp = phys.ring_amplitude(ya, p)
        if not amp > RING_NEGLIGIBLE:
            return 0, amp
        th, _ = dense_theta(ya, Q, h, 0.5)
        s0, _ = sincos(ya[0])
        s1, _ = sincos(yb[0])
        sh, _ = sincos(th)
        lg = p[P_L]
        p0 = lg * s0 - p[P_GAP]
        p1 = lg * s1 - p[P_GAP]
        pm = lg * sh - p[P_GAP]
        if max(p0, p1, pm) + 0.5 * abs(p1 - p0) + amp >= 0.0:
            return min(RING_SAMPLES_MAX, int(math.ceil(8.0 * h / phys.ring_period(p, ya))) + 1), amp
        return 0, amp

    @compiled
    def scan_onset(ya, Q, h, p, fs, scan, amp, da):
        """Contact onset while the modes ring: ``delta`` sampled eight times per ringing period.

        Chunks of one ringing period; only a chunk the ring can reach from the pendulum's ``delta`` (bounded
        by its ends and their spread) is sampled. Returns ``(fraction, event code)``.
        """
        nchunk = max(1, (scan + 7) // 8)
        lg = p[P_L]
        s0, _ = sincos(ya[0])
        q0 = lg * s0 - p[P_GAP]
        for j in range(nchunk):
            xa = j / nchunk
            xb = (j + 1) / nchunk
            thb, _ = dense_theta(ya, Q, h, xb)
            sb, _ = sincos(thb)
            q1 = lg * sb - p[P_GAP]
            if max(q0, q1) + 0.5 * abs(q1 - q0) + amp >= 0.0:
                glo = drv.event_value(0, FREE, ya, Q, h, xa, p, fs) if j > 0 else da
                if glo > 0.0:
                    return xa, EV_ENTER
                for i in range(1, 9):
                    x = xa + (xb - xa) * i / 8.0
                    g = drv.event_value(0, FREE, ya, Q, h, x, p, fs)
                    if g > 0.0:
                        return drv.find_root(0, FREE, ya, Q, h, xa + (xb - xa) * (i - 1) / 8.0, glo, x, g, p,
                                             fs), EV_ENTER
                    glo = g
            q0 = q1
        return 2.0, EV_NONE

    @compiled
    def scan_release(ya, Q, h, p, fs, scan, da, dda):
        """After a release with ``delta > 0`` while the modes ring: the end of the impact or a re-contact.

        ``delta`` and the law's force sampled ``scan`` times over the step. Returns ``(fraction, event code)``.
        """
        best = 2.0
        code = EV_NONE
        xlo = 0.0
        glo = da
        flo = law_force(da, dda, p, fs[F_VIMP])
        for j in range(1, scan + 1):
            x = j / scan
            g, gd = phys.penetration(phys.dense_point(FREE, ya, Q, h, x, p), p)
            fx = law_force(g, gd, p, fs[F_VIMP])
            if g <= 0.0:
                best = drv.find_root(0, FREE, ya, Q, h, xlo, glo, x, g, p, fs)
                code = EV_CLOSE
            if flo < 0.0 and fx >= 0.0:
                xr = drv.find_root(1, FREE, ya, Q, h, xlo, flo, x, fx, p, fs)
                if xr < best:
                    best = xr
                    code = EV_REENTER
            if code != EV_NONE:
                break
            xlo = x
            glo = g
            flo = fx
        return best, code

    @compiled
    def onset(ya, h, K, Q, q_ok, p, fs, da, dda, db, ddb):
        """A free step with no impact open: ``delta`` rising through 0 inside it (``da``, ``db``: its ends).

        Returns ``(fraction, event code, q_ok)``; ``Q`` is computed from the stages ``K`` (unless ``q_ok``) only
        where the search needs the dense output: ``delta`` ending the step beyond the stop from below it, or
        peaking inside the step. Most free steps need neither (a map's asks for ``Q`` once a cycle, for its
        stroboscopic point).
        """
        if db > 0.0:
            if da < 0.0:
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                return drv.find_root(0, FREE, ya, Q, h, 0.0, da, 1.0, db, p, fs), EV_ENTER, True
            return min(1.0, p[P_EVTOL] / h), EV_ENTER, q_ok   # starts on the surface and moves in
        if da < 0.0 and dda > 0.0 and ddb < 0.0:
            xm = hermite_peak(da, db, dda * h, ddb * h)
            if xm > 0.0:
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                gm = drv.event_value(0, FREE, ya, Q, h, xm, p, fs)
                if gm > 0.0:
                    return drv.find_root(0, FREE, ya, Q, h, 0.0, da, xm, gm, p, fs), EV_ENTER, True
                return 2.0, EV_NONE, True
        return 2.0, EV_NONE, q_ok

    @compiled
    def detect_event(mode, rec, ya, yb, h, K, Q, p, fs):
        """Earliest switch inside the step ``[0, 1]``: ``(fraction, event code, q_ok)``, or ``(2, EV_NONE, q_ok)``.

        The step's dense coefficients ``Q`` are computed from its stages ``K`` when the search needs them (always
        but in the free steps of :func:`onset`); ``q_ok`` says whether they were.

        ``rec`` tells whether an impact is open. In FREE mode it selects what to watch: with no impact open,
        ``delta`` rising through 0 (a state a rounding error beyond the surface counts as on it); with an
        impact open (released by a vanishing force while ``delta > 0``), re-contact and ``delta`` returning
        below 0. Choosing by the record rather than by the sign of ``delta`` keeps a state that lies a
        rounding error off the surface from switching again and again.
        """
        best = 2.0
        code = EV_NONE
        da, dda = phys.penetration(phys.point(ya), p)
        db, ddb = phys.penetration(phys.point(yb), p)
        if mode == FREE and rec == 0 and not rings:
            return drv.onset(ya, h, K, Q, False, p, fs, da, dda, db, ddb)
        drv.dense_coeffs(K, Q)
        if mode == FREE:
            scan = 0
            amp = 0.0
            if rings:
                scan, amp = drv.ring_scan(ya, yb, Q, h, p)
            if rec == 0:
                if rings and scan > 0:
                    if da > 0.0 and dda > 0.0:  # on the surface (rounding) and moving in
                        return min(1.0, p[P_EVTOL] / h), EV_ENTER, True
                    # On the surface (rounding) but moving out: not a contact.
                    x, c = drv.scan_onset(ya, Q, h, p, fs, scan, amp, min(da, 0.0))
                    return x, c, True
                return drv.onset(ya, h, K, Q, True, p, fs, da, dda, db, ddb)
            # Separated by a vanishing force while still beyond the stop position.
            if da <= 0.0:  # already back at the surface (rounding): the impact is over
                return min(1.0, p[P_EVTOL] / h), EV_CLOSE, True
            if rings and scan > 0:
                x, c = drv.scan_release(ya, Q, h, p, fs, scan, da, dda)
                return x, c, True
            if db <= 0.0:
                best = drv.find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                code = EV_CLOSE
            fa = law_force(da, dda, p, fs[F_VIMP])
            fb = law_force(db, ddb, p, fs[F_VIMP])
            if fa < 0.0 and fb >= 0.0:
                x = drv.find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
                if x < best:
                    best = x
                    code = EV_REENTER
        else:
            fa = law_force(da, dda, p, fs[F_VIMP])
            fb = law_force(db, ddb, p, fs[F_VIMP])
            if fa >= 0.0 and fb < 0.0:
                best = drv.find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
                code = EV_EXIT
            if da >= 0.0 and db < 0.0:
                x = drv.find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                if x < best:
                    best = x
                    code = EV_EXIT_CLOSE
        return best, code, True

    return event_value, find_root, ring_scan, scan_onset, scan_release, onset, detect_event
