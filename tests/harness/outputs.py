"""Reading the product's output files as their independent users would."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def _refuse(token: str) -> None:
    raise ValueError(f"not JSON: the bare token {token} (JSON has no NaN or infinity; the product writes null)")


def read_json(path: Path) -> Any:  # any JSON document
    """The JSON document at ``path``, parsed strictly: ``NaN``, ``Infinity`` and ``-Infinity`` are refused.

    Python's ``json`` reads those tokens, but jq, browsers and most other readers do not, so every test that
    reads a summary, schedule or report the product wrote reads it through this.
    """
    return json.loads(Path(path).read_text(), parse_constant=_refuse)
