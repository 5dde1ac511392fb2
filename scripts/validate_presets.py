#!/usr/bin/env python3
"""What each shipped preset reproduces of the paper: docs/validation/presets.csv (docs/configuration.md's table).

Runs the paper's findings (:func:`rimd_sim.analysis.dynamics.paper_targets.check_targets`, what ``rimd paper``
checks) on every preset of config/ and writes one row per preset and finding. ``scripts/gen_docs.py`` renders
the table from it; ``--check`` compares a fresh run with the file instead (exit 1 naming what differs).

The findings are computed without what only ``rimd paper``'s figures show (``check_targets(..., figures=False)``:
no bifurcation diagram at gap 0, the costliest part of the two-mass preset's run).

Usage: scripts/validate_presets.py [--check [--presets NAME...]] [--workers N]
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PRESETS = ("rimd.yaml", "paper_model.yaml", "structural.yaml")
OUT = ROOT / "docs" / "validation" / "presets.csv"
FIELDS = ["preset", "key", "finding", "paper", "twin", "unit", "passed"]


def rows(workers: int | None, presets=PRESETS) -> list[dict]:
    """One row per preset and finding."""
    from rimd_sim.analysis.dynamics.paper_targets import check_targets
    from rimd_sim.settings.config import load_config

    out = []
    for name in presets:
        config = load_config(ROOT / "config" / name)
        checks = check_targets(config, workers=workers, figures=False).checks
        for c in checks:
            row = c.row()
            out.append({"preset": name, **{k: row[k] for k in FIELDS[1:]}})
    return out


def render(table: list[dict]) -> str:
    """The CSV text of the rows."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(table)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    """Write (or, with ``--check``, compare) docs/validation/presets.csv; the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with docs/validation/presets.csv")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), choices=PRESETS,
                        help="with --check, compare only these presets' rows")
    args = parser.parse_args(argv)
    text = render(rows(args.workers, args.presets if args.check else PRESETS))
    if args.check:
        old = OUT.read_text() if OUT.exists() else ""
        if set(args.presets) != set(PRESETS):   # the file's rows of the presets asked for
            lines = old.splitlines(keepends=True)
            old = lines[0] + "".join(line for line in lines[1:] if line.split(",", 1)[0] in args.presets)
        if old != text:
            changed = sorted(set(text.splitlines()) ^ set(old.splitlines()))
            print(f"{OUT.relative_to(ROOT)} differs from the presets' findings (run scripts/validate_presets.py):\n"
                  + "\n".join(changed[:20]), file=sys.stderr)
            return 1
        return 0
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
