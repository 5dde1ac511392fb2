"""Run the curated benchmarks and write their headline figures into docs/benchmarks.md, one table per component.

Each benchmark of :data:`BENCHES` runs as its own process with the arguments that give its headline figures and
with ``RIMD_BENCH_FIGURES`` naming a JSON-lines file, to which its ``_figures.record`` calls append one line per
figure (``benchmarks/_figures.py``). The warm-up and the test suite are timed here, as commands. Then the tables
of docs/benchmarks.md are rewritten between their markers, one pair per component::

    <!-- BEGIN BENCHMARKS: lockstep -->
    | figure | value | target | benchmark |
    ...
    <!-- END BENCHMARKS: lockstep -->

(not scripts/gen_docs.py's ``GENERATED`` markers, which that script owns). A table keeps the rows of benchmarks
that did not run, and the rows of a benchmark that ran are replaced by what it recorded, where its first row was.
The ``machine`` section says once on what machine and on which date the tables were measured: a full run rewrites
it, a run of a few benchmarks (``--only``) adds each to the line of the machine it ran on (benchmark, date, load).

The machine must be idle, since the figures are absolute: with a load average above 0.5 the report refuses to
start unless ``--force`` (then the figures are marked as taken under that load). Before each benchmark it waits up
to ``--settle`` seconds for the load left by the one before to fall back to 0.5; a benchmark that started above
it is named in the machine section. A benchmark that fails (a non-zero exit status) changes no table.

Run (after ``source env.sh``, from the repository root, nothing else running):
    python benchmarks/report.py                     # every default benchmark, every table (about an hour)
    python benchmarks/report.py --only lockstep     # one benchmark (comma-separated names for several)
    python benchmarks/report.py --list              # the benchmarks, their arguments, which are not default
    python benchmarks/report.py --from FIGURES      # rewrite the tables from a kept figures file, run nothing
``--figures FILE`` keeps the figures file of a run (by default a temporary one).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _figures  # noqa: E402 - benchmarks/_figures.py, beside this file

DOC = ROOT / "docs" / "benchmarks.md"
#: The load average (1 min) above which the machine is not idle enough for absolute figures.
IDLE_LOAD = 0.5
BEGIN = "<!-- BEGIN BENCHMARKS: {name} -->"
END = "<!-- END BENCHMARKS: {name} -->"
MARKER = re.compile(r"^<!-- (BEGIN|END) BENCHMARKS: ([\w-]+) -->[ \t]*$", re.MULTILINE)
HEAD = "| figure | value | target | benchmark |\n|---|---|---|---|"
#: The tables, in the page's order: component name (``_figures.record``'s first argument) and heading.
COMPONENTS = {
    "core": "Physics core",
    "rig": "Rig CPU per process",
    "soak": "Soak",
    "lockstep": "Lockstep",
    "latency": "Latency",
    "recording": "Recorder and replay",
    "rerun": "Rerun bridge",
    "foxglove": "Foxglove sink",
    "maps": "Maps at scale",
    "analyses": "Analyses",
    "setup": "Set-up and tests",
}


@dataclass(frozen=True)
class Timed:
    """A command timed here, start to exit, recorded as one figure in seconds."""

    component: str
    measure: str
    argv: tuple[str, ...]
    target: str | None = None
    cold_cache: bool = False   # NUMBA_CACHE_DIR on a new, empty directory: what a first run on a new machine pays


@dataclass(frozen=True)
class Bench:
    """One entry of the report: a benchmark script with its arguments, or commands timed here."""

    name: str
    script: str | None
    args: tuple[str, ...] = ()
    default: bool = True
    commands: tuple[Timed, ...] = ()
    note: str = ""

    @property
    def label(self) -> str:
        """The benchmark column's name for the rows this entry writes: its script, or how to time its commands."""
        return self.script or f"{Path(__file__).name} --only {self.name}"


#: The curated benchmarks, in the order a full run takes them. ``default=False``: only with ``--only``.
BENCHES = (
    Bench("core", "bench_core.py", ("--seconds", "30")),
    Bench("structural", "bench_structural.py", ("--seconds", "30")),
    Bench("rig", "bench_rig.py", ("--seconds", "60", "--warmup", "10", "--block-rate", "50")),
    Bench("faults", "bench_faults.py"),
    Bench("lockstep", "bench_lockstep.py", ("--seconds", "12", "--warmup", "5")),
    Bench("lockstep_join", "bench_lockstep_join.py", ("--runs", "3")),
    Bench("latency", "bench_latency.py", ("--repeats", "5")),
    Bench("recorder", "bench_recorder.py"),
    Bench("replay", "bench_replay.py"),
    Bench("rerun", "bench_rerun.py"),
    Bench("browser", "bench_browser.py", default=False,
          note="needs Debian's chromium and tesseract-ocr, and playwright"),
    Bench("foxglove", "bench_foxglove.py", ("--seconds", "30", "--warmup", "5")),
    Bench("maps", "bench_maps.py", ("--sections", "3,6", "--skip-big", "--skip-dask", "--workers", "2")),
    Bench("wall", "bench_wall.py", ("--large", "--only", "peterka,map,basins,bifurcation,continue")),
    Bench("analysis", "bench_analysis.py", ("--peterka", "20")),
    Bench("identify", "bench_identify.py", ("--time",)),
    Bench("fixture", "bench_fixture.py", ("--cold", "1", "--warm", "0")),
    Bench("warmup", None, commands=(
        Timed("setup", "`rimd warmup`, empty numba cache", ("rimd", "warmup"), cold_cache=True),
        Timed("setup", "`rimd warmup --all`, empty numba cache", ("rimd", "warmup", "--all"), cold_cache=True),
    ), note="rimd warmup and --all, each on an empty numba cache"),
    Bench("soak", "bench_soak.py", ("--minutes", "60"), default=False, note="an hour"),
    Bench("suite", None, default=False, commands=(
        Timed("setup", "`make test-fast`", ("make", "test-fast")),
        Timed("setup", "`make test`", ("make", "test"), target="<= 300"),
        Timed("setup", "the same, `RIMD_TEST_WORKERS=2` (one per core)",
              ("env", "RIMD_TEST_WORKERS=2", "make", "test")),
        Timed("setup", "`make test-dist` (wheels built)", ("make", "test-dist")),
    ), note="make test-fast, make test and make test-dist"),
)


@dataclass(frozen=True)
class Figure:
    """One recorded figure (a line of the figures file)."""

    component: str
    measure: str
    value: float | None
    unit: str
    target: str | None
    script: str
    date: str


@dataclass
class Run:
    """What the machine section says about one run: when, where, under which load, which benchmarks."""

    date: str
    machine: str
    entries: list[str]
    full: bool
    loads: dict[str, float] = field(default_factory=dict)   # each benchmark's load average at its start


# ---- the figures file ----------------------------------------------------------------------------------------------

def read_figures(path: Path) -> tuple[list[Figure], Run | None]:
    """The figures of a JSON-lines file and its last run line (None when it has none)."""
    figures, run = [], None
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
            if "run" in data:
                run = Run(**data["run"])
                continue
            figures.append(Figure(**{k: data.get(k) for k in Figure.__dataclass_fields__}))
        except (ValueError, TypeError) as exc:
            raise SystemExit(f"report: {path}:{number}: not a figure: {exc}") from None
    return figures, run


def figure_lines(figures: list[Figure]) -> str:
    """Figures as the lines of a figures file."""
    return "".join(json.dumps(f.__dict__, ensure_ascii=False) + "\n" for f in figures)


def write_run(path: Path, run: Run) -> None:
    """Append the run's line to the figures file, so that ``--from`` can write the machine section again."""
    with path.open("a", encoding="utf-8") as out:
        out.write(json.dumps({"run": run.__dict__}) + "\n")


# ---- rendering -------------------------------------------------------------------------------------------------------

def number(value: float, unit: str = "") -> str:
    """A figure's number: three significant digits below 100, whole with thousands separators from 100 on.

    A percentage from 90 to 100 keeps four digits, so that it is told apart from a target such as 99.5 %.
    """
    if abs(value) >= 100:
        return f"{value:,.0f}"
    return f"{value:.4g}" if unit == "%" and abs(value) >= 90 else f"{value:.3g}"


def with_unit(text: str, unit: str) -> str:
    """``28.2 s``, ``29.3 %``, ``27.9×`` (times real time), or the number alone for a ratio."""
    return text + unit if unit in ("", "×") else f"{text} {unit}"


def value_cell(figure: Figure) -> str:
    return "—" if figure.value is None else with_unit(number(figure.value, figure.unit), figure.unit)


def target_cell(figure: Figure) -> str:
    """``≥ 20: met``, ``≤ 12: not met``, ``0.8–1.2: met`` (in the value's unit), or ``—`` without a target."""
    if figure.target is None:
        return "—"
    low, high = _figures.parse_target(figure.target)
    if low == -float("inf"):
        goal = "≤ " + number(high, figure.unit)
    elif high == float("inf"):
        goal = "≥ " + number(low, figure.unit)
    else:
        goal = f"{number(low, figure.unit)}–{number(high, figure.unit)}"
    if figure.value is None:
        return goal
    return f"{goal}: {'met' if _figures.meets(figure.value, figure.target) else 'not met'}"


def row(figure: Figure) -> str:
    return f"| {figure.measure} | {value_cell(figure)} | {target_cell(figure)} | `{figure.script}` |"


def row_script(line: str) -> str | None:
    """The benchmark a table row names in its last cell (None for a line that is not a row of figures)."""
    cells = [c.strip() for c in line.strip().strip("|").split("|")]
    if len(cells) < 4 or not cells[-1].startswith("`"):
        return None
    return cells[-1].strip("`")


def merge_rows(old: list[str], new: list[Figure], ran: set[str]) -> list[str]:
    """The table's rows: the old ones of benchmarks that did not run, the new ones where their benchmark's were."""
    by_script: dict[str, list[str]] = {}
    for figure in new:
        by_script.setdefault(figure.script, []).append(row(figure))
    out, placed = [], set()
    for line in old:
        script = row_script(line)
        if script not in ran:
            out.append(line)
        elif script not in placed:
            out.extend(by_script.get(script, []))
            placed.add(script)
    for script, rows in by_script.items():
        if script not in placed:
            out.extend(rows)
    return out


def _section(text: str, name: str, heading: str | None) -> tuple[str, tuple[int, int] | None]:
    """``text`` and where the content of ``name``'s section is (None when the page has no such section).

    Given a ``heading`` (a ``## title`` line, or "" for none), a missing section is appended at the end of the page
    under it first, so that the place is never None then.
    """
    span = _span(text, name)
    if span is not None or heading is None:
        return text, span
    text = text.rstrip("\n") + f"\n\n{heading}{BEGIN.format(name=name)}\n{END.format(name=name)}\n"
    print(f"report: appended the section '{name}' at the end of the page: move it where it belongs", file=sys.stderr)
    return text, _span(text, name)


def _span(text: str, name: str) -> tuple[int, int] | None:
    """Where the content between ``name``'s markers starts and ends (None when the page has no such section)."""
    begin = re.search(rf"^{re.escape(BEGIN.format(name=name))}[ \t]*\n", text, re.MULTILINE)
    if begin is None:
        return None
    end = re.compile(rf"^{re.escape(END.format(name=name))}[ \t]*$", re.MULTILINE).search(text, begin.end())
    if end is None:
        raise SystemExit(f"report: {BEGIN.format(name=name)} has no {END.format(name=name)}")
    return begin.end(), end.start()


def _first(pattern: str, path: str) -> str | None:
    """The first group of ``pattern``'s first match in the file ``path`` (None when it is missing or unmatched)."""
    try:
        found = re.search(pattern, Path(path).read_text(), re.MULTILINE)
    except OSError:
        return None
    return found.group(1).strip() if found else None


def machine() -> str:
    """The CPU model, its cores, the memory, the system and Python, from /proc and the interpreter."""
    model = _first(r"^model name\s*:(.*)$", "/proc/cpuinfo") or platform.machine()
    mem_kb = _first(r"^MemTotal:\s+(\d+)", "/proc/meminfo")
    memory = f"{int(mem_kb) / 2 ** 20:.0f} GiB" if mem_kb else "memory unknown"
    system = _first(r'^PRETTY_NAME="?([^"\n]+)', "/etc/os-release") or platform.system()
    return f"{model}, {os.cpu_count()} cores, {memory}, {system}, CPython {platform.python_version()}"


def _load_note(run: Run) -> str:
    """The load the run's benchmarks started at, in words for the machine section."""
    if len(run.loads) == 1:
        (load,) = run.loads.values()
        loaded = "" if load <= IDLE_LOAD else ": not an idle machine's figures"
        return f"load average {load:.2f} at its start{loaded}"
    high = {name: load for name, load in run.loads.items() if load > IDLE_LOAD}
    if not high:
        return f"load average at most {IDLE_LOAD:g} at each benchmark's start"
    return ("load average above " + f"{IDLE_LOAD:g} at the start of " + ", ".join(
        f"{name} ({load:.2f})" for name, load in high.items()) + ": those figures are not an idle machine's")


#: A line of the machine section naming the ``--only`` runs made on one machine: each run's benchmark, date and load.
ONLY_LINE = re.compile(r"^- `--only` runs on (?P<machine>.+?): "
                       r"(?P<entries>`[^`]+` \S+ \([^)]*\)(?:, `[^`]+` \S+ \([^)]*\))*)\.$")
ONLY_ENTRY = re.compile(r"`(?P<name>[^`]+)` \S+ \([^)]*\)")


def _only_entry(name: str, date: str, load: float | None) -> str:
    """One ``--only`` run in the machine section: its benchmark, date and load average at its start."""
    if load is None:
        return f"`{name}` {date} (load not recorded)"
    return f"`{name}` {date} (load {load:.2f}{'' if load <= IDLE_LOAD else ', not idle'})"


def machine_section(old: str, run: Run) -> str:
    """The machine section's lines after ``run``.

    A full run rewrites them. An ``--only`` run's benchmarks join the line of the machine they ran on (one line per
    machine), replacing their earlier entries on any machine.
    """
    if run.full:
        return f"- Machine: {run.machine}.\n- All tables: {run.date}, {_load_note(run)}.\n"
    kept: list[str] = []
    machines: dict[str, list[str]] = {}
    for line in old.splitlines():
        if not line.strip() or any(line.startswith(f"- `--only {name}`") for name in run.entries):
            continue
        found = ONLY_LINE.match(line)
        if found is None:
            kept.append(line)
            continue
        entries = [m.group(0) for m in ONLY_ENTRY.finditer(found["entries"]) if m["name"] not in run.entries]
        if entries:
            machines.setdefault(found["machine"], []).extend(entries)
    here = "the machine above" if f"- Machine: {run.machine}." in kept else run.machine
    machines.setdefault(here, []).extend(_only_entry(name, run.date, run.loads.get(name)) for name in run.entries)
    kept.extend(f"- `--only` runs on {where}: {', '.join(entries)}." for where, entries in machines.items())
    return "\n".join(kept) + "\n"


def update_document(text: str, figures: list[Figure], ran: set[str], run: Run | None) -> str:
    """``text`` with its tables merged with ``figures`` and its machine section rewritten after ``run``.

    ``ran``: the benchmarks whose rows the figures replace. A table that no benchmark of the run wrote is left as
    it is; a component whose section is missing is appended at the end of the page under its heading.
    """
    for name in [*COMPONENTS, *sorted({f.component for f in figures} - set(COMPONENTS))]:
        new = [f for f in figures if f.component == name]
        text, span = _section(text, name, f"## {COMPONENTS.get(name, name)}\n\n" if new else None)
        if span is None:
            continue
        old = [line for line in text[span[0]:span[1]].splitlines() if row_script(line) is not None]
        if not new and not any(row_script(line) in ran for line in old):
            continue   # a table no benchmark of this run wrote: left as it is
        rows = merge_rows(old, new, ran)
        text = text[:span[0]] + "\n".join([HEAD, *rows]) + "\n" + text[span[1]:]
    if run is not None:
        text, span = _section(text, "machine", "")
        if span is not None:
            text = text[:span[0]] + machine_section(text[span[0]:span[1]], run) + text[span[1]:]
    return text


# ---- running ---------------------------------------------------------------------------------------------------------

def wait_quiet(settle: float) -> float:
    """Wait up to ``settle`` s for the 1-minute load average to fall to :data:`IDLE_LOAD`; the load then."""
    deadline = time.monotonic() + settle
    while (load := os.getloadavg()[0]) > IDLE_LOAD and time.monotonic() < deadline:
        time.sleep(5.0)
    return load


def run_bench(bench: Bench, figures_file: Path) -> bool:
    """Run one entry with ``RIMD_BENCH_FIGURES`` set to ``figures_file``; whether it succeeded."""
    env = dict(os.environ, **{_figures.ENV: str(figures_file)})
    if bench.script is not None:
        argv = [sys.executable, str(HERE / bench.script), *bench.args]
        print(f"\nreport: {' '.join(argv[1:])}", flush=True)
        return subprocess.run(argv, cwd=ROOT, env=env, stdin=subprocess.DEVNULL).returncode == 0
    for command in bench.commands:
        with tempfile.TemporaryDirectory(prefix="report_numba_") as cache:
            command_env = dict(env, NUMBA_CACHE_DIR=cache) if command.cold_cache else env
            print(f"\nreport: {' '.join(command.argv)}", flush=True)
            start = time.perf_counter()
            status = subprocess.run(command.argv, cwd=ROOT, env=command_env, stdin=subprocess.DEVNULL).returncode
            seconds = time.perf_counter() - start
        if status != 0:
            print(f"report: {' '.join(command.argv)} exited {status}", file=sys.stderr)
            return False
        previous = os.environ.get(_figures.ENV)
        os.environ[_figures.ENV] = str(figures_file)
        try:
            _figures.record(command.component, command.measure, seconds, "s", command.target)
        finally:
            if previous is None:
                del os.environ[_figures.ENV]
            else:
                os.environ[_figures.ENV] = previous
    return True


def select(only: str | None) -> list[Bench]:
    """The entries ``--only`` names (comma-separated), or every default one; an unknown name fails, naming all."""
    if only is None:
        return [b for b in BENCHES if b.default]
    names = [n.strip() for n in only.split(",") if n.strip()]
    known = {b.name: b for b in BENCHES}
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise SystemExit(f"report: --only {only!r}: unknown {', '.join(unknown) or 'empty'}; known: "
                         f"{', '.join(known)}")
    return [known[n] for n in names]


def _banner(message: str) -> None:
    line = "!" * 100
    print(f"{line}\n!! {message}\n{line}", file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=None, metavar="NAME[,NAME...]", help="these benchmarks only (--list)")
    parser.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    parser.add_argument("--force", action="store_true", help=f"run even with a load average above {IDLE_LOAD:g}")
    parser.add_argument("--settle", type=float, default=120.0,
                        help="s to wait before each benchmark for the load to fall back (default 120)")
    parser.add_argument("--figures", type=Path, default=None, help="keep the run's figures file here")
    parser.add_argument("--from", dest="source", type=Path, default=None, metavar="FIGURES",
                        help="write the tables from this figures file instead of running benchmarks")
    parser.add_argument("--doc", type=Path, default=DOC, help="the page to rewrite (default docs/benchmarks.md)")
    args = parser.parse_args(argv)
    if args.list:
        for bench in BENCHES:
            what = " ".join((bench.script, *bench.args)) if bench.script else bench.note
            print(f"{bench.name:<16} {what}{'' if bench.default else '   (only with --only)'}")
        return 0
    if args.source is not None:
        kept, kept_run = read_figures(args.source)
        args.doc.write_text(update_document(args.doc.read_text(), kept, {f.script for f in kept}, kept_run))
        print(f"report: {len(kept)} figures from {args.source} written into {args.doc}")
        return 0
    benches = select(args.only)
    if shutil.which("rimd") is None:
        raise SystemExit("report: `rimd` is not on PATH: run `source env.sh` first")
    load = os.getloadavg()[0]
    if load > IDLE_LOAD and not args.force:
        print(f"report: the load average is {load:.2f}, above {IDLE_LOAD:g}: the figures would be this load's, not "
              "the code's. Run it on an idle machine, or with --force to mark the figures as loaded.", file=sys.stderr)
        return 2
    if load > IDLE_LOAD:
        _banner(f"load average {load:.2f} > {IDLE_LOAD:g}: --force given, the figures will be marked as loaded")
    run = Run(datetime.now(UTC).date().isoformat(), machine(), [b.name for b in benches], args.only is None)
    keep = args.figures or Path(tempfile.mkstemp(prefix="rimd_figures_", suffix=".jsonl")[1])
    keep.write_text("")
    figures: list[Figure] = []
    ran: set[str] = set()
    failed = []
    for i, bench in enumerate(benches):
        run.loads[bench.name] = load if i == 0 else wait_quiet(args.settle)
        if run.loads[bench.name] > IDLE_LOAD:
            _banner(f"{bench.name} starts at load average {run.loads[bench.name]:.2f}")
        with tempfile.TemporaryDirectory(prefix="report_") as tmp:
            own = Path(tmp) / "figures.jsonl"
            own.touch()
            ok = run_bench(bench, own)
            got = [replace(f, script=bench.label) for f in read_figures(own)[0]]
        if not ok or not got:
            failed.append(bench.name)
            print(f"report: {bench.name} {'failed' if not ok else 'recorded no figure'}: its tables keep their rows",
                  file=sys.stderr)
            continue
        figures += got
        ran.add(bench.label)
        with keep.open("a", encoding="utf-8") as out:
            out.write(figure_lines(got))
    if failed:   # the machine section names what ran: a full run with a failure is a line per benchmark
        run.entries, run.full = [b.name for b in benches if b.name not in failed], False
    write_run(keep, run)
    args.doc.write_text(update_document(args.doc.read_text(), figures, ran, run))
    print(f"\nreport: {len(figures)} figures of {len(ran)} benchmark(s) written into {args.doc}; the figures file is "
          f"{keep}" + (f"; FAILED: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
