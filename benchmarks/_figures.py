"""A benchmark's headline figures in one format, for docs/benchmarks.md and ``benchmarks/report.py``.

A benchmark calls :func:`record` once per headline figure, after printing its own output. The call prints one
``figure`` line and, when the environment variable ``RIMD_BENCH_FIGURES`` names a file, appends the figure to it
as one JSON line; ``report.py`` sets that variable, runs the benchmarks and writes their tables from the file.

A target is a string: ``">= N"`` (at least N), ``"<= N"`` (at most N) or ``"A..B"`` (from A to B), N, A and B in
the figure's unit. :func:`meets` judges a value against it.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from datetime import UTC, datetime
from pathlib import Path

#: The environment variable naming the JSON-lines file that :func:`record` appends to.
ENV = "RIMD_BENCH_FIGURES"
_NUMBER = r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
_BOUND = re.compile(rf"^\s*(>=|<=)\s*({_NUMBER})\s*$")
_RANGE = re.compile(rf"^\s*({_NUMBER})\s*\.\.\s*({_NUMBER})\s*$")


def parse_target(target: str) -> tuple[float, float]:
    """The closed interval ``(low, high)`` a target allows; a ValueError names a target of another form."""
    if match := _BOUND.match(target):
        bound = float(match.group(2))
        return (bound, math.inf) if match.group(1) == ">=" else (-math.inf, bound)
    if match := _RANGE.match(target):
        low, high = float(match.group(1)), float(match.group(2))
        if low <= high:
            return low, high
    raise ValueError(f"target {target!r}: write '>= N', '<= N' or 'A..B'")


def meets(value: float | None, target: str) -> bool:
    """Whether ``value`` lies within ``target`` (a missing or non-finite value never does)."""
    if value is None or not math.isfinite(value):
        return False
    low, high = parse_target(target)
    return low <= value <= high


def record(component: str, measure: str, value: float, unit: str, target: str | None = None) -> None:
    """Print one headline figure and, when ``RIMD_BENCH_FIGURES`` names a file, append it there as a JSON line.

    Args:
        component: the table of docs/benchmarks.md the figure belongs to (``report.COMPONENTS``: ``core``,
            ``rig``, ``lockstep``, ...).
        measure: what was measured, in words, as the table's first column shows it.
        value: the figure; a non-finite value is written as missing.
        unit: its unit as the table shows it after the number (``s``, ``%``, ``×`` for times real time, ``""``
            for a ratio).
        target: the goal the figure is judged against (the module's docstring), or None.
    """
    if target is not None:
        parse_target(target)   # a malformed target fails the benchmark here, not the report later
    number = float(value) if value is not None and math.isfinite(float(value)) else None
    shown = "missing" if number is None else f"{number:g}{'' if unit in ('', '×') else ' '}{unit}"
    verdict = "" if target is None else f" (target {target}: {'met' if meets(number, target) else 'NOT met'})"
    print(f"figure [{component}] {measure}: {shown}{verdict}", flush=True)
    path = os.environ.get(ENV)
    if path:
        line = {"component": component, "measure": measure, "value": number, "unit": unit, "target": target,
                "script": Path(sys.argv[0]).name, "date": datetime.now(UTC).date().isoformat()}
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps(line, ensure_ascii=False) + "\n")
