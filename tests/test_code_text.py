"""The code's comments, docstrings and strings say what it does, not its history.

A comment or docstring states the contract and the reason for it in the present tense; the history of a change,
an incident or a figure measured on some day belongs to docs/development.md's changelog and docs/benchmarks.md.
This scan reads every ``*.py`` of ``rimd_sim/`` and ``tests/`` and ``scripts/*.py`` and fails, naming
``path:line``, on the marks of a narrative: an ISO date, the adjective for what something once was (and its
adverb), a continuous-integration run quoted as the evidence, and a duration the code "was" (a number of ms or s).

The patterns are built from pieces (:data:`PATTERNS`), so that this file does not match itself.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: What the scan reads: (directory, glob) pairs, relative to the repository root.
SCANNED = (("rimd_sim", "**/*.py"), ("tests", "**/*.py"), ("scripts", "*.py"))
#: Build output and caches under the scanned directories: not the project's text.
SKIPPED_DIRS = {"build", "dist", "__pycache__", ".eggs"}

#: Each mark of a narrative, by name.
PATTERNS = {
    "date": re.compile(r"\b20\d\d" + "-" + r"\d\d" + "-" + r"\d\d\b"),
    "history word": re.compile(r"\b" + "form" + r"er(?:ly)?\b", re.IGNORECASE),
    "CI run": re.compile(r"\ba " + "C" + r"I run\b", re.IGNORECASE),
    "old duration": re.compile(r"\bw" + r"as \d+(?:\.\d+)? ?(?:ms|s|us|µs)\b"),
}

#: Paths the scan leaves out (a path ending in "/" stands for everything under it): none.
ALLOWED: set[str] = set()


def scanned_files(root: Path = ROOT) -> list[Path]:
    """Every file the scan reads under ``root``, sorted."""
    files: set[Path] = set()
    for folder, pattern in SCANNED:
        for path in (root / folder).glob(pattern):
            if path.is_file() and not SKIPPED_DIRS.intersection(path.relative_to(root).parts):
                files.add(path)
    return sorted(files)


def is_allowed(relative: str, allowed: set[str] = ALLOWED) -> bool:
    """Whether ``relative`` (a POSIX path from the root) is one of ``allowed`` or under one ending in "/"."""
    return any(relative == a or (a.endswith("/") and relative.startswith(a)) for a in allowed)


def offending_lines(root: Path = ROOT, allowed: set[str] = ALLOWED) -> list[str]:
    """``path:line: [mark] text`` of every line that carries a mark of a narrative, outside ``allowed``."""
    out = []
    for path in scanned_files(root):
        relative = path.relative_to(root).as_posix()
        if is_allowed(relative, allowed):
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for name, pattern in PATTERNS.items():
                if pattern.search(line):
                    out.append(f"{relative}:{n}: [{name}] {line.strip()}")
    return out


def test_comments_and_docstrings_state_the_contract_not_the_history():
    found = offending_lines()
    assert found == [], "say what the code does and why, in the present tense:\n" + "\n".join(found)


def test_the_scan_finds_each_mark_and_names_file_and_line(tmp_path):
    date = "20" + "31-02" + "-14"
    planted = ("x = 1\n"
               f"# changed on {date}\n"
               "# the " + "form" + "er rule\n"
               "y = 2  # seen in a " + "C" + "I run\n"
               '"""The pass w' + 'as 12 ms, now less."""\n'
               "# transformer, performer, was 12 people, waste 3 s: no mark\n")
    (tmp_path / "rimd_sim" / "pkg").mkdir(parents=True)
    (tmp_path / "rimd_sim" / "pkg" / "mod.py").write_text(planted)
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_x.py").write_text("# " + "Form" + "erly a test\n")
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "tool.py").write_text("# a pin w" + "as 0.5 s\n")
    (tmp_path / "rimd_sim" / "build").mkdir()
    (tmp_path / "rimd_sim" / "build" / "copy.py").write_text(planted)   # build output: not read
    found = offending_lines(tmp_path, allowed=set())
    assert [line.split(": ", 1)[0] for line in found] == [
        "rimd_sim/pkg/mod.py:2", "rimd_sim/pkg/mod.py:3", "rimd_sim/pkg/mod.py:4", "rimd_sim/pkg/mod.py:5",
        "scripts/tool.py:1", "tests/test_x.py:1"], found
    assert [line.split("[", 1)[1].split("]", 1)[0] for line in found] == [
        "date", "history word", "CI run", "old duration", "old duration", "history word"]
    # an allowed file, or everything under an allowed directory, is left out
    assert offending_lines(tmp_path, allowed={"rimd_sim/pkg/", "scripts/tool.py"}) == found[-1:]
