"""Files the analyses write: CSV tables, strict JSON, and parameter files built from a base file.

Library code (no verb, no ROS): ``rimd analyze``, ``rimd identify``, ``rimd fit-table`` and the other analysis
verbs write through these.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rimd_sim.settings.config import SimConfig

from rimd_sim.errors import InputError
from rimd_sim.settings.yaml_file import read_yaml

__all__ = ["FileFormatError", "jsonable", "nest", "rows_of", "write_columns", "write_csv", "write_json",
           "write_parameter_file", "write_summary"]


class FileFormatError(InputError):
    """A file the analyses read is not what it must be (one line: the file, line and column, what is wrong)."""


def write_csv(path: Path, rows: list[dict]) -> None:
    """Write ``rows`` (dicts with the same keys) as CSV with a header."""
    with open(path, "w", newline="") as fh:
        if not rows:
            return
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def write_columns(path: Path, columns: Mapping[str, Sequence]) -> None:
    """Write a table given column by column (name: values, all of one length) as CSV with a header.

    The bytes :func:`write_csv` writes for the same rows (the ``csv`` module's ``excel`` dialect, each value as
    ``str`` gives it), in time linear in the cells and without a dict per row: the writer of the maps' tables
    (a 200 x 200 map is 40,000 rows). Give Python values (``ndarray.tolist()``): a NumPy scalar's ``str`` may
    differ from its Python value's. An empty table (no column) is an empty file.
    """
    with open(path, "w", newline="") as fh:
        if not columns:
            return
        writer = csv.writer(fh)
        writer.writerow(list(columns))
        writer.writerows(zip(*columns.values(), strict=True))


def rows_of(columns: Mapping[str, Sequence]) -> list[dict]:
    """The rows (one dict per row, keys in column order) of a table given column by column."""
    names = list(columns)
    return [dict(zip(names, values, strict=True)) for values in zip(*columns.values(), strict=True)]


def jsonable(value: Any) -> Any:
    """``value`` as strict JSON data: NumPy scalars as Python numbers, tuples as lists, NaN and ±inf as null.

    JSON has no NaN or infinity; Python's ``json`` would write the bare tokens ``NaN`` and ``Infinity``,
    which jq, browsers and most JSON libraries refuse. A value that does not exist (the peak of a capture with
    no sample, the phase of a step with no impact) is ``null``.
    """
    import numpy as np

    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` to ``path`` as strict JSON (:func:`jsonable`), indented, with a final newline."""
    path.write_text(json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")


def write_summary(out: Path, summary: dict) -> None:
    """Write ``out/summary.json`` (strict JSON: :func:`jsonable`)."""
    write_json(out / "summary.json", summary)


def nest(flat: dict) -> dict:
    """Dotted parameter names to nested mappings."""
    tree: dict = {}
    for key, value in flat.items():
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return tree


def write_parameter_file(path: Path, base_path: Path, config: SimConfig, header: str) -> None:
    """The base file with the simulator's section replaced by every value of ``config``.

    The section is written as ``/**/rimd_simulator``: the node runs in namespace ``/rig`` and ROS applies a
    section only to the fully qualified name or a wildcard (a plain ``rimd_simulator:`` key means
    ``/rimd_simulator``, which the node is not); the core reads the same section.

    Raises:
        FileFormatError: The base file is not a YAML mapping (the file, line and column).
    """
    import yaml

    from rimd_sim.settings.config import NODE_NAME

    doc = read_yaml(base_path, what="parameter file") or {}
    if not isinstance(doc, dict):
        raise FileFormatError(f"{base_path} line 1 column 1: a parameter file must be a mapping of node names, "
                              f"not {type(doc).__name__}")
    for section in (NODE_NAME, "/" + NODE_NAME, "/**/" + NODE_NAME):
        doc.pop(section, None)
    wildcard = doc.pop("/**", None)   # its simulator values are in the new section; other nodes keep it
    if wildcard is not None:
        doc["/**"] = wildcard
    doc["/**/" + NODE_NAME] = {"ros__parameters": nest(config.to_parameters())}
    path.write_text(header + yaml.safe_dump(doc, sort_keys=False))
