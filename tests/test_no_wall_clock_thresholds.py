"""The functional suite asserts what happened, never how fast: no assertion compares a wall-clock duration.

Speed and lateness are figures of the benchmarks (benchmarks/), measured on an idle machine or as ratios of one
run; a test that needs time waits on an observable condition with a deadline (docs/development.md, "Green under
load"). This scan fails on an ``assert`` line of tests/ that compares a wall-clock reading (``time.monotonic()``,
``time.perf_counter()``, ``time.time()``) or a variable named for one (``took``, ``elapsed``, ``wall_s``,
``lateness``, ``latency_s``), or a name the file assigns from such a reading (``made = time.monotonic()``), with
``<``, ``<=``, ``>`` or ``>=``.
"""

from __future__ import annotations

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
CLOCK = re.compile(r"\b(time\.monotonic\(\)|time\.perf_counter\(\)|time\.time\(\)|took|elapsed|wall_s|lateness|"
                   r"latency_s)\b")
COMPARE = re.compile(r"(<=?|>=?)(?!>)")
#: ``name = <a wall-clock reading>``: the name holds a wall-clock instant in that file.
ASSIGNED = re.compile(r"^\s*(\w+)\s*=\s*time\.(?:monotonic|perf_counter|time)\(\)\s*$")


def offending_lines(root: Path = TESTS) -> list[str]:
    """``path:line: text`` of every assert line that compares a wall-clock reading."""
    out = []
    for path in sorted(root.rglob("*.py")):
        if path.name == Path(__file__).name:
            continue
        lines = path.read_text().splitlines()
        names = {m.group(1) for m in map(ASSIGNED.match, lines) if m}
        clock = re.compile(CLOCK.pattern + "".join(rf"|\b{name}\b" for name in sorted(names)))
        for n, line in enumerate(lines, 1):
            text = line.strip()
            if text.startswith("assert ") and clock.search(text) and COMPARE.search(text.split(",")[0]):
                out.append(f"{path.relative_to(root.parent)}:{n}: {text}")
    return out


def test_no_assertion_compares_a_wall_clock_duration():
    assert offending_lines() == []


def test_the_scan_finds_such_an_assertion(tmp_path):
    (tmp_path / "test_x.py").write_text("def test_x():\n    took = 1.0\n    assert took < 5.0, took\n"
                                        "    assert summary['wall_s'] > 0 or True\n    assert len(x) == 3\n"
                                        "    made = time.monotonic()\n    assert heard[0] - made < 0.8\n"
                                        "    assert made_count < 3\n")
    found = offending_lines(tmp_path)
    assert len(found) == 3 and "took < 5.0" in found[0] and "made < 0.8" in found[2]
