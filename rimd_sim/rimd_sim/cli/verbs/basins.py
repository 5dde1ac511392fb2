"""``rimd basins``: basins of attraction at one parameter point, a grid of initial (theta, theta').

Writes ``DIR/basins.png`` (the attractors' stroboscopic points drawn over it), ``DIR/basins.csv`` (with each
initial condition's attractor id) and ``DIR/summary.json`` (initial conditions per class, the attractors).
"""

from __future__ import annotations

import argparse

from rimd_sim.cli import count, number, positive_float
from rimd_sim.cli.verbs._analysis_io import (
    VerbClock,
    add_accept_invalid_argument,
    add_map_arguments,
    add_model_arguments,
    load_model_config,
    progress_printer,
    validity_exit,
    write_columns,
    write_summary,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd basins``."""
    add_model_arguments(parser, "out/basins", gap=2.4)
    parser.add_argument("--frequency", type=positive_float("--frequency", "Hz"), default=4.0,
                        help="motor frequency (Hz), default 4.0")
    parser.add_argument("--size", type=count("--size", 2), default=40, help="grid points per axis, default 40")
    for name, what, unit in (("theta", "initial angle", "rad"), ("theta-dot", "initial rate", "rad/s")):
        for end, word in (("min", "smallest"), ("max", "largest")):
            parser.add_argument(f"--{name}-{end}", type=number(f"--{name}-{end}", unit), default=None,
                                help=f"{word} {what} ({unit})")
    add_map_arguments(parser, transient=160)
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Compute the basins and write their files."""
    clock = VerbClock()
    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.basins import basins, basins_columns, default_basin_ranges
    from rimd_sim.analysis.plots import plot_basins
    from rimd_sim.model.validity import Verdict, domain

    config = load_model_config(args)
    (t_lo, t_hi), (r_lo, r_hi) = default_basin_ranges(config)
    t_range = (t_lo if args.theta_min is None else args.theta_min,
               t_hi if args.theta_max is None else args.theta_max)
    r_range = (r_lo if args.theta_dot_min is None else args.theta_dot_min,
               r_hi if args.theta_dot_max is None else args.theta_dot_max)
    result = basins(config, args.frequency, t_range, r_range, (args.size, args.size),
                    transient_cycles=args.transient_cycles, measure_cycles=args.measure_cycles,
                    early_stop=not args.fixed_length, workers=args.workers, scheduler=args.scheduler,
                    progress=progress_printer("basins", "rows"))
    clock.writing()
    args.out.mkdir(parents=True, exist_ok=True)
    write_columns(args.out / "basins.csv", basins_columns(result))
    rig = config.rig
    summary = {
        "gap_mm": args.gap_mm, "gap_ratio": rig.gap / rig.amplitude, "frequency_hz": args.frequency,
        "frequency_ratio": args.frequency / rig.natural_frequency, "theta0_range_rad": list(t_range),
        "theta_dot0_range_rad_s": list(r_range), "size": args.size, "classes": result.class_counts(),
        "coexisting_attractors": len(set(result.class_counts()) - {"inside the stop"}) > 1,
        "attractors": [{"id": a["id"], "class": a["class"], "settled": a["settled"], "period": a["period"],
                        "cells": a["cells"],
                        "theta_rad": a["theta_rad"][0], "theta_dot_rad_s": a["theta_dot_rad_s"][0],
                        "u": a["u"][0], "v": a["v"][0], "peak_force_n": a["peak_force_n"]}
                       for a in result.attractors or []],
        "wall_seconds": result.wall_seconds, "workers": result.workers, "validity": result.validity,
    }
    write_summary(args.out, summary)
    plot_basins(result, args.out / "basins.png",
                f"RIMD model, gap {args.gap_mm:g} mm, {args.frequency:g} Hz "
                f"(Omega/omega_n = {args.frequency / rig.natural_frequency:.3g}): basins of attraction",
                caption=describe(config))
    classes = ", ".join(f"{k}: {v}" for k, v in result.class_counts().items())
    on = "process(es)" if result.where == "local" else f"Dask worker thread(s) of {result.where}"
    times = clock.times(f"basins computed in {result.wall_seconds:.1f} s on {result.workers} {on}")
    print(f"{classes}; {len(result.attractors or [])} attractor(s): {times}; files in {args.out}")
    run = (result.labels != "inside the stop").ravel().tolist()
    rules = [] if result.invalid_rule is None else result.invalid_rule.ravel().tolist()
    sentence = domain(config).sentence((Verdict.of(r) for r, ran in zip(rules, run, strict=False) if ran),
                                       "initial conditions")
    return validity_exit("basins", sentence, args.accept_invalid,
                         f"the invalid_rule column of {args.out / 'basins.csv'}")
