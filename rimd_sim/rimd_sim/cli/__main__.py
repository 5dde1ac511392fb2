"""``python -m rimd_sim.cli``: the ``rimd`` command (for a venv whose console script is not on PATH)."""

import sys

from rimd_sim.cli import entry

if __name__ == "__main__":
    sys.exit(entry())
