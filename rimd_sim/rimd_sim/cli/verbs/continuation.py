"""``rimd continue``: continuation of periodic orbits with their stability, bifurcations located.

Writes ``DIR/branch.csv`` (one row per orbit of every branch: parameter, fixed point, stability, Floquet
multipliers, peak force, impacts per period, validity), ``DIR/bifurcations.json`` (period doublings, folds,
Neimark-Sacker points, grazings, located), ``DIR/continuation.png`` (the branches, stable solid, unstable dashed,
over the brute-force bifurcation diagram) and ``DIR/summary.json``. Method: docs/analyses.md, "`rimd continue`".
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from rimd_sim.cli import CommandError, count, number, positive_float
from rimd_sim.cli.verbs._analysis_io import (
    CONFIG_GAP,
    VerbClock,
    add_accept_invalid_argument,
    add_model_arguments,
    load_model_config,
    validity_exit,
    write_csv,
    write_summary,
)

#: What the verb says of a fold found right at its branch's start.
FOLD_NOTE = (" (suspect: within 1 % of the range from the branch's first orbit, where the predictor may have turned "
           "back on the branch rather than found a fold: check with a start on either side)")


def suspect_fold(result, bif) -> bool:
    """Whether a fold lies within 1 % of the range from its branch's first orbit."""
    if bif.kind != "fold":
        return False
    first = result.branches[bif.branch].points[0].parameter
    return abs(bif.parameter - first) < 0.01 * abs(result.end - result.start)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd continue``."""
    add_model_arguments(parser, "out/continuation", gap=CONFIG_GAP)
    parser.add_argument("--f-start", type=positive_float("--f-start", "Hz"), default=3.0,
                        help="motor frequency where the branch starts (Hz), default 3")
    parser.add_argument("--f-end", type=positive_float("--f-end", "Hz"), default=6.0,
                        help="motor frequency where it ends (Hz; below --f-start to go down), default 6")
    parser.add_argument("--parameter", default="frequency",
                        help="continuation parameter: frequency (default) or a numeric parameter of the "
                             "configuration (gap, mass, damping_ratio, contact.stiffness, ...), with --from, --to "
                             "and --frequency")
    parser.add_argument("--from", dest="p_from", type=number("--from", ""), default=None,
                        help="the parameter's first value (its unit in docs/configuration.md)")
    parser.add_argument("--to", dest="p_to", type=number("--to", ""), default=None, help="its last value")
    parser.add_argument("--frequency", type=positive_float("--frequency", "Hz"), default=None,
                        help="motor frequency (Hz) when the parameter is not the frequency")
    parser.add_argument("--period", type=count("--period"), default=None,
                        help="period (cycles) of the orbit to start from; default the attractor's")
    parser.add_argument("--theta0", type=number("--theta0", "rad"), default=None,
                        help="a start near the orbit (rad); default the attractor reached from rest")
    parser.add_argument("--theta-dot0", type=number("--theta-dot0", "rad/s"), default=0.0,
                        help="its rate (rad/s), default 0")
    parser.add_argument("--max-period", type=count("--max-period"), default=8,
                        help="longest period a switch at a period doubling creates (cycles), default 8")
    parser.add_argument("--no-switch", action="store_true", help="do not switch branches at period doublings")
    parser.add_argument("--ds-max", type=positive_float("--ds-max", ""), default=1.0,
                        help="largest arclength step (scaled: the range is 50), default 1")
    parser.add_argument("--max-points", type=count("--max-points", 2), default=400,
                        help="points per branch at most, default 400")
    parser.add_argument("--diagram-points", type=count("--diagram-points", 0), default=60,
                        help="frequencies of the brute-force bifurcation diagram drawn behind (0: none), default 60")
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Follow the branches and write the files."""
    clock = VerbClock()
    import numpy as np

    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.continuation import ContinuationSettings, StartOutsideDomain, continuation
    from rimd_sim.analysis.plots import plot_continuation
    from rimd_sim.model.validity import Verdict, domain

    config = load_model_config(args)
    freq = args.parameter == "frequency"
    if freq:
        start, end, f_fixed = args.f_start, args.f_end, None
        for option, f in (("--f-start", start), ("--f-end", end)):
            if f > config.motor.max_frequency:
                raise CommandError(f"{option} {f:g} refused: above motor.max_frequency = "
                                   f"{config.motor.max_frequency:g} Hz")
    else:
        if args.p_from is None or args.p_to is None or args.frequency is None:
            raise CommandError(f"--parameter {args.parameter} needs --from, --to and --frequency")
        start, end, f_fixed = args.p_from, args.p_to, args.frequency
    if start == end:
        raise CommandError("the range is empty: give different start and end values")
    initial = None if args.theta0 is None else (args.theta0, args.theta_dot0)
    settings = ContinuationSettings(ds_max=args.ds_max, max_points=args.max_points, max_period=args.max_period,
                                    switch=not args.no_switch)
    what = f"{args.parameter} {start:g} -> {end:g}" + ("" if freq else f" at {f_fixed:g} Hz")
    print(f"rimd continue: gap {args.gap_mm:g} mm, {what}...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    try:
        result = continuation(config, start, end, parameter=args.parameter, frequency_hz=f_fixed,
                              period=args.period, initial=initial, settings=settings)
    except StartOutsideDomain as error:
        return _outside(args, config, error)
    wall = time.perf_counter() - t0
    # The brute-force diagram is computed before any file is written, so that the files' time is theirs alone.
    diagram, diagram_wall = None, 0.0
    if freq and args.diagram_points:
        from rimd_sim.analysis.dynamics.bifurcation import bifurcation

        lo, hi = sorted((start, end))
        diagram_freqs = np.round(np.linspace(lo, hi, args.diagram_points), 6)
        print(f"rimd continue: brute-force diagram, {len(diagram_freqs)} frequencies...", file=sys.stderr, flush=True)
        diagram, diagram_wall, _ = bifurcation(config, diagram_freqs, "both")
    clock.writing()
    args.out.mkdir(parents=True, exist_ok=True)
    rig = config.rig
    rows = []
    n_mu = max((len(p.multipliers) for b in result.branches for p in b.points), default=0)
    n_modes = max((len(p.point) - 2 for b in result.branches for p in b.points), default=0)
    for b in result.branches:
        for p in b.points:
            row = {"branch": b.index, "period": b.period, "parent": "" if b.parent is None else b.parent,
                   "parameter": result.parameter, "value": p.parameter, "frequency_hz": p.frequency_hz,
                   "frequency_ratio": p.frequency_hz / rig.natural_frequency,
                   "theta_rad": float(p.point[0]), "theta_dot_rad_s": float(p.point[1])}
            for m in range(n_modes):
                row[f"mode_{m + 1}"] = float(p.point[2 + m])
            row["displacement_ratio"] = rig.length * math.sin(float(p.point[0])) / rig.amplitude
            row["stable"] = p.stable
            for i in range(n_mu):
                mu = p.multipliers[i] if i < len(p.multipliers) else complex("nan")
                row[f"mu{i + 1}_re"], row[f"mu{i + 1}_im"] = float(mu.real), float(mu.imag)
            row["max_abs_multiplier"] = p.max_multiplier
            row.update({"peak_force_n": p.peak_force_n, "impacts_per_period": p.impacts_per_period,
                        "max_penetration_m": p.max_penetration_m, "max_abs_theta_rad": p.max_abs_theta_rad,
                        "valid": p.valid, "invalid_rule": p.invalid_rule})
            rows.append(row)
    write_csv(args.out / "branch.csv", rows)
    bifs = [{"kind": b.kind, "frequency_hz": b.frequency_hz, "parameter": result.parameter, "value": b.parameter,
             "period": b.period, "branch": b.branch, "new_branch": b.new_branch,
             "theta_rad": float(b.point[0]), "theta_dot_rad_s": float(b.point[1]),
             "multipliers": [[float(m.real), float(m.imag)] for m in b.multipliers], "detail": b.detail}
            for b in result.bifurcations]
    (args.out / "bifurcations.json").write_text(json.dumps(bifs, indent=2) + "\n")
    rules = domain(config)
    verdicts = [Verdict.of(p.invalid_rule) for b in result.branches for p in b.points]
    summary = {
        "gap_mm": args.gap_mm, "parameter": result.parameter, "start": start, "end": end, "frequency_hz": f_fixed,
        "branches": [{"index": b.index, "period": b.period, "parent": b.parent, "points": len(b.points),
                      "from": b.points[0].parameter, "to": b.points[-1].parameter, "end": b.end,
                      "stable_points": sum(p.stable for p in b.points)} for b in result.branches],
        "bifurcations": {kind: len(result.of_kind(kind)) for kind in sorted({b.kind for b in result.bifurcations})},
        "suspect_folds": [b.parameter for b in result.bifurcations if suspect_fold(result, b)],
        "settings": {"ds_max": settings.ds_max, "max_points": settings.max_points,
                     "max_period": settings.max_period, "switch": settings.switch,
                     "newton_tolerance": settings.newton_tolerance, "locate_tolerance": settings.locate_tolerance},
        "periods_integrated": result.evaluations, "wall_seconds": wall,
        "validity": rules.report(verdicts),
    }
    if diagram is not None:
        summary["diagram_frequencies"] = len(diagram_freqs)
    write_summary(args.out, summary)
    title = (f"RIMD model, gap {args.gap_mm:g} mm: periodic orbits by continuation" if freq else
             f"RIMD model: periodic orbits by continuation in {args.parameter} at {f_fixed:g} Hz"
             + ("" if args.parameter == "gap" else f", gap {args.gap_mm:g} mm"))
    plot_continuation(result, args.out / "continuation.png", title, natural_frequency_hz=rig.natural_frequency,
                      length_m=rig.length, amplitude_m=rig.amplitude, diagram=diagram,
                      caption=describe(config, omit=() if freq else (args.parameter,)))
    for b in result.branches:
        print(f"branch {b.index}: period {b.period}, {len(b.points)} orbits, {args.parameter} "
              f"{b.points[0].parameter:.6g} -> {b.points[-1].parameter:.6g} ({b.end})")
    for bif in result.bifurcations:
        to = f", switched to branch {bif.new_branch}" if bif.new_branch is not None else ""
        print(f"{bif.kind.replace('_', ' ')} at {args.parameter} {bif.parameter:.6g}"
              + (f" ({bif.frequency_hz / rig.natural_frequency:.5g} omega_n)" if freq else "")
              + f" on branch {bif.branch} (period {bif.period}){to}"
              + (FOLD_NOTE if suspect_fold(result, bif) else ""))
    computed = f"{result.evaluations} periods integrated in {wall:.1f} s" + (
        f", the brute-force diagram in {diagram_wall:.1f} s" if diagram is not None else "")
    print(clock.times(computed) + f"; files in {args.out}")
    return validity_exit("continue", rules.sentence(verdicts, "orbits"), args.accept_invalid,
                         f"the invalid_rule column of {args.out / 'branch.csv'}")


def _outside(args: argparse.Namespace, config, error) -> int:
    """No branch: the motion at the start leaves the model's valid domain. The files say so."""
    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.plots import plot_message
    from rimd_sim.model.validity import Verdict, domain

    rules = domain(config)
    verdict = Verdict.of(error.invalid_rule)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "branch.csv", [])
    (args.out / "bifurcations.json").write_text("[]\n")
    write_summary(args.out, {"gap_mm": args.gap_mm, "parameter": args.parameter, "branches": [],
                             "bifurcations": {}, "valid": False, "invalid_rule": error.invalid_rule,
                             "error": str(error), "validity": rules.report([verdict])})
    plot_message(args.out / "continuation.png", f"RIMD model, gap {args.gap_mm:g} mm: no branch",
                 f"OUTSIDE THE MODEL'S VALID DOMAIN: {error.invalid_rule}\n{error}", caption=describe(config))
    print(f"rimd continue: {error}", flush=True)
    return validity_exit("continue", rules.sentence([verdict], "starts"), args.accept_invalid,
                         f"invalid_rule in {args.out / 'summary.json'}")
