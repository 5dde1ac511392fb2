"""``rimd poincare``: phase plane and Poincare map of the simulated motion at one point (paper Figs 9, 10).

Writes ``DIR/poincare.png`` (displacements over time; phase plane with the stroboscopic points),
``DIR/poincare.csv`` (the stroboscopic points), ``DIR/trajectory.csv`` (the plotted cycles) and
``DIR/summary.json`` (class ``p/n``, largest Lyapunov exponent and the chaos verdict).
"""

from __future__ import annotations

import argparse
import sys

from rimd_sim.cli import CommandError, count, number, positive_float
from rimd_sim.cli.verbs._analysis_io import (
    add_accept_invalid_argument,
    add_model_arguments,
    check_positive,
    load_model_config,
    validity_exit,
    write_csv,
    write_summary,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd poincare``."""
    add_model_arguments(parser, "out/poincare", gap=1.0, gap_note=" (paper Fig. 9)")
    parser.add_argument("--frequency", type=positive_float("--frequency", "Hz"), default=None,
                        help="motor frequency (Hz); default 1.5 x the natural frequency (paper Fig. 9)")
    parser.add_argument("--ratio", type=positive_float("--ratio", ""), default=None,
                        help="frequency as Omega/omega_n instead of --frequency")
    parser.add_argument("--theta0", type=number("--theta0", "rad"), default=0.0,
                        help="initial angle (rad), default 0 (rest)")
    parser.add_argument("--theta-dot0", type=number("--theta-dot0", "rad/s"), default=0.0,
                        help="initial rate (rad/s), default 0")
    parser.add_argument("--transient-cycles", type=count("--transient-cycles", 0), default=200,
                        help="cycles dropped first, default 200")
    parser.add_argument("--cycles", type=count("--cycles", 6), default=300,
                        help="stroboscopic points (cycles), default 300")
    parser.add_argument("--plot-cycles", type=count("--plot-cycles"), default=10,
                        help="cycles drawn as trajectory, default 10")
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Simulate the point and write its files."""
    import numpy as np

    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.lyapunov import CHAOS_THRESHOLD, CHAOTIC, largest_lyapunov
    from rimd_sim.analysis.dynamics.steady import classify, constant_frequency, nondimensional
    from rimd_sim.analysis.plots import plot_poincare
    from rimd_sim.model.rig_model import TRUTH_FIELDS, ChatteringError, RigModel
    from rimd_sim.model.validity import PointMeasures, domain

    if args.frequency is not None and args.ratio is not None:
        raise CommandError("give --frequency or --ratio, not both")
    base = load_model_config(args)
    rig = base.rig
    f = args.frequency if args.frequency is not None else (args.ratio or 1.5) * rig.natural_frequency
    check_positive("--frequency", f)
    if f > base.motor.max_frequency:
        raise CommandError(f"--frequency {f:g} refused: above motor.max_frequency = "
                           f"{base.motor.max_frequency:g} Hz")
    cfg = constant_frequency(base, f, args.theta0, args.theta_dot0).with_parameters(
        {"truth.sample_rate": max(1000.0, 200.0 * f)})
    print(f"rimd poincare: gap {args.gap_mm:g} mm, {f:.4g} Hz: simulating...", file=sys.stderr, flush=True)
    model = RigModel(cfg, channels=False, truth=True, strobe=True)
    n0 = args.transient_cycles
    rules = domain(base)
    try:
        spans = [model.advance(n0 / f)]
        shown = model.advance((n0 + args.plot_cycles) / f)
        rest = model.advance((n0 + args.cycles + 1.5) / f)
    except ChatteringError as error:
        return _chattering(args, base, f, rules, error)
    spans += [shown, rest]
    strobe = [s for s in shown.strobe + rest.strobe if n0 < s.cycle_index <= n0 + args.cycles]
    impacts = [i for i in shown.impacts + rest.impacts if n0 < i.cycle_index <= n0 + args.cycles]
    print("rimd poincare: largest Lyapunov exponent...", file=sys.stderr, flush=True)
    lyap = largest_lyapunov(base, f, theta0=args.theta0, theta_dot0=args.theta_dot0,
                            transient_cycles=args.transient_cycles, cycles=args.cycles)
    assert shown.truth is not None  # the model was built with truth=True
    first_truth, truth = shown.truth
    rows = {name: truth[i] for i, name in enumerate(TRUTH_FIELDS)}
    t = (first_truth + np.arange(truth.shape[1])) / cfg.truth_rate
    u, v = nondimensional(rig.length, rig.amplitude, f, rows["theta"], rows["theta_dot"])
    th = np.array([s.theta for s in strobe])
    om = np.array([s.theta_dot for s in strobe])
    su, sv = nondimensional(rig.length, rig.amplitude, f, th, om)
    counts = np.bincount([i.cycle_index - n0 - 1 for i in impacts], minlength=len(strobe))[:len(strobe)]
    label, period, p, spread = classify(su, sv, counts)
    chaotic = lyap.exponent > CHAOS_THRESHOLD and label == CHAOTIC
    verdict = rules.check(PointMeasures(max(o.max_abs_theta for o in spans),
                                        max((i.peak_force for o in spans for i in o.impacts), default=0.0),
                                        float(counts.mean()), chattering=not lyap.valid and "chattering" in
                                        lyap.invalid_rule))
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "poincare.csv", [
        {"cycle": s.cycle_index, "t_s": s.t, "theta_rad": s.theta, "theta_dot_rad_s": s.theta_dot,
         "displacement_ratio": float(a), "velocity_ratio": float(b), "impacts_in_cycle": int(c)}
        for s, a, b, c in zip(strobe, su, sv, counts, strict=True)])
    write_csv(args.out / "trajectory.csv", [
        {"t_s": float(t[k]), "theta_rad": float(rows["theta"][k]), "theta_dot_rad_s": float(rows["theta_dot"][k]),
         "rimd_position_m": float(rows["rimd_position"][k]), "cart_position_m": float(rows["cart_position"][k]),
         "contact_force_n": float(rows["contact_force"][k])} for k in range(len(t))])
    summary = {
        "gap_mm": args.gap_mm, "gap_ratio": rig.gap / rig.amplitude, "frequency_hz": f,
        "frequency_ratio": f / rig.natural_frequency, "initial_state": [args.theta0, args.theta_dot0],
        "class": label, "period_cycles": period, "impacts_per_period": p, "poincare_spread": spread,
        "impacts_per_cycle": float(counts.mean()), "lyapunov_exponent_per_s": lyap.exponent,
        "lyapunov_method": "two trajectories (Benettin) on the stroboscopic map, renormalised every period",
        "chaos_threshold_per_s": CHAOS_THRESHOLD, "chaotic": bool(chaotic),
        "transient_cycles": n0, "cycles": args.cycles,
        "max_abs_theta_rad": max(o.max_abs_theta for o in spans), "valid": verdict.valid,
        "invalid_rule": verdict.invalid_rule, "validity": rules.report([verdict]),
    }
    write_summary(args.out, summary)
    plot_poincare(t, rows["rimd_position"] * 1e3, rows["cart_position"] * 1e3, u, v, su, sv,
                  args.out / "poincare.png",
                  f"RIMD model, gap {args.gap_mm:g} mm, Omega/omega_n = {f / rig.natural_frequency:.3g} "
                  f"({f:.4g} Hz): {label}, lambda_max = {lyap.exponent:.3g} 1/s"
                  + ("" if verdict.valid else f"\nOUTSIDE THE MODEL'S VALID DOMAIN: {verdict.invalid_rule}"),
                  invalid=verdict.invalid_rule, caption=describe(base))
    print(f"gap {args.gap_mm:g} mm, {f:.4g} Hz: {label}, largest Lyapunov exponent {lyap.exponent:.3g} 1/s "
          f"({'chaotic' if chaotic else 'not chaotic'}); files in {args.out}")
    return validity_exit("poincare", rules.sentence([verdict]), args.accept_invalid,
                         f"invalid_rule in {args.out / 'summary.json'}")


def _chattering(args: argparse.Namespace, base, f: float, rules, error) -> int:
    """The point where the chattering guard stopped the run: its files say so, no Poincare map."""
    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.plots import plot_message
    from rimd_sim.model.validity import PointMeasures

    verdict = rules.check(PointMeasures(chattering=True))
    rig = base.rig
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "poincare.csv", [])
    write_csv(args.out / "trajectory.csv", [])
    write_summary(args.out, {
        "gap_mm": args.gap_mm, "gap_ratio": rig.gap / rig.amplitude, "frequency_hz": f,
        "frequency_ratio": f / rig.natural_frequency, "initial_state": [args.theta0, args.theta_dot0],
        "class": None, "lyapunov_exponent_per_s": None, "chaotic": None, "transient_cycles": args.transient_cycles,
        "cycles": args.cycles, "valid": False, "invalid_rule": verdict.invalid_rule,
        "chattering": str(error), "validity": rules.report([verdict])})
    plot_message(args.out / "poincare.png", f"RIMD model, gap {args.gap_mm:g} mm, {f:.4g} Hz",
                 f"OUTSIDE THE MODEL'S VALID DOMAIN: {verdict.invalid_rule}\n{error}", caption=describe(base))
    print(f"gap {args.gap_mm:g} mm, {f:.4g} Hz: the chattering guard stopped the run ({error}); files in {args.out}")
    return validity_exit("poincare", rules.sentence([verdict]), args.accept_invalid,
                         f"invalid_rule in {args.out / 'summary.json'}")
