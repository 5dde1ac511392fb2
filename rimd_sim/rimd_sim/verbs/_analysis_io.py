"""Shared plumbing of the analysis verbs: argument checks, progress on stderr, CSV and summary files."""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

from rimd_sim.cli import CommandError


def check_range(name: str, lo: float, hi: float, *, allow_zero: bool = False, unit: str = "") -> None:
    """Refuse a range unless ``0 < lo <= hi`` (``0 <= lo`` with ``allow_zero``), naming the options and values.

    The options are ``--{name}-min{unit}`` and ``--{name}-max{unit}`` (``unit`` for example ``-mm``).
    """
    lo_opt, hi_opt = f"--{name}-min{unit}", f"--{name}-max{unit}"
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise CommandError(f"{lo_opt} {lo:g} / {hi_opt} {hi:g} refused: must be finite")
    if lo < 0 or (lo == 0 and not allow_zero):
        raise CommandError(f"{lo_opt} {lo:g} refused: must be {'>= 0' if allow_zero else '> 0'}")
    if lo > hi:
        raise CommandError(f"{lo_opt} {lo:g} > {hi_opt} {hi:g}: need min <= max")


def check_positive(option: str, value: float, *, minimum: float = 0.0, inclusive: bool = False) -> None:
    """Refuse ``value`` unless it is finite and above ``minimum`` (or equal to it with ``inclusive``)."""
    ok = math.isfinite(value) and (value >= minimum if inclusive else value > minimum)
    if not ok:
        rule = f">= {minimum:g}" if inclusive else f"> {minimum:g}"
        raise CommandError(f"{option} {value!r} refused: must be {rule}")


def progress_printer(verb: str, what: str):
    """A ``progress(done, total)`` callable that rewrites one line on stderr."""
    def progress(done: int, total: int) -> None:
        end = "\n" if done == total else ""
        print(f"\rrimd {verb}: {done}/{total} {what}", end=end, file=sys.stderr, flush=True)

    return progress


def write_csv(path: Path, rows: list[dict]) -> None:
    """Write ``rows`` (dicts with the same keys) as CSV with a header."""
    with open(path, "w", newline="") as fh:
        if not rows:
            return
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def write_summary(out: Path, summary: dict) -> None:
    """Write ``out/summary.json``."""
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")


def class_runs(frequencies, labels) -> list[dict]:
    """Consecutive frequencies of the same class as ``{"class", "f_from_hz", "f_to_hz"}`` runs."""
    runs: list[dict] = []
    for f, label in zip(frequencies, labels, strict=True):
        if runs and runs[-1]["class"] == label:
            runs[-1]["f_to_hz"] = float(f)
        else:
            runs.append({"class": label, "f_from_hz": float(f), "f_to_hz": float(f)})
    return runs
