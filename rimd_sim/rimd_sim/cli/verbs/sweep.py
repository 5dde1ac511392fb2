"""``rimd sweep``: simulated steady peak impact force F_i/mg and impacts per cycle versus Omega/omega.

Writes ``DIR/summary.json`` (its keys: docs/analyses.md, "`rimd sweep`"), ``DIR/sweep.csv`` and ``DIR/sweep.png``
(not with ``--no-plot``: no plotting library is then loaded, nor a figure worker started).
"""

from __future__ import annotations

import argparse
import csv

import numpy as np

from rimd_sim.cli import CommandError, count
from rimd_sim.cli.verbs._analysis_io import (
    CONFIG_GAP,
    VerbClock,
    add_accept_invalid_argument,
    add_model_arguments,
    add_scheduler_argument,
    check_range,
    load_model_config,
    progress_printer,
    validity_exit,
    write_summary,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd sweep``."""
    add_model_arguments(parser, "out/sweep", gap=CONFIG_GAP, f_range=(2.0, 9.5), f_step=0.25)
    parser.add_argument("--direction", choices=("up", "down", "rest"), default="rest",
                        help="rest: each frequency from rest (Table 1); up/down: continue from the previous state")
    parser.add_argument("--cycles", type=count("--cycles", 2), default=150,
                        help="excitation cycles per frequency, default 150")
    parser.add_argument("--measure-cycles", type=count("--measure-cycles"), default=50,
                        help="last cycles read as steady state")
    parser.add_argument("--workers", type=count("--workers"), default=None,
                        help="processes for rest sweeps (default: all cores)")
    add_scheduler_argument(parser)
    add_accept_invalid_argument(parser)
    parser.add_argument("--no-plot", action="store_true",
                        help="no sweep.png (one left by an earlier run is removed): the files only, without "
                             "loading matplotlib (a study scripting many points)")


def main(args: argparse.Namespace) -> int:
    """Run the sweep and write its files."""
    clock = VerbClock()
    from rimd_sim.analysis.executor import local_workers, scheduler_address
    from rimd_sim.analysis.figures import Figures

    check_range("f", args.f_min, args.f_max)
    if args.measure_cycles >= args.cycles:
        raise CommandError(f"--measure-cycles {args.measure_cycles} >= --cycles {args.cycles}: no transient left")
    freqs = np.round(np.arange(args.f_min, args.f_max + args.f_step / 2, args.f_step), 6)
    # The figure's worker only when the sweep runs in this process (no pool of its own forked beside the
    # worker's threads: up/down, or a rest sweep the executor runs inline, its tasks at most one per point);
    # made before the heavy imports, so that it loads the plots meanwhile.
    here = not args.no_plot and scheduler_address(args.scheduler) is None and (
        args.direction != "rest" or local_workers(args.workers, len(freqs)) == 1)
    with Figures(None if here else False) as figures:
        from rimd_sim.analysis.captions import describe
        from rimd_sim.analysis.dynamics.sweep import points_table, sweep

        config = load_model_config(args)
        with progress_printer("sweep", "frequencies") as progress:
            result = sweep(config, freqs, args.direction, cycles=args.cycles, measure_cycles=args.measure_cycles,
                           workers=args.workers, scheduler=args.scheduler, progress=progress)
        clock.writing()
        args.out.mkdir(parents=True, exist_ok=True)
        rows = points_table(result)
        with open(args.out / "sweep.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        write_summary(args.out, result.summary())
        if args.no_plot:
            (args.out / "sweep.png").unlink(missing_ok=True)   # a figure of another run would not match the files
        else:
            figures.draw("plot_sweep", [result], args.out / "sweep.png",
                         f"RIMD model, gap {args.gap_mm:g} mm, sweep {args.direction}", caption=describe(config))
    from rimd_sim.model.validity import Verdict, domain

    def band(p) -> str:
        return "none" if p is None else f"{p.frequency_hz:g} Hz {p.peak_force_n:.1f} N"

    print(f"gap {args.gap_mm:g} mm, {args.direction}: band A {band(result.band_a)}, band B {band(result.band_b)}; "
          + clock.times(f"{result.simulated_seconds:.0f} s simulated in {result.wall_seconds:.1f} s on "
                        f"{result.workers} process(es)") + f"; files in {args.out}")
    sentence = domain(config).sentence(Verdict.of(p.invalid_rule) for p in result.points)
    return validity_exit("sweep", sentence, args.accept_invalid, f"the invalid_rule column of {args.out / 'sweep.csv'}")
