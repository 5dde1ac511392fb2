"""``rimd peterka``: Peterka map, the class of the motion over gap/A0 x Omega/omega (paper Fig. 12 left).

Each cell is classified ``p/n`` (p impacts in n cycles), ``no impact`` or ``chaotic/non-periodic`` from
rest, from a kick and continuing from the neighbouring lower frequency; cells where these differ (coexisting
attractors) are marked. Writes ``DIR/peterka.png``, ``DIR/peterka.csv`` and ``DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rimd_sim.cli import CommandError

from ._analysis_io import check_positive, check_range, progress_printer, write_csv, write_summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd peterka``."""
    parser.add_argument("--gap-min-mm", type=float, default=0.0, help="smallest gap (mm), default 0")
    parser.add_argument("--gap-max-mm", type=float, default=3.0, help="largest gap (mm), default 3")
    parser.add_argument("--gaps", type=int, default=31, help="gap values, default 31")
    parser.add_argument("--f-min", type=float, default=1.82, help="lowest frequency (Hz), default 1.82")
    parser.add_argument("--f-max", type=float, default=9.1, help="highest frequency (Hz), default 9.1")
    parser.add_argument("--freqs", type=int, default=61, help="frequency values, default 61")
    parser.add_argument("--transient-cycles", type=int, default=60, help="cycles dropped first, default 60")
    parser.add_argument("--measure-cycles", type=int, default=36, help="cycles classified, default 36")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    parser.add_argument("--config", type=Path, default=None, help="ROS parameter YAML (default config/rimd.yaml)")
    parser.add_argument("--out", type=Path, default=Path("out/peterka"), help="output directory")


def main(args: argparse.Namespace) -> int:
    """Compute the map and write its files."""
    import numpy as np

    from rimd_sim.analysis.peterka import START_NAMES, peterka, peterka_table
    from rimd_sim.analysis.plots import plot_peterka
    from rimd_sim.core import RimdError, load_config

    check_range("gap", args.gap_min_mm, args.gap_max_mm, allow_zero=True, unit="-mm")
    check_range("f", args.f_min, args.f_max)
    check_positive("--gaps", args.gaps, minimum=1, inclusive=True)
    check_positive("--freqs", args.freqs, minimum=1, inclusive=True)
    check_positive("--transient-cycles", args.transient_cycles, inclusive=True)
    check_positive("--measure-cycles", args.measure_cycles, minimum=6, inclusive=True)
    if args.workers is not None:
        check_positive("--workers", args.workers, minimum=1, inclusive=True)
    try:
        config = load_config(args.config)
        gaps = np.linspace(args.gap_min_mm, args.gap_max_mm, args.gaps) * 1e-3
        freqs = np.linspace(args.f_min, args.f_max, args.freqs)
        result = peterka(config, gaps, freqs, transient_cycles=args.transient_cycles,
                         measure_cycles=args.measure_cycles, workers=args.workers,
                         progress=progress_printer("peterka", "gap rows"))
    except RimdError as exc:
        raise CommandError(str(exc)) from None
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "peterka.csv", peterka_table(result))
    summary = {
        "gaps_mm": [args.gap_min_mm, args.gap_max_mm, args.gaps],
        "frequencies_hz": [args.f_min, args.f_max, args.freqs],
        "cells": int(result.primary.size), "starts": list(START_NAMES), "classes_from_rest": result.class_counts(),
        "coexisting_cells": int(result.coexisting.sum()), "transient_cycles": args.transient_cycles,
        "measure_cycles": args.measure_cycles, "wall_seconds": result.wall_seconds, "workers": result.workers,
    }
    write_summary(args.out, summary)
    plot_peterka(result, args.out / "peterka.png", "RIMD model: Peterka map (class of the motion from rest)")
    print(f"{result.primary.size} cells, {summary['coexisting_cells']} with coexisting attractors, in "
          f"{result.wall_seconds:.1f} s on {result.workers} process(es); files in {args.out}", file=sys.stdout)
    return 0
