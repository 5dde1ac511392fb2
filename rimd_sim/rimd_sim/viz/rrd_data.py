"""Read back what an ``.rrd`` file holds on the ``sim_time`` timeline, as numpy arrays (rerun 0.41 chunk API).

Used by the tests (counts and times per entity) and by the layout rendering. Only temporal rows on
``sim_time`` are read; static rows (series names, colours) are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimd_sim.viz.rerun_map import TIMELINE
from rimd_sim.viz.sinks import require_rerun

__all__ = ["EntityData", "load_rrd"]


@dataclass
class EntityData:
    """Rows of one entity, sorted by time: ``times`` (int64 ns of sim time) and arrow list columns."""

    times: np.ndarray
    columns: dict[str, Any] = field(default_factory=dict)  # component -> pyarrow ListArray (one row each)

    def scalars(self, component: str = "Scalars:scalars") -> np.ndarray:
        """One float per row (Scalars, AnyValues numbers)."""
        return np.asarray(self.columns[component].flatten().to_numpy(zero_copy_only=False), dtype=np.float64)

    def points(self, component: str = "Points2D:positions") -> np.ndarray:
        """(n, 2) positions, all rows together."""
        flat = self.columns[component].flatten().flatten().to_numpy(zero_copy_only=False)
        return np.asarray(flat, dtype=np.float64).reshape(-1, 2)

    def strips(self, component: str = "LineStrips2D:strips") -> list[np.ndarray]:
        """One (k, 2) array per line strip, in time order."""
        out = []
        for row in self.columns[component].to_pylist():
            for strip in row or []:
                out.append(np.asarray(strip, dtype=np.float64).reshape(-1, 2))
        return out

    def texts(self, component: str = "TextLog:text") -> list[str]:
        """One string per row."""
        return [t for row in self.columns[component].to_pylist() for t in row]


def load_rrd(path: str | Path) -> dict[str, EntityData]:
    """Entity path (without the leading ``/``) -> its temporal rows on ``sim_time``."""
    require_rerun("reading .rrd files", "")
    import pyarrow as pa
    from rerun.chunk import RrdReader

    parts: dict[str, list[tuple[np.ndarray, dict[str, Any]]]] = {}
    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static or TIMELINE not in chunk.timeline_names:
            continue
        rb = chunk.to_record_batch()
        times = rb.column(TIMELINE).cast(pa.int64()).to_numpy()
        cols = {name: rb.column(name) for name in rb.schema.names
                if name not in (TIMELINE, "log_time", "rerun.controls.RowId")}
        parts.setdefault(chunk.entity_path.lstrip("/"), []).append((times, cols))
    result = {}
    for entity, chunks in parts.items():
        times = np.concatenate([t for t, _ in chunks])
        order = np.argsort(times, kind="stable")
        names = set().union(*(c.keys() for _, c in chunks))
        columns = {}
        for name in names:
            arrays = [c[name] for _, c in chunks if name in c]
            if len(arrays) == len(chunks):
                columns[name] = pa.concat_arrays(arrays).take(pa.array(order))
        result[entity] = EntityData(times[order], columns)
    return result
