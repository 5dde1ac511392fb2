"""``rimd map``: the steady motion over any two parameters of the model, with its peak force and impact velocity.

Each cell ``(x, y)`` (two declared parameters by their ROS names, or ``frequency``, the motor frequency) runs
from rest at one motor frequency (``--frequency``, unless an axis is the frequency) and is classified ``p/n``,
``no impact`` or ``chaotic/non-periodic``; its classified window gives the peak impact force, ``F / (m g)`` and
the largest impact velocity (:mod:`rimd_sim.analysis.dynamics.maps`). Writes ``DIR/map.csv``, ``DIR/map.npz``
(the same as arrays), ``DIR/map.png`` (the classes and the peak force) and ``DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import sys

from rimd_sim.cli import CommandError, count, positive_float
from rimd_sim.cli.verbs._analysis_io import (
    CONFIG_GAP,
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


def _values(option: str):
    """An argparse ``type``: comma-separated finite numbers (``0.1,0.15,0.2``)."""
    import math

    def convert(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",") if v.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} {text!r} refused: must be numbers separated by commas") \
                from None
        if not values or not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"{option} {text!r} refused: must be finite numbers separated by commas")
        return values

    convert.__name__ = "numbers"
    return convert


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd map``."""
    for axis, what in (("x", "columns"), ("y", "rows")):
        parser.add_argument(f"--{axis}", required=True, metavar="NAME",
                            help=f"parameter of the {what}: a ROS parameter name (natural_frequency, mass, gap, "
                                 "contact.stiffness, ...) or frequency (the motor frequency, Hz)")
        group = parser.add_mutually_exclusive_group(required=True)
        group.add_argument(f"--{axis}-values", type=_values(f"--{axis}-values"), metavar="V1,V2,...",
                           help=f"values of --{axis}, in the parameter's declared unit (SI: gap in m)")
        group.add_argument(f"--{axis}-range", nargs=3, metavar=("FROM", "TO", "COUNT"),
                           help=f"COUNT values of --{axis} evenly from FROM to TO")
    parser.add_argument("--frequency", type=positive_float("--frequency", "Hz"), default=None,
                        help="motor frequency of every cell (Hz); needed unless an axis is frequency")
    add_model_arguments(parser, "out/map", gap=CONFIG_GAP, gap_note=" (unless an axis is gap)")
    add_map_arguments(parser, transient=120)
    add_accept_invalid_argument(parser)


def _axis(args: argparse.Namespace, axis: str) -> list[float]:
    """The values of an axis from ``--AXIS-values`` or ``--AXIS-range FROM TO COUNT``."""
    import math

    import numpy as np

    values = getattr(args, f"{axis}_values")
    if values is not None:
        return values
    lo, hi, n = getattr(args, f"{axis}_range")
    option = f"--{axis}-range"
    try:
        lo_v, hi_v = float(lo), float(hi)
        count_v = count(option, 1)(n)
    except (ValueError, argparse.ArgumentTypeError):
        raise CommandError(f"{option} {lo} {hi} {n} refused: need FROM TO (numbers) and COUNT (an integer >= 1)") \
            from None
    if not (math.isfinite(lo_v) and math.isfinite(hi_v)):
        raise CommandError(f"{option} {lo} {hi} {n} refused: FROM and TO must be finite")
    return np.linspace(lo_v, hi_v, count_v).tolist()


def main(args: argparse.Namespace) -> int:
    """Compute the map and write its files."""
    clock = VerbClock()
    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.maps import parameter_map, save_map_npz
    from rimd_sim.analysis.plots import plot_map
    from rimd_sim.model.validity import Verdict, domain

    xs, ys = _axis(args, "x"), _axis(args, "y")
    config = load_model_config(args)
    result = parameter_map(config, args.x, xs, args.y, ys, frequency_hz=args.frequency,
                           transient_cycles=args.transient_cycles, measure_cycles=args.measure_cycles,
                           early_stop=not args.fixed_length, workers=args.workers, scheduler=args.scheduler,
                           progress=progress_printer("map", "rows"))
    clock.writing()
    args.out.mkdir(parents=True, exist_ok=True)
    write_columns(args.out / "map.csv", result.columns())
    save_map_npz(result, args.out / "map.npz")
    write_summary(args.out, result.summary())
    at = "" if args.frequency is None else f" at {args.frequency:g} Hz"
    plot_map(result, args.out / "map.png", f"RIMD model: {args.y} x {args.x}{at}, from rest",
             caption=describe(config, omit=(args.x, args.y)))
    classes = ", ".join(f"{k}: {v}" for k, v in result.class_counts().items())
    on = "process(es)" if result.where == "local" else f"Dask worker thread(s) of {result.where}"
    times = clock.times(f"map computed in {result.wall_seconds:.1f} s on {result.workers} {on}")
    print(f"{result.labels.size} cells ({classes}): {times}; files in {args.out}", file=sys.stdout)
    sentence = domain(config).sentence((Verdict.of(r) for r in result.invalid_rule.ravel().tolist()), "cells")
    return validity_exit("map", sentence, args.accept_invalid, f"the invalid_rule column of {args.out / 'map.csv'}")
