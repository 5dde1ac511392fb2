"""``rimd fit-table TABLE.csv --out DIR``: the parameter set that best reproduces a table of impact resonances.

See :mod:`rimd_sim.analysis.dynamics.fit_table`. Writes ``DIR/fitted.yaml`` (the base parameter file with the fitted
values), ``DIR/fit_table.csv`` (per entry: the table, the twin's resonance on the 0.25 Hz grid and interpolated,
the peak forces and their residuals), ``DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rimd_sim.cli import count
from rimd_sim.cli.verbs._analysis_io import add_accept_invalid_argument, add_config_arguments, read_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd fit-table``."""
    parser.add_argument("table", type=Path, nargs="?", default=None,
                        help="CSV with gap_mm, band (A, B or natural), frequency_hz, optional peak_force_n "
                             "(default: the paper's Table 1, config/paper_table1.csv)")
    parser.add_argument("--out", type=Path, default=Path("out/fit_table"), help="output directory")
    add_config_arguments(parser, "base parameter file (default config/rimd.yaml)")
    parser.add_argument("--parameters", nargs="+", default=["damping_ratio", "mass"],
                        help="parameters fitted (default: damping_ratio mass; the others are held at the base)")
    parser.add_argument("--max-evaluations", type=count("--max-evaluations"), default=20,
                        help="most parameter sets evaluated (default 20)")
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Fit and write the results."""
    import time

    from rimd_sim.analysis.dynamics.fit_table import SCALES, fit_table, read_table
    from rimd_sim.analysis.outputs import write_parameter_file
    from rimd_sim.cli import CommandError
    from rimd_sim.cli.verbs._analysis_io import validity_exit, write_csv, write_summary
    from rimd_sim.model.validity import Verdict, domain
    from rimd_sim.settings.config import find_config_file

    for p in args.parameters:
        if p not in SCALES:
            raise CommandError(f"--parameters {p!r} refused: must be among {', '.join(SCALES)}")
    if args.max_evaluations < 1:
        raise CommandError(f"--max-evaluations {args.max_evaluations} refused: must be >= 1")
    table = args.table or find_config_file("paper_table1.csv")
    base_path = args.config or find_config_file()
    entries, natural = read_table(table)
    base = read_config(args, {"natural_frequency": natural} if natural else None)
    start = time.perf_counter()
    result = fit_table(base, entries, tuple(args.parameters), max_evaluations=args.max_evaluations,
                       log=lambda text: print(f"rimd fit-table: {text}", file=sys.stderr, flush=True))
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in result["rows"]:
        rows.append({**r, "frequency_residual_hz": None if r["twin_grid_hz"] is None else
                     r["twin_grid_hz"] - r["frequency_hz"],
                     "peak_force_residual_n": (r["twin_grid_peak_force_n"] - r["peak_force_n"])
                     if r["peak_force_n"] and r.get("twin_grid_peak_force_n") is not None else None})
    write_csv(out / "fit_table.csv", rows)
    write_parameter_file(out / "fitted.yaml", base_path, result["config"],
                         f"# Fitted by `rimd fit-table {table}` (parameters: {', '.join(args.parameters)}); "
                         f"base file {base_path}.\n")
    summary = {"table": str(table), "base_config": str(base_path), "fitted": result["values"],
               "natural_frequency_from_table": natural, "misfit": result["misfit"],
               "all_resonances_within_0.25_hz": result["all_within_grid_step"], "entries": rows,
               "start": {"values": result["start"]["values"], "misfit": result["start"]["misfit"]},
               "evaluations": result["evaluations"], "wall_seconds": time.perf_counter() - start,
               "validity": result["validity"], "invalid_sets": result["invalid_sets"],
               "determines": "damping_ratio and mass (the force scale) at most, with A0, the gaps and the contact "
                             "law given; not contact.stiffness and contact.damping separately, nor A0 apart from "
                             "the gaps"}
    write_summary(out, summary)
    print(f"{'gap (mm)':>8} {'band':>4} {'table (Hz)':>10} {'twin (Hz)':>9} {'table F (N)':>11} {'twin F (N)':>10}")
    for r in rows:
        twin = "-" if r["twin_grid_hz"] is None else f"{r['twin_grid_hz']:.2f}"
        tf = "-" if r.get("twin_grid_peak_force_n") is None else f"{r['twin_grid_peak_force_n']:.1f}"
        pf = "-" if r["peak_force_n"] is None else f"{r['peak_force_n']:.1f}"
        print(f"{r['gap_mm']:>8.2f} {r['band']:>4} {r['frequency_hz']:>10.2f} {twin:>9} {pf:>11} {tf:>10}")
    print("fitted: " + ", ".join(f"{p} = {v:.6g}" for p, v in result["values"].items())
          + f" ({result['evaluations']} sets evaluated); files in {out}")
    sentence = domain(base).sentence((Verdict.of(r["invalid_rule"]) for r in rows), "entries")
    return validity_exit("fit-table", sentence, args.accept_invalid,
                         f"the invalid_rule column of {out / 'fit_table.csv'}")
