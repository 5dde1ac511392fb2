"""The one integration driver of every model: event-exact Dormand-Prince with Filippov contact switching.

The driver is the hot loop, written in the subset of Python that numba compiles; with the environment
variable ``RIMD_NO_JIT=1`` the very same functions run as plain Python (slow, for debugging and for the test
that both paths agree). The public, typed interface is :class:`rimd_sim.model.rig_model.RigModel`; the models are
chosen in its registry (:data:`rimd_sim.model.rig_model.MODELS`); the arrays and integer codes here are an
implementation detail.

The model is data: :func:`build_driver` compiles the driver once per model from that model's *physics*, a
module that follows the contract below (:mod:`rimd_sim.model.rigid`, the paper's pendulum;
:mod:`rimd_sim.model.structural`, the two-mass hammer on a compliant sensor mount), in the manner of scipy's
``integrate/_ivp``: one solver with a written contract, methods in a registry, validation in one place.

Method
------
* State ``y = (theta, theta_dot, J, m_1 .. m_k)``: embarked pendulum angle, its rate, the impulse of the
  current contact (``J' = F``), then the model's own *modes* (none for the paper's model). A *point* is the
  state without ``J``: ``(theta, theta_dot, m_1 .. m_k)``. Integrated by the explicit Dormand-Prince 5(4)
  pair with local extrapolation, standard step control on ``(theta, theta_dot)`` (and, in contact, on the
  modes the model weighs) and its 4th-order continuous extension (the coefficients of
  ``scipy.integrate.RK45``). Global error O(h^5).
* The right-hand side is smooth inside each *mode* (FREE or CONTACT) and within a motor segment (constant
  angular acceleration of the motor). Every step ends at a motor breakpoint (ramp start/end).
* Events (switches) are located on the dense output by the Illinois method to ``event_tolerance``; the
  step is then recomputed from its start to the event time, so the state at the switch carries the
  method's full order. Modes change only at located events, never by testing the sign of a state inside
  the right-hand side, so a switch can neither be missed by an oscillating sign nor be applied twice.
* FREE mode watches ``delta`` crossing 0 upwards (contact starts, Filippov surface Sigma_alpha), a double
  crossing of ``delta`` inside one step (found from the cubic Hermite of delta and its rate), and, while
  the hammer is separated but still beyond the stop position (``delta > 0`` after a dashpot release), the
  law's force crossing 0 upwards (re-contact) and ``delta`` returning to 0 (the impact is over).
  CONTACT mode watches the force crossing 0 downwards (Sigma_beta) and ``delta`` crossing 0 downwards.
* A model whose modes *ring* in free flight (``RINGS``) advances them by their closed form there (so the free
  step is the pendulum's however long they ring), and while they ring near the stop the onset test samples
  ``delta`` eight times per ringing period, so a re-contact on the ring is not stepped over.
* An *impact* is the interval from ``delta`` rising through 0 to ``delta`` falling back through 0; it
  may hold several contact intervals. Its duration runs to the last instant the force vanished.
* A chattering guard stops with a status code when more than ``ZENO_MAX_EVENTS`` switches happen within
  ``ZENO_WINDOW`` seconds, instead of stalling.

Chunk independence: an ``advance`` call never shortens a step to land on its stop time. The current
step (with its dense output) persists between calls and samples are drawn from it, so the trajectory and
every sample are bit-identical however the simulated time is cut into calls. Only commands (see
``truncate``) end a step early, at the command's time.

Modules
-------
This module holds the contract below, checks a physics module against it and composes the driver from the
modules that follow, one job each (:func:`build_driver`). It re-exports their names that the rest of the package
reads as ``kernel.*``: the whole layout, the compilation decorators and the shared compiled functions.

=================================== ===========================================================================
:mod:`rimd_sim.model.layout`        the layout of the shared arrays (``P_*``, ``F_*``, ``I_*``, ``T_*``, ``R_*``,
                                    ``S_*``) and the integer codes
:mod:`rimd_sim.model.jit`           how functions are compiled, and the digests that keep numba's cache fresh
:mod:`rimd_sim.model.numerics`      ``sincos`` and ``inv_fifth_root``, cheap forms of library functions
:mod:`rimd_sim.model.contact`       the contact laws, by name and by code (``law_force``)
:mod:`rimd_sim.model.motor`         the motor's segments and the cart's motion
:mod:`rimd_sim.model.integration`   the Dormand-Prince step, its dense output, and the loop (``advance``,
                                    ``truncate``)
:mod:`rimd_sim.model.events`        the search for switches inside a step
:mod:`rimd_sim.model.records`       applying switches, impact records, ``resync``
:mod:`rimd_sim.model.sampling`      channels, truth block and stroboscopic points from the dense output
=================================== ===========================================================================

The physics contract
--------------------
A model's physics module defines, compiled with :func:`physics_inline` or :func:`physics_jit` (``p`` is the
parameter vector, ``fs`` the float state, ``y`` a state tuple, ``s`` a point tuple, ``mode`` FREE or CONTACT):

=========================================== =================================================================
``N_MODES``                                 number of modes ``k`` (the state has ``3 + k`` components)
``RINGS``                                   True when the modes ring in free flight (then the ``ring_*``
                                            functions and ``settle`` below are used)
``HAMMER_MODES``                            state indices (>= 3) a reset of the hammer puts at rest
``derivs(t, y, mode, p, fs)``               the right-hand side, a tuple of ``3 + k``
``free_flight(y0, y1, h, p)``               the state at the end of a free step from ``y0`` (``y1``: as the
                                            Runge-Kutta stages computed it; closed-form modes replace theirs)
``mode_scale(j, p)``                        in contact, the absolute-tolerance scale of mode ``j`` in the error
                                            norm (0: not error-controlled)
``point(y)``, ``dense_point(mode, ya, Q,    the point at a step end, and at fraction ``x`` of the current step
h, x, p)``                                  (from :func:`dense_theta`, :func:`dense_comp` or a closed form)
``penetration(s, p)``                       ``(delta, delta_dot)``
``sensor_force(force, s, p)``               what the force sensor reads in contact when the law gives
                                            ``force`` (unclipped): the impact record's peak is taken on it
``force_free_is_zero(p)``                   the sensor reads exactly 0 outside contact
``sample(qty, mode, s, p, fs, w, alpha,     the force or the acceleration (``Q_FORCE``, ``Q_ACC``; the driver
sp, cp)``                                   samples the displacements) from the point and the motor's angular
                                            frequency, acceleration and the sine and cosine of its phase
``truth(mode, s, t, p, fs, xc, vc, ac)``    ``(x, v, a, delta, force)`` of the truth block
``ring_amplitude(y, p)``                    a bound on how far the modes can move ``delta`` from the
                                            pendulum's ``l sin(theta) - gap`` from now on (free flight)
``ring_period(p, y)``                       the shortest period of a mode still ringing, or inf
``settle(y, p)``                            set modes that have died out to exactly 0 (start of a free step)
``params(config)``                          (Python) the parameter vector: the ``P_*`` of
                                            :mod:`rimd_sim.model.layout` first, the model's own after it
=========================================== =================================================================

:func:`check_physics` checks a module against this table (``CONTRACT``, ``RING_HOOKS``) before a driver is built.
"""

from __future__ import annotations

import sys
import types

from rimd_sim.model import events, integration, records, sampling
from rimd_sim.model.contact import law_force as law_force
from rimd_sim.model.contact import spow as spow
from rimd_sim.model.events import hermite_peak as hermite_peak
from rimd_sim.model.integration import dense_comp as dense_comp
from rimd_sim.model.integration import dense_theta as dense_theta
from rimd_sim.model.jit import JIT as JIT
from rimd_sim.model.jit import KERNEL_MODULES, load_cached
from rimd_sim.model.jit import _jit as _jit
from rimd_sim.model.jit import _jit_alloc as _jit_alloc
from rimd_sim.model.jit import _jit_fused as _jit_fused
from rimd_sim.model.jit import _jit_inline as _jit_inline
from rimd_sim.model.jit import jit_for as jit_for
from rimd_sim.model.jit import namespace as _namespace
from rimd_sim.model.jit import physics_inline as physics_inline
from rimd_sim.model.jit import physics_jit as physics_jit
from rimd_sim.model.jit import source_key as source_key
from rimd_sim.model.jit import to_tuple as to_tuple
from rimd_sim.model.jit import tuple_set as tuple_set
from rimd_sim.model.layout import *  # noqa: F403  # the whole layout is read as kernel.P_*, kernel.F_*, ...
from rimd_sim.model.motor import cart_accel as cart_accel
from rimd_sim.model.motor import cart_kinematics as cart_kinematics
from rimd_sim.model.motor import motor_angles as motor_angles
from rimd_sim.model.motor import motor_command as motor_command
from rimd_sim.model.motor import motor_finish_ramp as motor_finish_ramp
from rimd_sim.model.motor import motor_freq as motor_freq
from rimd_sim.model.motor import motor_phase as motor_phase
from rimd_sim.model.motor import motor_rebase as motor_rebase
from rimd_sim.model.motor import motor_slip as motor_slip
from rimd_sim.model.motor import next_strobe as next_strobe
from rimd_sim.model.numerics import inv_fifth_root as inv_fifth_root
from rimd_sim.model.numerics import sincos as sincos
from rimd_sim.model.records import close_record as close_record

#: The modules the driver is compiled from (:data:`rimd_sim.model.jit.KERNEL_MODULES`), this one included: their
#: sources are part of every driver's cache key.
DRIVER_MODULES = tuple(sys.modules[f"rimd_sim.model.{name}"] for name in KERNEL_MODULES)

#: What a physics module must define (the contract of the module docstring); ``RINGS`` adds :data:`RING_HOOKS`.
CONTRACT = ("N_MODES", "RINGS", "HAMMER_MODES", "derivs", "free_flight", "mode_scale", "point", "dense_point",
            "penetration", "sensor_force", "force_free_is_zero", "sample", "truth", "params")
RING_HOOKS = ("ring_amplitude", "ring_period", "settle")


def check_physics(physics) -> None:
    """Raise ``TypeError`` naming what ``physics`` lacks of the contract (:data:`CONTRACT`)."""
    missing = [a for a in CONTRACT + (RING_HOOKS if getattr(physics, "RINGS", False) else ())
               if not hasattr(physics, a)]
    if missing:
        raise TypeError(f"{physics.__name__} is not a physics module of rimd_sim.model.kernel: it lacks "
                        f"{', '.join(missing)}")


def build_driver(physics, name: str, sources=()) -> types.ModuleType:
    """Compile the driver for one model from its physics module (the contract of the module docstring).

    Args:
        physics: The model's physics module.
        name: The model's name (registry key).
        sources: Further modules whose source the physics compiles in (for the cache key).

    Returns:
        A namespace with ``advance``, ``truncate`` and ``resync`` (their contracts are their docstrings), the
        functions they call, ``N_STATE``, ``N_MODES`` and ``physics``.

    Raises:
        TypeError: For a physics module that lacks part of the contract.

    The factories of :mod:`~rimd_sim.model.integration`, :mod:`~rimd_sim.model.events`,
    :mod:`~rimd_sim.model.records` and :mod:`~rimd_sim.model.sampling` return closures over the model's state
    size, its number of modes, whether they ring, and two namespaces. Closures, because numba fixes at compile
    time what an argument cannot give: the length of a state tuple (``to_tuple(y, n)``) and which physics
    function a call inlines; a closure cell or a module attribute gives both.

    numba compiles each function at its first call and caches it on disk (``cache=True``) under a key made of
    the closure's cells. The functions reach the physics and one another through namespaces (modules registered
    in ``sys.modules``) whose names hold the digest of the sources: a module is pickled by its name into that key
    (a compiled function would be pickled with an id of its process, and never hit the cache). The digest covers
    the physics and every module of the kernel (:data:`DRIVER_MODULES`): numba checks a cached function against
    its own file only, and a cached caller (the ensemble loop, ...) holds the code of what it calls, so an edit
    anywhere changes the names and is never served stale.
    """
    check_physics(physics)
    key = source_key(*DRIVER_MODULES, physics, *sources)
    phys = _namespace(f"{__name__}.physics_{name}_{key}", f"The physics of the {name!r} model ({physics.__name__}).")
    for attr in CONTRACT + (RING_HOOKS if physics.RINGS else ()):
        setattr(phys, attr, getattr(physics, attr))
    n = 3 + physics.N_MODES
    n_modes = physics.N_MODES
    rings = bool(physics.RINGS)
    drv = _namespace(f"{__name__}.driver_{name}_{key}",
                     f"The integration driver of the {name!r} model, built by rimd_sim.model.kernel.build_driver.")
    # Functions built for different models share their Python names: the scope with the model's name keeps their
    # compiled symbols and cache files apart (:func:`rimd_sim.model.jit.jit_for`).
    scope = f"build_driver.{name}"
    for fn in (*integration.step_functions(scope, phys, drv, n, n_modes),
               *events.event_functions(scope, phys, drv, rings),
               *sampling.sampling_functions(scope, phys, n_modes),
               *records.record_functions(scope, phys, drv, n),
               *integration.loop_functions(scope, phys, drv, n, rings)):
        setattr(drv, getattr(fn, "py_func", fn).__name__, fn)
    drv.N_STATE = n
    drv.N_MODES = n_modes
    drv.physics = physics
    load_cached(drv.rk_step)   # before its callers: every caller then runs this code (jit.load_cached)
    return drv
