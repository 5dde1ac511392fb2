#!/usr/bin/env python3
"""Write the tables of the documentation that restate the code, from the code.

Every parameter table (name, default, type, rule, description) and every ``rimd`` verb's options table
(option, default, help) in ``README.md`` and ``docs/*.md`` is generated here from its single source:

- the simulator's parameters: ``rimd_sim.settings.config.PARAMETERS`` (type, rule, description) and
  ``SimConfig().to_parameters()`` (defaults);
- the recorder's: ``rimd_sim.settings.recording.PARAMETERS`` (and the rules that module checks);
- the replay's: ``rimd_sim.runtime.replay.ReplaySettings``;
- the Rerun bridge's: ``rimd_sim.viz.bridge_settings.PARAMETERS``;
- the verbs: ``rimd_sim.cli.VERBS`` and each verb's argparse parser (``add_arguments``);
- the packages a ROS 2 install takes from pip: ``rimd_sim.dependencies`` (the rows without a rosdep key).

A generated section sits between two markers in a page::

    <!-- BEGIN GENERATED: NAME -->
    ...
    <!-- END GENERATED: NAME -->

Usage (in the project environment, ``source env.sh``)::

    python scripts/gen_docs.py           # rewrite the generated sections of the pages
    python scripts/gen_docs.py --check   # exit 1, naming each page and section that differs from the code

Everything outside the markers is left as written. A section missing from its page is appended at the end of
that page by a rewrite (move it where it belongs); ``--check`` reports it. ``tests/test_docs.py`` runs the check.
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "rimd_sim") not in sys.path:  # rimd_sim from this checkout, also without env.sh's PYTHONPATH
    sys.path.insert(0, str(ROOT / "rimd_sim"))

BEGIN = "<!-- BEGIN GENERATED: {name} -->"
END = "<!-- END GENERATED: {name} -->"
MARKER = re.compile(r"^<!-- (BEGIN|END) GENERATED: ([\w.-]+) -->[ \t]*$", re.MULTILINE)  # a marker is a line

#: The guide that explains each verb (the CLI reference, docs/cli.md, links each verb's table to it).
VERB_GUIDES = {
    "rig": "docs/rig.md",
    "node": "docs/rig.md",
    "rerun": "docs/rerun.md",
    "sweep": "docs/analyses.md",
    "bifurcation": "docs/analyses.md",
    "poincare": "docs/analyses.md",
    "continue": "docs/analyses.md",
    "peterka": "docs/analyses.md",
    "basins": "docs/analyses.md",
    "map": "docs/analyses.md",
    "experiment": "docs/analyses.md",
    "analyze": "docs/analyses.md",
    "identify": "docs/identification.md",
    "fit-table": "docs/identification.md",
    "fit-paper": "docs/validation.md",
    "paper": "docs/validation.md",
    "pulse": "docs/physics.md",
    "info": "docs/development.md",
    "warmup": "docs/development.md",
    "faults": "docs/faults.md",
    "crop": "docs/recording.md",
    "replay": "docs/recording.md",
    **{verb: "docs/rig.md" for verb in ("motor", "perturb", "inject", "pause", "resume", "reset", "clear-faults",
                                         "status")},
}
#: The guide of a verb that is not in VERB_GUIDES.
DEFAULT_VERB_GUIDE = "docs/analyses.md"
#: The page that holds every verb's options table and the overview of the verbs.
CLI_PAGE = "docs/cli.md"


@dataclass(frozen=True)
class Section:
    """One generated section: its marker name, the page it lives in and the function that writes it."""

    name: str
    page: str
    render: Callable[[], str]
    title: str = ""  # heading used when a rewrite has to append the section to its page


# ------------------------------------------------------------------------------------------------------------
# Formatting
# ------------------------------------------------------------------------------------------------------------


#: The end of a text's first sentence: a period and a capital, not after "e.g." or "i.e.".
SENTENCE_END = re.compile(r"(?<!e\.g)(?<!i\.e)\.\s+(?=[A-Z`])")


def _cell(text: Any) -> str:
    """A Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _value(value: Any) -> str:
    """A default as it is written in a ROS parameter YAML file (or on a command line), in backticks."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = repr(value) if math.isfinite(value) else str(value)
    elif isinstance(value, (list, tuple)):
        text = json.dumps(list(value))
    elif isinstance(value, Path):
        text = str(value)
    elif isinstance(value, str):
        text = json.dumps(value) if value == "" or value != value.strip() else value
    else:
        text = str(value)
    return f"`{_cell(text)}`"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _first_sentence(text: str) -> str:
    """A description cut to its first sentence: the tables index; the declaration keeps the whole text."""
    return SENTENCE_END.split(text, maxsplit=1)[0]


def _type_name(value: Any) -> str:
    return {bool: "bool", int: "int", float: "float", str: "str", list: "string list"}.get(type(value),
                                                                                        type(value).__name__)


# ------------------------------------------------------------------------------------------------------------
# Parameter tables
# ------------------------------------------------------------------------------------------------------------


def parameter_table(table: Mapping[str, Any], *, skip: Callable[[str], bool] = lambda name: False) -> str:
    """A node's parameters as a table, from their one declaration (rimd_sim.settings.params.Param)."""
    rows = [[f"`{name}`", _value(p.default), _cell(p.kind), _cell(p.unit or "—"), _cell(p.rule),
             _cell(_first_sentence(p.description) + (" (read at start)" if p.read_only else ""))]
            for name, p in table.items() if not skip(name)]
    return _table(["parameter", "default", "type", "unit", "rule", "description"], rows)


def render_parameters() -> str:
    """The simulator's parameters other than the channels'."""
    from rimd_sim.settings.config import PARAMETERS

    return parameter_table(PARAMETERS, skip=lambda name: _channel_key(name) is not None)


def _channel_key(name: str) -> tuple[str, str] | None:
    parts = name.split(".")
    if len(parts) == 3 and parts[0] == "channels":
        return parts[1], parts[2]
    return None


def render_channel_parameters() -> str:
    """The channels' parameters: one row per field, the default of each channel in its own column."""
    from rimd_sim.settings.config import PARAMETERS as specs

    channels: list[str] = []
    fields: dict[str, Any] = {}
    for name, spec in specs.items():
        key = _channel_key(name)
        if key is None:
            continue
        channel, field = key
        if channel not in channels:
            channels.append(channel)
        fields.setdefault(field, spec)
    rows = []
    for field, spec in fields.items():
        row = [f"`channels.<name>.{field}`", _cell(spec.kind), _cell(spec.unit or "—"), _cell(spec.rule),
               _cell(_first_sentence(spec.description))]
        for channel in channels:
            full = f"channels.{channel}.{field}"
            row.append(_value(specs[full].default) if full in specs else "—")
        rows.append(row)
    return _table(["parameter", "type", "unit", "rule", "description", *(f"`{c}`" for c in channels)], rows)


def render_node_parameters() -> str:
    """The simulator node's own parameters: start, fault scenario, capture, lockstep (read at start)."""
    from rimd_sim.settings.config import NODE_PARAMETERS

    return parameter_table(NODE_PARAMETERS)


def render_recorder_parameters() -> str:
    """The recorder's parameters (rimd_sim.settings.recording)."""
    from rimd_sim.settings.recording import PARAMETERS

    return parameter_table(PARAMETERS)


def render_replay_parameters() -> str:
    """The replay's parameters (rimd_sim.runtime.replay.ReplaySettings)."""
    from rimd_sim.runtime.replay import ReplaySettings
    from rimd_sim.settings.params import parameters

    return parameter_table(parameters(ReplaySettings))


def render_rerun_parameters() -> str:
    """The Rerun bridge's parameters (rimd_sim.viz.bridge_settings)."""
    from rimd_sim.viz.bridge_settings import PARAMETERS

    return parameter_table(PARAMETERS)


def render_pip_only() -> str:
    """The pip-only packages of a ROS 2 install (rimd_sim.dependencies), and the pip command of the base ones."""
    from rimd_sim import dependencies

    rows = dependencies.pip_only()
    lines = ["| pip requirement | module | installed for | what needs it |", "|---|---|---|---|"]
    for row in rows:
        what = f"the extra `{row.extra}`" if row.extra else "every command"
        lines.append(f"| `{row.requirement}` | `{row.module}` | {what} | {row.why} |")
    base = " ".join(f"'{row.requirement}'" for row in rows if row.extra is None)
    lines += ["", "```bash", f"python -m pip install -c constraints.txt {base}", "```"]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------------------
# Verb tables
# ------------------------------------------------------------------------------------------------------------


def _verb_parsers() -> dict[str, argparse.ArgumentParser]:
    from rimd_sim import cli

    parser = cli.build_parser()
    for action in parser._actions:  # argparse keeps sub-parsers there only
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_name(action: argparse.Action) -> str:
    if action.option_strings:
        name = ", ".join(action.option_strings)
        if action.nargs == 0:
            return f"`{name}`"
        if action.choices is not None:
            metavar = "{" + ",".join(map(str, action.choices)) + "}"
        else:
            metavar = action.metavar if isinstance(action.metavar, str) else action.dest.upper()
        if action.nargs in ("+", "*"):
            metavar = f"{metavar} ..."
        return f"`{name} {metavar}`"
    name = action.metavar if isinstance(action.metavar, str) else action.dest
    if action.choices is not None:
        name = "{" + ",".join(map(str, action.choices)) + "}"
    if action.nargs == argparse.REMAINDER:
        name = f"{name} ..."
    return f"`{name}`"


def _option_default(action: argparse.Action) -> str:
    if not action.option_strings:
        return "(optional)" if action.nargs in ("?", "*", argparse.REMAINDER) else "(required)"
    if action.nargs == 0:
        return "off" if action.default in (False, None) else _value(action.default)
    if action.required:
        return "(required)"
    return _value(action.default)


#: A help text's ", default X" or " (default X)", removed when X is the default column's value.
DEFAULT_NOTE = re.compile(r" \(default:? ([^()\s]+)\)|, default ([^,;()\s]+)(?=[,;]|$)")


def _option_help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The option's help as ``--help`` expands it, cut to its first sentence.

    The table indexes the options; ``rimd VERB --help`` gives each one's whole text.
    """
    formatter = parser._get_formatter()  # expands %(default)s and friends like --help does
    text = formatter._expand_help(action) if action.help else ""
    text = _first_sentence(text)
    shown = str(action.default)
    text = DEFAULT_NOTE.sub(lambda m: "" if shown in (m.group(1), m.group(2)) else m.group(0), text)
    for group in parser._mutually_exclusive_groups:
        if action in group._group_actions:
            others = [o.option_strings[0] for o in group._group_actions if o is not action and o.option_strings]
            if others:
                text += f" (not with {', '.join(others)})"
    return _cell(text)


def render_verb(name: str) -> str:
    """The options table of ``rimd NAME``, from its parser."""
    parser = _verb_parsers()[name]
    rows = [[_option_name(a), _option_default(a), _option_help(parser, a)]
            for a in parser._actions
            if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)]
    return _table(["option", "default", "help"], rows)


def render_validation_table() -> str:
    """docs/validation.md's table of findings, from docs/validation/validation.csv (what `rimd paper` wrote)."""
    import csv

    with open(ROOT / "docs" / "validation" / "validation.csv", newline="") as fh:
        checks = list(csv.DictReader(fh))
    passed = sum(c["passed"] == "True" for c in checks)
    rows = [[_cell(c["finding"]), _cell(c["source"]),
             _cell(f"{c['paper']} {c['unit']}".strip() if c["paper"].replace(".", "", 1).isdigit() else c["paper"]),
             _cell(f"{c['twin']} {c['unit']}".strip() if c["twin"] not in ("", "None") else "-"),
             _cell(c["tolerance"]), "pass" if c["passed"] == "True" else "**FAIL**", _cell(c["detail"])]
            for c in checks]
    return (f"**{passed} of {len(checks)} findings reproduced** by the default configuration.\n\n"
            + _table(["finding", "source", "paper", "twin", "tolerance", "result", "how"], rows))


def render_presets() -> str:
    """docs/configuration.md's table of what each preset reproduces.

    From docs/validation/presets.csv, which scripts/validate_presets.py writes.
    """
    import csv

    with open(ROOT / "docs" / "validation" / "presets.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    presets = list(dict.fromkeys(r["preset"] for r in table))
    findings = list(dict.fromkeys((r["key"], r["finding"], r["paper"], r["unit"]) for r in table))
    cell = {(r["preset"], r["key"]): r for r in table}
    rows = []
    for key, finding, paper, unit in findings:
        numeric = paper.replace(".", "", 1).isdigit()
        row = [_cell(finding), _cell(f"{paper} {unit}".strip() if numeric else paper)]
        for p in presets:
            r = cell.get((p, key))
            twin = "-" if r is None or r["twin"] in ("", "None") else f"{r['twin']} {unit}".strip()
            row.append(_cell(twin + (" (pass)" if r is not None and r["passed"] == "True" else " (**fail**)")))
        rows.append(row)
    passed = [sum(cell[(p, k)]["passed"] == "True" for k, *_ in findings if (p, k) in cell) for p in presets]
    rows.append(["**findings reproduced**", "", *[f"**{n} of {len(findings)}**" for n in passed]])
    return _table(["finding", "paper", *[f"`{p}`" for p in presets]], rows)


def render_verbs() -> str:
    """The overview of the verbs (``rimd_sim.cli.VERBS``) with the page that documents each."""
    from rimd_sim import cli

    rows = []
    by_module: dict[str, list[str]] = {}
    for verb in cli.VERBS:
        page = VERB_GUIDES.get(verb.name, DEFAULT_VERB_GUIDE)
        status = "" if verb.module else " (not implemented yet)"
        if verb.module and verb.module in by_module:   # verbs of one module (pause, resume...) share a row
            by_module[verb.module].append(verb.name)
            continue
        if verb.module:
            by_module[verb.module] = [verb.name]
        rows.append([verb.module or verb.name, _cell(verb.summary + status), f"[{Path(page).stem}]({Path(page).name})"])
    for row in rows:
        names = by_module.get(row[0], [row[0]])
        row[0] = " ".join(f"[`rimd {n}`](#rimd-{n})" for n in names)
        if len(names) > 1:
            row[1] = _cell("the rig's services " + ", ".join(n.replace("-", " ") for n in names) + ", in one line each")
    return _table(["command", "what it does", "guide"], rows)


# ------------------------------------------------------------------------------------------------------------
# Sections and pages
# ------------------------------------------------------------------------------------------------------------


def sections() -> list[Section]:
    """Every generated section, in the order of the pages."""
    from rimd_sim import cli

    out = [
        Section("verbs", CLI_PAGE, render_verbs, "The verbs"),
        Section("parameters", "docs/configuration.md", render_parameters, "Parameters"),
        Section("channel-parameters", "docs/configuration.md", render_channel_parameters, "Channel parameters"),
        Section("recorder-parameters", "docs/recording.md", render_recorder_parameters, "Recorder parameters"),
        Section("replay-parameters", "docs/recording.md", render_replay_parameters, "Replay parameters"),
        Section("rerun-parameters", "docs/rerun.md", render_rerun_parameters, "Rerun bridge parameters"),
        Section("node-parameters", "docs/configuration.md", render_node_parameters, "Simulator node parameters"),
        Section("pip-only", "docs/ros-install.md", render_pip_only, "The pip-only packages"),
        Section("validation-table", "docs/validation.md", render_validation_table, "The findings"),
        Section("presets", "docs/configuration.md", render_presets, "Presets"),
    ]
    for verb in cli.VERBS:
        if verb.module is None:
            continue
        out.append(Section(f"verb-{verb.name}", CLI_PAGE, lambda name=verb.name: render_verb(name),
                           f"rimd {verb.name}"))
    return out


def _find(text: str, name: str) -> tuple[int, int] | None:
    """Start and end offsets of section ``name``'s content (between its markers), or None."""
    begin, end = BEGIN.format(name=name), END.format(name=name)
    first = re.search(rf"^{re.escape(begin)}[ \t]*$", text, re.MULTILINE)
    if first is None:
        return None
    last = re.compile(rf"^{re.escape(end)}[ \t]*$", re.MULTILINE).search(text, first.end())
    if last is None:
        raise ValueError(f"'{begin}' has no '{end}' line after it")
    return first.end(), last.start()


def _block(content: str) -> str:
    return "\n" + content.strip("\n") + "\n"


@dataclass
class Problem:
    """A page that does not say what the code says."""

    page: str
    section: str
    what: str
    diff: str = ""

    def __str__(self) -> str:
        """The page, the section, what is wrong, and the difference if any."""
        text = f"{self.page}: section '{self.section}' {self.what}"
        return text + ("\n" + self.diff if self.diff else "")


def run(root: Path = ROOT, *, check: bool = False) -> list[Problem]:
    """Rewrite (or, with ``check``, compare) the generated sections of the pages under ``root``.

    Returns the problems: with ``check``, every section that differs from the code or is missing, and every
    marker naming an unknown section; when rewriting, only what could not be written (unknown markers,
    a BEGIN without its END).
    """
    problems: list[Problem] = []
    wanted = sections()
    pages: dict[str, list[Section]] = {}
    for section in wanted:
        pages.setdefault(section.page, []).append(section)
    known = {s.name for s in wanted}
    page_files = sorted({*pages, "README.md", *(p.relative_to(root).as_posix() for p in (root / "docs").glob("*.md"))})
    for page in page_files:
        path = root / page
        text = path.read_text() if path.exists() else ""
        original = text
        for match in MARKER.finditer(text):
            if match.group(2) not in known:
                problems.append(Problem(page, match.group(2), "is not generated by scripts/gen_docs.py "
                                        "(unknown section: remove its markers)"))
        for section in pages.get(page, []):
            content = _block(section.render())
            try:
                span = _find(text, section.name)
            except ValueError as exc:
                problems.append(Problem(page, section.name, f"is broken: {exc}"))
                continue
            if span is None:
                if check:
                    problems.append(Problem(page, section.name, "is missing (run python scripts/gen_docs.py)"))
                else:
                    heading = f"\n## {section.title}\n\n" if section.title else "\n"
                    text = (text.rstrip("\n") + "\n" + heading + BEGIN.format(name=section.name) + content
                            + END.format(name=section.name) + "\n")
                    print(f"gen_docs: appended section '{section.name}' at the end of {page}: move it where it "
                          "belongs", file=sys.stderr)
                continue
            current = text[span[0]:span[1]]
            if current != content:
                if check:
                    diff = "".join(difflib.unified_diff(
                        current.splitlines(keepends=True), content.splitlines(keepends=True),
                        f"{page} ({section.name}, written)", f"{page} ({section.name}, from the code)", n=0))
                    problems.append(Problem(page, section.name, "differs from the code "
                                            "(run python scripts/gen_docs.py)", diff))
                else:
                    text = text[:span[0]] + content + text[span[1]:]
        if not check and text != original:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            print(f"gen_docs: wrote {page}", file=sys.stderr)
    return problems


def main(argv: list[str] | None = None) -> int:
    """Command line: rewrite the pages, or check them with ``--check``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="change nothing; exit 1 naming each page and section that differs from the code")
    parser.add_argument("--root", type=Path, default=ROOT, help="repository root (default: this checkout)")
    args = parser.parse_args(argv)
    problems = run(args.root, check=args.check)
    for problem in problems:
        print(f"gen_docs: {problem}", file=sys.stderr)
    if args.check and not problems:
        print("gen_docs: every generated section agrees with the code", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
