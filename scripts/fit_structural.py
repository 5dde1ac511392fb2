#!/usr/bin/env python3
"""Fit the structural contact model's stiffnesses to what the paper shows (docs/physics.md, "Structural model").

Targets (paper, gap 0): Table 1's peak forces 82.4 N at 3.75 Hz (band A) and 120 N at 7.25 Hz (band B), and
Fig. 3's double peak at 3.75 Hz, about 80 N then 50 N (second/first 0.625). Free parameters: the hammer's
axial stiffness and the force sensor's mount stiffness (log scale); the masses and damping ratios are fixed
at their geometry/material estimates (config/structural.yaml says which). The peak forces are the
steady state from rest (last 5 s of 20 s); the double peak is a 1 MHz pulse at the steady-state impact
velocity of 3.75 Hz. Nelder-Mead (scipy.optimize) on the sum of squared relative misses.

    python scripts/fit_structural.py [--config config/structural.yaml]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.optimize import minimize

from rimd_sim.analysis.dynamics.pulse import pulse
from rimd_sim.model.rig_model import RigModel
from rimd_sim.settings.config import find_config_file, load_config

TARGETS = {"F_A": 82.4, "F_B": 120.0, "ratio": 50.0 / 80.0}
#: Restitution of one impact of the paper's single-mass model (k, c of Table 2, m = 0.15 kg): J / (m v) - 1.
#: That model places five of Table 1's six resonances exactly; the structural model, far more elastic with
#: the paper's c (0.64), moves them up by 0.25-1 Hz, so with --free-damping it is a target too.
RESTITUTION_TARGET = 0.2242


def steady(cfg, f: float, seconds: float = 20.0):
    """Largest peak force and median impact velocity over the last 5 s of ``seconds`` from rest at ``f``."""
    c = cfg.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f})
    impacts = RigModel(c, channels=False, truth=False).advance(seconds).impacts
    last = [i for i in impacts if i.t_start > seconds - 5.0]
    return max(i.peak_force for i in last), float(np.median([i.impact_velocity for i in last]))


def evaluate(cfg, ka: float, km: float, extra: dict | None = None) -> dict:
    """The fitted figures for one parameter set."""
    c = cfg.with_parameters({"structure.axial_stiffness": ka, "structure.mount_stiffness": km, **(extra or {})})
    fa, va = steady(c, 3.75)
    fb, _ = steady(c, 7.25)
    s = pulse(c, va).summary
    ratio = s["second_peak_force_n"] / s["peak_force_n"]
    e = s["impulse_n_s"] / (c.rig.mass * va) - 1.0
    dip = s["valley_force_n"] / s["second_peak_force_n"] if s["second_peak_force_n"] > 0 else 1.0
    return {"ka": ka, "km": km, "F_A": fa, "F_B": fb, "ratio": ratio, "e": e, "dip": dip, "v_A": va,
            "ring_hz": s["ring_frequency_hz"], "pulse_peaks": s["force_peaks_n"][:3]}


def main() -> None:
    """Run the fit and print every evaluation and the best."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=None, help="start from this preset (default config/structural.yaml)")
    ap.add_argument("--maxiter", type=int, default=60)
    ap.add_argument("--free-masses", action="store_true",
                    help="also fit structure.impactor_mass and structure.sensor_mass (log scale)")
    ap.add_argument("--dip", type=float, default=None,
                    help="also require the valley between the peaks to be at most this fraction of the second")
    ap.add_argument("--free-zeta", action="store_true", help="also fit damping_ratio (the wires' damping)")
    ap.add_argument("--free-damping", action="store_true",
                    help="also fit contact.damping, with the single-mass model's restitution as a 4th target")
    args = ap.parse_args()
    cfg = load_config(args.config or find_config_file("structural.yaml"))
    st = cfg.rig.structure
    x0 = [math.log10(st.axial_stiffness), math.log10(st.mount_stiffness)]
    names = []
    if args.free_masses:
        x0 += [math.log10(st.impactor_mass), math.log10(st.sensor_mass)]
        names += ["structure.impactor_mass", "structure.sensor_mass"]
    if args.free_zeta:
        x0.append(math.log10(cfg.rig.damping_ratio))
        names.append("damping_ratio")
    targets = dict(TARGETS)
    if args.free_damping:
        x0.append(math.log10(cfg.rig.contact.damping))
        names.append("contact.damping")
        targets["e"] = RESTITUTION_TARGET

    def extra(x):
        return {name: 10 ** v for name, v in zip(names, x[2:], strict=True)}

    def cost(x):
        try:
            r = evaluate(cfg, 10 ** x[0], 10 ** x[1], extra(x))
        except Exception as exc:  # an unphysical corner: steer away
            print("  refused", x, exc)
            return 1e3
        c = sum(((r[key] - val) / val) ** 2 for key, val in targets.items())
        if args.dip is not None:
            c += max(0.0, r["dip"] - args.dip) ** 2
        print(f"  ka={r['ka']:.4g} km={r['km']:.4g}  F_A={r['F_A']:.1f} F_B={r['F_B']:.1f} "
              f"ratio={r['ratio']:.3f} e={r['e']:.3f} dip={r['dip']:.2f} ring={r['ring_hz']:.0f} Hz {extra(x)} "
              f"cost={c:.4g}", flush=True)
        return c

    simplex = [list(x0)] + [[v + (0.3 if i == j else 0.0) for j, v in enumerate(x0)] for i in range(len(x0))]
    res = minimize(cost, x0, method="Nelder-Mead",
                   options={"maxiter": args.maxiter, "xatol": 1e-3, "fatol": 1e-6, "initial_simplex": simplex})
    best = evaluate(cfg, 10 ** res.x[0], 10 ** res.x[1], extra(res.x))
    print("best:", {k: (round(float(v), 4) if isinstance(v, float) else v) for k, v in best.items()}, extra(res.x))


if __name__ == "__main__":
    main()
