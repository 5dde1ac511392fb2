"""Shooting kernel: the stroboscopic map of many starts in one compiled call.

The continuation of periodic orbits (:mod:`rimd_sim.analysis.dynamics.continuation`) solves ``P^n(x) = x``,
where ``P`` advances a *point* ``x = (theta, theta_dot, m_1 .. m_k)`` (the state without the contact impulse,
the model's own modes included) by one excitation period at a constant motor frequency, phase 0 at t = 0.
Its Newton iterations need ``P^n`` at a point and at a few perturbed points (the finite-difference Jacobian):
this module runs such a batch inside numba, with the model's compiled driver unchanged
(:data:`rimd_sim.model.rig_model.MODELS`, any of them), so a batch costs its integration and no Python
bookkeeping per run. The compiled loop releases the GIL (``nogil``), so a batch is split over the machine's
cores by threads (:data:`THREADS`); each run is independent, so the points do not depend on the split.

Each run starts as :class:`~rimd_sim.model.rig_model.RigModel` does (the Filippov mode set from the state by
the driver's ``resync``), integrates with the event-exact driver and takes the point at ``t = n / f`` from the
step's dense output, as a stroboscopic point of ``RigModel`` is taken: the same start gives the same point,
bit for bit (tested).
"""

from __future__ import annotations

import os
import types
from concurrent.futures import ThreadPoolExecutor
from functools import cache

import numpy as np

import rimd_sim.model.kernel as k
from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import MODELS

__all__ = ["THREADS", "flow_points"]

_jit = k._jit

#: Threads a batch is split over: the cores this process may use, at most 4 (a batch is a few to tens of runs).
THREADS = max(1, min(4, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1))


@cache
def _pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(THREADS, thread_name_prefix="rimd-shooting")


@cache
def _loop(name: str) -> types.ModuleType:
    """The compiled batch of maps of model ``name``, built at its first use."""
    drv = MODELS[name].driver
    n_state = drv.N_STATE
    n_modes = drv.N_MODES
    n_point = 2 + n_modes
    n_strobe = k.N_STROBE + n_modes
    ns = k._namespace(drv.__name__ + "_shooting", f"The shooting maps of the {name!r} model.")
    loop = ns
    compiled = k.jit_for(f"_shooting.{name}", allocates=True)   # both make their workspace

    @compiled
    def map_one(p, f, x0, periods, fs, ist, ya, yb, fa, Q, imp_out, st_out, x_out):
        """``P^periods(x0)`` into ``x_out``; returns the driver's status (``ST_OK`` when it got there)."""
        for i in range(fs.shape[0]):
            fs[i] = 0.0
        for i in range(ist.shape[0]):
            ist[i] = 0
        for i in range(n_state):
            ya[i] = 0.0
        ya[0] = x0[0]
        ya[1] = x0[1]
        for m in range(n_modes):
            ya[3 + m] = x0[2 + m]
        for i in range(n_state):
            yb[i] = ya[i]
        fs[k.F_H] = min(1e-4, p[k.P_HMAX])
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
        drv.resync(p, fs, ist, ya, yb, imp_out)
        # The point of cycle ``periods`` is emitted once a step passes t = periods / f; stop just after it.
        t_stop = periods / f * (1.0 + 1e-12) + 1e-15
        ch_rate = np.zeros(0)
        ch_qty = np.zeros(0, dtype=np.int64)
        ch_idx = np.zeros(0, dtype=np.int64)
        ch_out = np.zeros((0, 0))
        tr_next = np.zeros(1, dtype=np.int64)
        tr_out = np.zeros((k.N_TRUTH, 0))
        found = False
        while True:
            ist[k.I_IMPOUT] = 0
            ist[k.I_STROUT] = 0
            status = drv.advance(p, fs, ist, ya, yb, fa, Q, t_stop, ch_rate, ch_qty, ch_idx, ch_idx, ch_idx,
                                 ch_out, 1.0, tr_next, tr_next, tr_next, tr_out, imp_out, st_out)
            for j in range(ist[k.I_STROUT]):
                if int(st_out[j, k.S_CYCLE]) == periods:
                    x_out[0] = st_out[j, k.S_THETA]
                    x_out[1] = st_out[j, k.S_OMEGA]
                    for m in range(n_modes):
                        x_out[2 + m] = st_out[j, k.S_MODES + m]
                    found = True
            if status == k.ST_STROBE_FULL or status == k.ST_IMPACTS_FULL:
                continue
            if status != k.ST_OK:
                return status
            if found:
                return k.ST_OK
            return k.ST_STEP_UNDERFLOW  # pragma: no cover - the point is always emitted before t_stop

    @compiled
    def map_many(params, freqs, starts, periods, out, status):
        """Run every start ``i`` with parameter row ``i`` at ``freqs[i]``."""
        fs = np.zeros(k.N_FSTATE)
        ist = np.zeros(k.N_ISTATE, dtype=np.int64)
        ya = np.zeros(n_state)
        yb = np.zeros(n_state)
        fa = np.zeros(n_state)
        Q = np.zeros((n_state, 4))
        imp_out = np.empty((64, k.N_RECORD))
        st_out = np.empty((8, n_strobe))
        x_out = np.zeros(n_point)
        for i in range(freqs.shape[0]):
            for j in range(n_point):
                x_out[j] = np.nan
            status[i] = loop.map_one(params[i], freqs[i], starts[i], periods, fs, ist, ya, yb, fa, Q, imp_out,
                                     st_out, x_out)
            for j in range(n_point):
                out[i, j] = x_out[j]

    ns.map_one = map_one
    ns.map_many = map_many
    ns.N_POINT = n_point
    return ns


def flow_points(model: str, params: np.ndarray, freqs, starts: np.ndarray, periods: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """``P^periods`` of each start, in one compiled call.

    Args:
        model: The model's name in :data:`rimd_sim.model.rig_model.MODELS`.
        params: Parameter vectors, one row per start (:meth:`~rimd_sim.model.rig_model.PhysicsModel.params`).
        freqs: Motor frequency per start (Hz, constant, phase 0 at t = 0).
        starts: Points ``(theta, theta_dot, modes...)``, one row per start.
        periods: Excitation periods to advance (>= 1).

    Returns:
        ``(points, status)``: the points at ``t = periods / f`` (NaN where the run failed) and the driver's status
        per start (:data:`rimd_sim.model.kernel.ST_OK`, or ``ST_ZENO`` for the chattering guard, ...).
    """
    if model not in MODELS:
        raise ConfigError("structure.model", model, f"must be one of {', '.join(MODELS)}")
    if periods < 1:
        raise ConfigError("periods", periods, "must be >= 1")
    loop = _loop(model)
    starts = np.ascontiguousarray(starts, dtype=np.float64)
    if starts.ndim != 2 or starts.shape[1] != loop.N_POINT:
        raise ConfigError("starts", starts.shape, f"must be (runs, {loop.N_POINT}) for the {model} model")
    freqs = np.ascontiguousarray(np.broadcast_to(np.asarray(freqs, dtype=np.float64), (starts.shape[0],)))
    params = np.asarray(params, dtype=np.float64)
    params = np.ascontiguousarray(np.broadcast_to(params, (starts.shape[0], params.shape[-1])))
    out = np.empty_like(starts)
    status = np.zeros(starts.shape[0], dtype=np.int64)
    runs = starts.shape[0]
    parts = min(THREADS, runs // 2)
    if parts <= 1:
        loop.map_many(params, freqs, starts, int(periods), out, status)
        return out, status
    cuts = np.linspace(0, runs, parts + 1).astype(int)
    futures = [_pool().submit(loop.map_many, params[a:b], freqs[a:b], starts[a:b], int(periods), out[a:b],
                              status[a:b]) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    for fut in futures:
        fut.result()
    return out, status
