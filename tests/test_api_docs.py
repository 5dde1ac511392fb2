"""docs/api.md: its examples run, and it documents every name ``rimd_sim.api`` exports.

Hypotheses:

* every ``python`` block of the page runs, in page order, in one namespace for the whole page (as the page says),
  in a temporary working directory, without an error or a failed ``assert``; the blocks fenced ``python process``
  (they start a local process pool) are skipped by the in-process test and run, with the whole page, by the test
  marked ``process``;
* a block that fails makes the test fail naming the page's line (the runner itself, on a made-up page);
* every name of ``rimd_sim.api.__all__`` appears on the page in a heading or in inline code, outside the code
  blocks, so the page cannot fall behind the module (and the check finds a missing name).
"""

from __future__ import annotations

import re
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "api.md"
FENCE = re.compile(r"^```python([^\n]*)\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
PROCESS = "process"


@dataclass(frozen=True)
class Block:
    """A ``python`` block of a page: its first line's number (1-based), its fence's words, its code."""

    line: int
    tags: tuple[str, ...]
    code: str


def blocks(text: str) -> list[Block]:
    """The page's ``python`` blocks, in order."""
    return [Block(text.count("\n", 0, m.start(2)) + 1, tuple(m.group(1).split()), m.group(2))
            for m in FENCE.finditer(text)]


def run_page(text: str, name: str, *, skip: tuple[str, ...] = ()) -> dict:
    """Run the page's blocks in order in one fresh module's namespace; returns the namespace.

    The module is registered in ``sys.modules`` while the page runs, so that a function the page defines pickles by
    name for a process pool or Dask (as a script's functions do). A block's traceback names the page and its line.
    """
    module = types.ModuleType(f"api_page_{abs(hash(name))}")
    sys.modules[module.__name__] = module
    try:
        for block in blocks(text):
            if set(block.tags) & set(skip):
                continue
            # Padded with blank lines, so the code's line numbers are the page's.
            code = compile("\n" * (block.line - 1) + block.code, name, "exec")
            exec(code, module.__dict__)  # noqa: S102 - the page's own examples
    finally:
        del sys.modules[module.__name__]
    return module.__dict__


def documented(text: str) -> set[str]:
    """The words in the page's headings and inline code (outside fenced blocks)."""
    prose = re.sub(r"^```.*?^```[ \t]*$", "", text, flags=re.MULTILINE | re.DOTALL)
    spans = re.findall(r"`([^`]+)`", prose) + re.findall(r"^#{1,6}\s+(.+)$", prose, flags=re.MULTILINE)
    return {word for span in spans for word in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", span)}


@pytest.fixture
def page_dir(tmp_path, monkeypatch):
    """A temporary working directory, and no Dask scheduler from the environment (the page runs locally)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("RIMD_DASK_SCHEDULER", raising=False)
    return tmp_path


def test_the_pages_examples_run_in_process(page_dir):
    text = PAGE.read_text()
    assert sum(PROCESS not in b.tags for b in blocks(text)) >= 12   # a parse that found nothing would pass
    namespace = run_page(text, str(PAGE.relative_to(ROOT)), skip=(PROCESS,))
    # The design study ran (inline and on Dask) and chose a 1/1 design.
    assert namespace["best"]["one_to_one"] and namespace["best_dask"] == namespace["best"]
    assert (page_dir / "band_a").is_dir() and (page_dir / "free_flight").is_dir()


@pytest.mark.process
def test_the_whole_page_runs_with_its_process_pool(page_dir):
    text = PAGE.read_text()
    assert any(PROCESS in b.tags for b in blocks(text))
    namespace = run_page(text, str(PAGE.relative_to(ROOT)))
    assert namespace["rows_pool"] == namespace["rows"]


def test_a_failing_example_fails_naming_the_pages_line(page_dir):
    text = "# Page\n\ntext\n\n```python\nx = 1\n```\n\nmore\n\n```python\nassert x == 2, 'x is not 2'\n```\n"
    assert [b.line for b in blocks(text)] == [6, 12]
    with pytest.raises(AssertionError, match="x is not 2") as failure:
        run_page(text, "made_up.md")
    assert any(entry.path == "made_up.md" and entry.lineno + 1 == 12 for entry in failure.traceback)
    # A block fenced "python process" is skipped when asked.
    assert run_page("```python process\nraise SystemExit\n```\n", "made_up.md", skip=(PROCESS,))["__name__"]


def test_every_exported_name_is_documented():
    import rimd_sim.api as api

    words = documented(PAGE.read_text())
    missing = sorted(set(api.__all__) - words)
    assert not missing, f"docs/api.md does not document (in a heading or in `code`): {', '.join(missing)}"
    assert len(api.__all__) == len(set(api.__all__)) and all(hasattr(api, name) for name in api.__all__)
    # The check finds a name the page lacks.
    assert "sweep" in words and "sweep" not in documented("# Page\n\n```python\nsweep()\n```\n")


@pytest.mark.process
def test_importing_rimd_sim_still_imports_nothing_else():
    import subprocess

    probe = "import sys, rimd_sim; print(sorted(m for m in sys.modules if m.startswith('rimd_sim')))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.strip() == "['rimd_sim']", out.stdout
