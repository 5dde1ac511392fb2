"""``rimd paper``: every figure of the paper the twin can make, in its layout, and the validation table.

Writes into ``DIR`` (default ``out/paper``): ``validation.md`` and ``validation.csv`` (every published finding,
the paper's value, the twin's, the tolerance, pass or fail: :mod:`rimd_sim.analysis.dynamics.paper_targets`),
``fig06_08_forces.png``, ``fig09_period1.png``, ``fig10_period_half.png``, ``fig11_bifurcation.png``,
``fig12_peterka.png``, ``continuation_gap0.png`` and ``summary.json``. Exit status 0 when the files are
written, whatever the findings: a finding the twin does not reproduce is a result, marked FAIL in the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rimd_sim.cli import count
from rimd_sim.cli.verbs._analysis_io import add_config_arguments, read_config

#: The paper's Fig. 9 and 10 conditions: gap (mm) and Omega/omega (the paper's omega).
FIG9 = (1.0, 1.5)
FIG10 = (2.4, 2.7)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd paper``."""
    add_config_arguments(parser)
    parser.add_argument("--out", type=Path, default=Path("out/paper"), help="output directory, default out/paper")
    parser.add_argument("--workers", type=count("--workers"), default=None, help="processes (default: all cores)")


def main(args: argparse.Namespace) -> int:
    """Compute every finding and figure, write the files."""
    import time

    from rimd_sim.analysis.captions import describe
    from rimd_sim.analysis.dynamics.bifurcation import bifurcation
    from rimd_sim.analysis.dynamics.continuation import ContinuationSettings, continuation
    from rimd_sim.analysis.dynamics.paper_targets import PAPER_NATURAL_FREQUENCY_HZ, check_targets, trajectory
    from rimd_sim.analysis.outputs import write_csv, write_summary
    from rimd_sim.analysis.paper_report import (
        plot_paper_bifurcation,
        plot_paper_forces,
        plot_paper_peterka,
        validation_markdown,
    )
    from rimd_sim.analysis.plots import plot_continuation, plot_poincare

    started = time.perf_counter()
    config = read_config(args)
    rig = config.rig

    def log(text: str) -> None:
        print(f"rimd paper: {text} ({time.perf_counter() - started:.0f} s)", file=sys.stderr, flush=True)

    run = check_targets(config, workers=args.workers, log=log)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    caption = describe(config)
    ratios = {gap: gap * 1e-3 / rig.amplitude for gap in run.sweeps}
    figures = [("fig06_08_forces.png", "Figs. 6 and 8: F_i/mg against Omega/omega from rest, three gaps; Table 1 "
                                       "and the published forces marked")]
    plot_paper_forces(run.sweeps, ratios, rig.mass, rig.gravity, out / figures[0][0], caption)
    for (gap, ratio), name, words in ((FIG9, "fig09_period1.png", "Fig. 9: period-1 motion"),
                                      (FIG10, "fig10_period_half.png", "Fig. 10: period-1/2 motion")):
        f = ratio * PAPER_NATURAL_FREQUENCY_HZ
        log(f"trajectory at gap {gap:g} mm, {f:.3f} Hz")
        tr = trajectory(config, gap, f)
        text = f"{words}, gap {gap:g} mm, Omega/omega {ratio:g} ({f:.3f} Hz), from rest: {tr.label}"
        plot_poincare(tr.t, tr.x_rimd_mm, tr.x_cart_mm, tr.u, tr.v, tr.strobe_u, tr.strobe_v, out / name, text,
                      caption=caption)
        figures.append((name, text))
    figures.append(("fig11_bifurcation.png", "Fig. 11: bifurcation diagrams of l sin(theta)/A0, up, down and from "
                                             "rest, three gaps"))
    plot_paper_bifurcation(run.branches, ratios, out / figures[-1][0], caption)
    assert run.peterka is not None   # check_targets computes it
    figures.append(("fig12_peterka.png", "Fig. 12: Peterka map, gap/A0 against Omega/omega, motion from rest and "
                                         "coexisting motions"))
    plot_paper_peterka(run.peterka, out / figures[-1][0], caption)
    log("continuation of the gap-0 period-1 branch")
    gap0 = config.with_parameters({"gap": 0.0})
    cont = continuation(gap0, 3.0, 5.6, settings=ContinuationSettings(max_period=4))
    diagram, _, _ = bifurcation(gap0, [round(3.0 + 0.05 * k, 3) for k in range(53)], "both", workers=args.workers)
    figures.append(("continuation_gap0.png", "Continuation of the gap-0 period-1 orbit and its period doubling "
                                             "(stable solid, unstable dashed), over the brute-force diagram"))
    plot_continuation(cont, out / figures[-1][0], figures[-1][1], natural_frequency_hz=rig.natural_frequency,
                      length_m=rig.length, amplitude_m=rig.amplitude, diagram=diagram, caption=caption)
    seconds = time.perf_counter() - started
    config_line = (f"Configuration: {args.config or 'config/rimd.yaml'}"
                   + "".join(f", {k} = {v}" for k, v in (getattr(args, "settings", None) or []))
                   + f" ({caption}).")
    command = "rimd paper" + (f" --config {args.config}" if args.config else "") + "".join(
        f" --set {k}={v}" for k, v in (getattr(args, "settings", None) or []))
    (out / "validation.md").write_text(validation_markdown(run.checks, figures, config_line=config_line,
                                                           seconds=seconds, command=command) + "\n")
    write_csv(out / "validation.csv", [c.row() for c in run.checks])
    write_summary(out, {"passed": run.passed, "findings": len(run.checks), "checks": [c.row() for c in run.checks],
                        "doubling_hz": run.doubling_hz,
                        "lyapunov": {str(g): {"exponent_per_s": e, "frequency_hz": f, "sweep": d}
                                     for g, (e, f, d) in run.lyapunov.items()},
                        "continuation_bifurcations": [{"kind": b.kind, "frequency_hz": b.frequency_hz,
                                                       "period": b.period} for b in cont.bifurcations],
                        "seconds": {**run.seconds, "all": seconds}, "figures": [n for n, _ in figures]})
    for c in run.checks:
        print(f"{'pass' if c.passed else 'FAIL'}  {c.finding}: paper {c.paper}, twin {c.twin} ({c.tolerance})")
    print(f"rimd paper: {run.passed} of {len(run.checks)} findings reproduced; files in {out} ({seconds:.0f} s)")
    return 0
