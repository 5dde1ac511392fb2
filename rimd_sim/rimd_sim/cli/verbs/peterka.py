"""``rimd peterka``: Peterka map, the class of the motion over gap/A0 x Omega/omega (paper Fig. 12 left).

Each cell is classified ``p/n`` (p impacts in n cycles), ``no impact`` or ``chaotic/non-periodic`` from
rest, from a kick and continuing from the neighbouring lower frequency, and from ``--starts`` more (the
no-impact forced response, then points spread over the region of ``rimd basins``); cells where these
differ (coexisting attractors, a lower bound at that resolution) are marked. Each trajectory stops when
its motion is known, or at the cap. Writes ``DIR/peterka.png``, ``DIR/peterka.csv``, ``DIR/peterka.npz``
(the same as arrays) and ``DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import sys
import time

from rimd_sim.cli import CommandError, count, gap_mm
from rimd_sim.cli.verbs._analysis_io import (
    VerbClock,
    add_accept_invalid_argument,
    add_map_arguments,
    add_model_arguments,
    check_range,
    progress_printer,
    read_config,
    validity_exit,
    write_columns,
    write_summary,
)

#: ``rimd_sim.analysis.dynamics.peterka.DEFAULT_EXTRA_STARTS``, without importing the analysis to build the parser.
DEFAULT_EXTRA_STARTS = 1
#: ``rimd_sim.analysis.dynamics.peterka.MAX_REST_CYCLES``, likewise.
MAX_REST_CYCLES = 1_000_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd peterka``."""
    add_model_arguments(parser, "out/peterka", f_range=(1.82, 9.1))
    parser.add_argument("--gap-min-mm", type=gap_mm("--gap-min-mm"), default=0.0,
                        help="smallest gap (mm), default 0")
    parser.add_argument("--gap-max-mm", type=gap_mm("--gap-max-mm"), default=3.0,
                        help="largest gap (mm), default 3")
    parser.add_argument("--gaps", type=count("--gaps"), default=31, help="gap values, default 31")
    parser.add_argument("--freqs", type=count("--freqs"), default=61, help="frequency values, default 61")
    add_map_arguments(parser, transient=120)
    parser.add_argument("--starts", type=count("--starts", 0, 4096), default=DEFAULT_EXTRA_STARTS,
                        help=f"extra starts per cell looking for coexisting attractors, default "
                             f"{DEFAULT_EXTRA_STARTS} (the no-impact forced response; more: points spread over "
                             f"the region of rimd basins); 0: the three-start map")
    parser.add_argument("--rest-cycles", type=count("--rest-cycles", 1, MAX_REST_CYCLES), default=None,
                        help="cap of the start from rest, which gives each cell its class: unsettled at the "
                             "others' cap, it runs on to this many cycles (default: 640, or --transient-cycles + "
                             "--measure-cycles if larger; its agreement with longer runs: docs/benchmarks.md)")
    add_accept_invalid_argument(parser)
    parser.add_argument("--compare-fixed", action="store_true",
                        help="also compute the map at fixed length (both caps) and list the differing cells in "
                             "summary.json, each with a 10x longer run's class")


def main(args: argparse.Namespace) -> int:
    """Compute the map and write its files."""
    clock = VerbClock()
    import numpy as np

    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.cells import cycles_summary
    from rimd_sim.analysis.dynamics.peterka import (
        START_NAMES,
        compare_maps,
        peterka,
        peterka_columns,
        save_peterka_npz,
    )
    from rimd_sim.analysis.plots import plot_peterka
    from rimd_sim.model.validity import Verdict, domain

    check_range("gap", args.gap_min_mm, args.gap_max_mm, allow_zero=True, unit="-mm")
    check_range("f", args.f_min, args.f_max)
    cap = args.transient_cycles + args.measure_cycles
    if args.rest_cycles is not None and args.rest_cycles < cap:
        raise CommandError(f"--rest-cycles {args.rest_cycles} refused: must be at least the cap of the other starts, "
                           f"--transient-cycles + --measure-cycles = {cap}")
    config = read_config(args)
    gaps = np.linspace(args.gap_min_mm, args.gap_max_mm, args.gaps) * 1e-3
    freqs = np.linspace(args.f_min, args.f_max, args.freqs)
    result = peterka(config, gaps, freqs, transient_cycles=args.transient_cycles,
                     measure_cycles=args.measure_cycles, early_stop=not args.fixed_length, starts=args.starts,
                     rest_cycles=args.rest_cycles, workers=args.workers,
                     scheduler=args.scheduler, progress=progress_printer("peterka", "gap rows"))
    comparison, compared = None, 0.0
    if args.compare_fixed and not args.fixed_length:
        started = time.perf_counter()
        fixed = peterka(config, gaps, freqs, transient_cycles=args.transient_cycles,
                        measure_cycles=args.measure_cycles, early_stop=False, starts=args.starts,
                        rest_cycles=result.rest_cap, workers=args.workers, scheduler=args.scheduler,
                        progress=progress_printer("peterka (fixed length)", "gap rows"))
        comparison = compare_maps(result, fixed, config, args.measure_cycles)
        compared = time.perf_counter() - started
    clock.writing()
    args.out.mkdir(parents=True, exist_ok=True)
    write_columns(args.out / "peterka.csv", peterka_columns(result))
    save_peterka_npz(result, args.out / "peterka.npz")
    summary = {
        "gaps_mm": [args.gap_min_mm, args.gap_max_mm, args.gaps],
        "frequencies_hz": [args.f_min, args.f_max, args.freqs],
        "cells": int(result.primary.size), "starts": list(START_NAMES), "classes_from_rest": result.class_counts(),
        "coexisting_cells": int(result.coexisting.sum()),
        "coexistence": {"starts_per_cell": result.starts, "extra_starts": args.starts, "lower_bound": True,
                        "resolution": "rest, kick, continued"
                        + (", the no-impact forced response" if args.starts else "")
                        + (f" and {args.starts - 1} Halton points over the region of rimd basins"
                           if args.starts > 1 else "")},
        "transient_cycles": args.transient_cycles,
        "measure_cycles": args.measure_cycles, "rest_cycles": result.rest_cap, "early_stop": result.early_stop,
        "stop": result.stop, "cycles_run": cycles_summary(result.cycles, result.cycles_per_start, result.rest_cap),
        "wall_seconds": result.wall_seconds, "workers": result.workers, "where": result.where,
        "validity": result.validity,
    }
    if comparison is not None:
        summary["comparison"] = comparison
    write_summary(args.out, summary)
    longer = f", run up to {result.rest_cap} cycles" if result.rest_cap > cap else ""
    plot_peterka(result, args.out / "peterka.png", f"RIMD model: Peterka map (class of the motion from rest{longer})",
                 caption=describe(config, omit=("gap",)))
    if comparison is not None:
        differ = [c for c in comparison["differing_cells"] if c["start"] == "rest"]
        print(f"early stop vs fixed length ({comparison['fixed_cycles']} cycles; the fixed-length map and the "
              f"long runs computed in {compared:.1f} s): "
              f"{100 * comparison['agreement_from_rest']:.2f} % of the cells agree (class from rest); differing: "
              + (", ".join(f"{c['gap_mm']:g} mm {c['frequency_hz']:.3f} Hz {c['early_stop']} vs {c['fixed_length']} "
                           f"(long run: {c['long_run']})" for c in differ) or "none"))
    on = "process(es)" if result.where == "local" else f"Dask worker thread(s) of {result.where}"
    times = clock.times(f"map computed in {result.wall_seconds:.1f} s on {result.workers} {on}")
    print(f"{result.primary.size} cells, {summary['coexisting_cells']} with coexisting attractors: {times}; "
          f"files in {args.out}", file=sys.stdout)
    unsettled = int((result.cycles[0] > result.rest_cap).sum()) if result.early_stop else 0
    if unsettled:
        longer = (f"; --rest-cycles {10 * cap} runs their start from rest on" if result.rest_cap < 10 * cap else "")
        print(f"{unsettled} cell(s) ({100 * unsettled / result.primary.size:.1f} %) classified at the cap of "
              f"{result.rest_cap} cycles from rest without having settled (chaotic, or a transient longer than the "
              f"cap){longer}", file=sys.stdout)
    rules = [] if result.invalid_rule is None else result.invalid_rule.ravel().tolist()
    sentence = domain(config).sentence((Verdict.of(r) for r in rules), "cells")
    return validity_exit("peterka", sentence, args.accept_invalid,
                         f"the invalid_rule column of {args.out / 'peterka.csv'}")
