"""``rimd bifurcation``: stroboscopic ``l sin(theta) / A0`` versus Omega/omega, up, down, from rest (paper Fig. 11).

Writes ``DIR/bifurcation.png``, ``DIR/bifurcation.csv`` (one row per stroboscopic sample) and
``DIR/summary.json`` (the classes along each sweep as frequency runs).
"""

from __future__ import annotations

import argparse
import sys

from rimd_sim.cli import CommandError, count, positive_float
from rimd_sim.cli.verbs._analysis_io import (
    CONFIG_GAP,
    VerbClock,
    add_accept_invalid_argument,
    add_model_arguments,
    add_scheduler_argument,
    check_range,
    class_runs,
    load_model_config,
    validity_exit,
    write_csv,
    write_summary,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd bifurcation``."""
    add_model_arguments(parser, "out/bifurcation", gap=CONFIG_GAP, f_range=(2.0, 9.5), f_step=0.05)
    parser.add_argument("--direction", default="both",
                        help="up, down, rest (every frequency from rest), both (up and down: the default) or all "
                             "(up, down and rest); one process per sweep")
    parser.add_argument("--transient-cycles", type=count("--transient-cycles", 0), default=100,
                        help="cycles before sampling, default 100")
    parser.add_argument("--sample-cycles", type=count("--sample-cycles", 3), default=48,
                        help="cycles sampled per frequency, default 48")
    parser.add_argument("--ramp-rate", type=positive_float("--ramp-rate", "Hz/s"), default=2.0,
                        help="motor ramp between steps (Hz/s), default 2")
    add_scheduler_argument(parser)
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Run the sweeps and write their files."""
    clock = VerbClock()
    import numpy as np

    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.bifurcation import DIRECTIONS, bifurcation, branch_table
    from rimd_sim.analysis.plots import plot_bifurcation
    from rimd_sim.model.validity import domain

    if args.direction not in DIRECTIONS:
        raise CommandError(f"--direction {args.direction!r} refused: must be one of {', '.join(DIRECTIONS)}")
    check_range("f", args.f_min, args.f_max)
    config = load_model_config(args)
    freqs = np.round(np.arange(args.f_min, args.f_max + args.f_step / 2, args.f_step), 6)
    print(f"rimd bifurcation: {len(freqs)} frequencies, sweep {args.direction}...", file=sys.stderr, flush=True)
    branches, wall, workers = bifurcation(config, freqs, args.direction, transient_cycles=args.transient_cycles,
                                          sample_cycles=args.sample_cycles, ramp_rate=args.ramp_rate,
                                          scheduler=args.scheduler)
    clock.writing()
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "bifurcation.csv", branch_table(branches))
    summary = {
        "gap_mm": args.gap_mm, "gap_ratio": config.rig.gap / config.rig.amplitude, "direction": args.direction,
        "frequencies": len(freqs), "transient_cycles": args.transient_cycles, "sample_cycles": args.sample_cycles,
        "branches": {b.direction: class_runs([p.frequency_hz for p in b.points], [p.label for p in b.points])
                     for b in branches},
        "simulated_seconds": sum(b.simulated_seconds for b in branches), "wall_seconds": wall, "workers": workers,
        "validity": domain(config).report(v for b in branches for v in b.verdicts),
        "restarts_from_rest_hz": {b.direction: list(b.restarts) for b in branches},
    }
    write_summary(args.out, summary)
    plot_bifurcation(branches, args.out / "bifurcation.png",
                     f"RIMD model, gap {args.gap_mm:g} mm: stroboscopic displacement, sweep {args.direction}",
                     caption=describe(config))
    for b in branches:
        doubled = [r for r in summary["branches"][b.direction] if r["class"] == "2/2"]
        note = ("2/2 (period doubling) at " + ", ".join(f"{r['f_from_hz']:g}-{r['f_to_hz']:g} Hz" for r in doubled)
                if doubled else "no 2/2 motion")
        print(f"sweep {b.direction}: {note}")
    print(clock.times(f"{summary['simulated_seconds']:.0f} s simulated in {wall:.1f} s on {workers} process(es)")
          + f"; files in {args.out}")
    sentence = domain(config).sentence(v for b in branches for v in b.verdicts)
    return validity_exit("bifurcation", sentence, args.accept_invalid,
                         f"the invalid_rule column of {args.out / 'bifurcation.csv'}")
