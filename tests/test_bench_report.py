"""benchmarks/report.py writes docs/benchmarks.md's tables from a figures file, in this process, running no benchmark.

The figures come from ``benchmarks/_figures.record`` as the benchmarks call it (a JSON line per figure); the page's
sections sit between ``BENCHMARKS`` markers, which scripts/gen_docs.py's ``GENERATED`` markers never match.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: Dates of runs, built from pieces (tests/test_code_text.py reads a written date as history).
DATE, LATER, LATEST, EARLIER = ("-".join(("2026", "12", day)) for day in ("02", "03", "04", "01"))


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module   # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


report = _load("bench_report", ROOT / "benchmarks" / "report.py")
figures = sys.modules["_figures"]   # the module report.py imports, which the benchmarks import too

PAGE = f"""# Benchmarks

What the page is for.

<!-- BEGIN BENCHMARKS: machine -->
- Machine: an older machine.
- All tables: {EARLIER}, load average at most 0.5 at each benchmark's start.
<!-- END BENCHMARKS: machine -->

## Physics core

<!-- BEGIN BENCHMARKS: core -->
| figure | value | target | benchmark |
|---|---|---|---|
| integrating, median of 5 points | 9,000× | ≥ 10,000: not met | `bench_core.py` |
| structural model, all channels, worst point | not measured idle | ≥ 1,000 | `bench_structural.py` |
<!-- END BENCHMARKS: core -->

## Lockstep

<!-- BEGIN BENCHMARKS: lockstep -->
| figure | value | target | benchmark |
|---|---|---|---|
| an old figure of the lockstep bench | 1× | — | `bench_lockstep.py` |
| hold at a consumer's join, worst run | 0.089 s | ≤ 1: met | `bench_lockstep_join.py` |
<!-- END BENCHMARKS: lockstep -->

## Latency

<!-- BEGIN BENCHMARKS: latency -->
| figure | value | target | benchmark |
|---|---|---|---|
| `rimd --help` | 0.066 s | ≤ 0.3: met | `bench_latency.py` |
<!-- END BENCHMARKS: latency -->

<!-- BEGIN GENERATED: verb-info -->
owned by scripts/gen_docs.py
<!-- END GENERATED: verb-info -->
"""


def _record(monkeypatch: pytest.MonkeyPatch, path: Path, script: str, *args) -> None:
    """``_figures.record(*args)`` as the benchmark ``script`` calls it, into the figures file ``path``."""
    monkeypatch.setenv(figures.ENV, str(path))
    monkeypatch.setattr(sys, "argv", [script])
    figures.record(*args)


def _figures_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "figures.jsonl"
    _record(monkeypatch, path, "bench_lockstep.py", "lockstep", "composed rig in lockstep", 27.94, "×", ">= 20")
    _record(monkeypatch, path, "bench_lockstep.py", "lockstep", "hold-back by a lockstep consumer", 16.6, "%", "<= 5")
    _record(monkeypatch, path, "bench_lockstep.py", "lockstep", "speed ratio", 0.94, "", "0.8..1.2")
    _record(monkeypatch, path, "bench_lockstep.py", "lockstep", "no target", 1234.5, "MB")
    _record(monkeypatch, path, "bench_core.py", "core", "integrating, median of 5 points", 10812.3, "×", ">= 10000")
    return path


def _section(text: str, name: str) -> list[str]:
    start = text.index(report.BEGIN.format(name=name))
    end = text.index(report.END.format(name=name))
    return text[start:end].splitlines()[1:]


def test_a_figures_file_becomes_the_rows_of_the_benchmarks_that_ran(tmp_path, monkeypatch, capsys):
    found, run = report.read_figures(_figures_file(tmp_path, monkeypatch))
    assert run is None and [f.script for f in found] == ["bench_lockstep.py"] * 4 + ["bench_core.py"]
    assert "figure [lockstep] composed rig in lockstep: 27.94× (target >= 20: met)" in capsys.readouterr().out

    text = report.update_document(PAGE, found, {"bench_lockstep.py", "bench_core.py"}, None)

    assert _section(text, "lockstep") == [
        "| figure | value | target | benchmark |",
        "|---|---|---|---|",
        "| composed rig in lockstep | 27.9× | ≥ 20: met | `bench_lockstep.py` |",
        "| hold-back by a lockstep consumer | 16.6 % | ≤ 5: not met | `bench_lockstep.py` |",
        "| speed ratio | 0.94 | 0.8–1.2: met | `bench_lockstep.py` |",
        "| no target | 1,234 MB | — | `bench_lockstep.py` |",
        "| hold at a consumer's join, worst run | 0.089 s | ≤ 1: met | `bench_lockstep_join.py` |",
    ]
    assert _section(text, "core")[2:] == [
        "| integrating, median of 5 points | 10,812× | ≥ 10,000: met | `bench_core.py` |",
        "| structural model, all channels, worst point | not measured idle | ≥ 1,000 | `bench_structural.py` |",
    ]
    # What no benchmark of this run wrote stays byte for byte: another table, the machine section (no run line),
    # gen_docs's section.
    assert _section(text, "latency") == _section(PAGE, "latency")
    assert text[text.index("<!-- BEGIN GENERATED"):] == PAGE[PAGE.index("<!-- BEGIN GENERATED"):]
    assert _section(text, "machine") == _section(PAGE, "machine")
    assert report.update_document(text, [], set(), None) == text


def test_the_markers_are_not_gen_docs_markers():
    gen_docs = _load("gen_docs_for_bench_report", ROOT / "scripts" / "gen_docs.py")
    ours = f"{report.BEGIN.format(name='core')}\n{report.END.format(name='core')}\n"
    assert not gen_docs.MARKER.search(ours)
    assert report.MARKER.findall(ours) == [("BEGIN", "core"), ("END", "core")]
    assert not report.MARKER.search("<!-- BEGIN GENERATED: verb-info -->\n")


def test_a_full_run_rewrites_the_machine_section_and_a_partial_run_adds_its_line():
    full = report.Run(DATE, "AMD EPYC, 2 cores, 24 GiB", ["core", "lockstep"], True, {"core": 0.2, "lockstep": 0.9})
    text = report.update_document(PAGE, [], set(), full)
    assert _section(text, "machine") == [
        "- Machine: AMD EPYC, 2 cores, 24 GiB.",
        f"- All tables: {DATE}, load average above 0.5 at the start of lockstep (0.90): those figures are not an "
        "idle machine's.",
    ]
    partial = report.Run(LATER, "AMD EPYC, 2 cores, 24 GiB", ["latency"], False, {"latency": 0.1})
    once = report.update_document(text, [], set(), partial)
    assert _section(once, "machine")[2:] == [f"- `--only` runs on the machine above: `latency` {LATER} (load 0.10)."]
    elsewhere = report.Run(LATEST, "another CPU, 2 cores", ["latency"], False, {"latency": 0.9})
    twice = report.update_document(once, [], set(), elsewhere)
    assert _section(twice, "machine")[:2] == _section(text, "machine")
    assert _section(twice, "machine")[2:] == [
        f"- `--only` runs on another CPU, 2 cores: `latency` {LATEST} (load 0.90, not idle)."]
    # Runs on one machine share its line; a benchmark run again leaves its earlier entry wherever it was.
    more = report.Run(LATEST, "AMD EPYC, 2 cores, 24 GiB", ["core", "rig"], False, {"core": 0.2, "rig": 0.3})
    thrice = report.update_document(twice, [], set(), more)
    again = report.Run(LATEST, "another CPU, 2 cores", ["core"], False, {"core": 0.1})
    four = report.update_document(thrice, [], set(), again)
    assert _section(four, "machine")[2:] == [
        f"- `--only` runs on another CPU, 2 cores: `latency` {LATEST} (load 0.90, not idle), `core` {LATEST} "
        "(load 0.10).",
        f"- `--only` runs on the machine above: `rig` {LATEST} (load 0.30)."]


def test_a_component_without_a_section_is_appended_under_its_heading(capsys):
    figure = report.Figure("foxglove", "CPU the Foxglove sink adds to the bridge", 3.3, "points", "<= 5",
                           "bench_foxglove.py", DATE)
    text = report.update_document(PAGE, [figure], {"bench_foxglove.py"}, None)
    assert text.startswith(PAGE.rstrip("\n"))
    assert text.endswith("## Foxglove sink\n\n<!-- BEGIN BENCHMARKS: foxglove -->\n"
                         "| figure | value | target | benchmark |\n|---|---|---|---|\n"
                         "| CPU the Foxglove sink adds to the bridge | 3.3 points | ≤ 5: met | `bench_foxglove.py` |\n"
                         "<!-- END BENCHMARKS: foxglove -->\n")
    assert "move it where it belongs" in capsys.readouterr().err


def test_targets_and_numbers():
    assert figures.parse_target(">= 20") == (20.0, float("inf"))
    assert figures.parse_target("<=0.5") == (float("-inf"), 0.5)
    assert figures.parse_target("0.97..1.03") == (0.97, 1.03)
    for bad in ("20", "> 20", "1.2..0.8", "at least 20"):
        with pytest.raises(ValueError, match="write '>= N'"):
            figures.parse_target(bad)
    with pytest.raises(ValueError):
        figures.record("core", "a figure", 1.0, "s", "fast")
    assert figures.meets(5.0, "<= 5") and not figures.meets(5.01, "<= 5") and not figures.meets(None, ">= 0")
    assert not figures.meets(float("nan"), ">= 0")
    assert [report.number(v, u) for v, u in ((10800, "×"), (9.5, "%"), (0.066, "s"), (99.52, "%"), (228.9, "µs"),
                                            (0, ""))] == ["10,800", "9.5", "0.066", "99.52", "229", "0"]


def test_from_a_kept_figures_file_the_page_is_written_without_running_anything(tmp_path, monkeypatch):
    path = _figures_file(tmp_path, monkeypatch)
    report.write_run(path, report.Run(DATE, "AMD EPYC, 2 cores, 24 GiB", ["core", "lockstep"], True,
                                      {"core": 0.1, "lockstep": 0.2}))
    page = tmp_path / "benchmarks.md"
    page.write_text(PAGE)
    monkeypatch.setattr(report, "run_bench", lambda *a: pytest.fail("--from ran a benchmark"))

    assert report.main(["--from", str(path), "--doc", str(page)]) == 0
    text = page.read_text()
    assert "| composed rig in lockstep | 27.9× | ≥ 20: met | `bench_lockstep.py` |" in text
    assert f"- All tables: {DATE}, load average at most 0.5 at each benchmark's start." in text


def test_it_refuses_a_loaded_machine_without_force(tmp_path, monkeypatch, capsys):
    page = tmp_path / "benchmarks.md"
    page.write_text(PAGE)
    monkeypatch.setattr(report.os, "getloadavg", lambda: (3.0, 2.0, 1.0))
    monkeypatch.setattr(report.shutil, "which", lambda name: f"/usr/bin/{name}")
    monkeypatch.setattr(report, "run_bench", lambda *a: pytest.fail("a benchmark ran on a loaded machine"))

    assert report.main(["--only", "core", "--doc", str(page)]) == 2
    assert "load average is 3.00, above 0.5" in capsys.readouterr().err and page.read_text() == PAGE
    with pytest.raises(SystemExit, match="unknown nonsense"):
        report.main(["--only", "core,nonsense", "--doc", str(page)])


def test_the_page_has_every_table_and_names_only_benchmarks_that_exist():
    text = (ROOT / "docs" / "benchmarks.md").read_text()
    names = {b.name for b in report.BENCHES}
    for bench in report.BENCHES:
        assert bench.script is None or (ROOT / "benchmarks" / bench.script).is_file(), bench.script
    for component in ["machine", *report.COMPONENTS]:
        assert report.BEGIN.format(name=component) in text, component
    for line in text.splitlines():
        script = report.row_script(line)
        if script is None or script == "benchmark":
            continue
        only = script.removeprefix("report.py --only ")
        assert (ROOT / "benchmarks" / script).is_file() or only in names, line
