"""The ground truth of a run, from its recording, for a window of time: what a DAQ test checks its software against.

:class:`RunTruth` reads a recording (a file or a recording directory, finished or still being written) and gives
its impact events, injected faults, motor states and channels' samples between two times, as tables of numpy
columns (:class:`Table`). Times are the messages' stamps in seconds: on a rig whose stamps are simulation time (the
``rimd_rig`` fixture's, in lockstep; any rig not at real time) they are the run's simulation time, from 0.

An impact event's ``time`` is its contact start. A fault is one row from its start to its end (``end`` is ``inf``
while it lasts: a fault of duration 0, or one whose end is not recorded yet). A channel's ``time`` is each
sample's time, ``index`` its running number since the run started (a hole in ``index`` is a lost sample).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from rimd_sim.analysis.recordings import recorded
from rimd_sim.errors import InputError

__all__ = ["CHANNEL_TOPICS", "EVENT_COLUMNS", "FAULT_COLUMNS", "MOTOR_COLUMNS", "Faults", "RunTruth", "Table"]

#: The channels by name (as in the configuration and the fault scenarios) and their topics.
CHANNEL_TOPICS = {"cart_displacement": recorded.CART_X, "rimd_displacement": recorded.RIMD_X,
                  "rimd_acceleration": recorded.ACC, "impact_force": recorded.FORCE}
#: The columns of each table, in order.
EVENT_COLUMNS = ("time", "duration", "peak_force", "impulse", "impact_velocity", "max_penetration",
                 "excitation_frequency", "excitation_phase", "cycle_index", "index")
MOTOR_COLUMNS = ("time", "frequency_setpoint", "frequency", "phase", "cycle_index")
FAULT_COLUMNS = ("id", "channel", "kind", "start", "end", "magnitude", "detail")


class Table(Mapping[str, np.ndarray]):
    """Columns of equal length by name: ``table["peak_force"]`` or ``table.peak_force``; ``len(table)`` rows."""

    def __init__(self, columns: Mapping[str, np.ndarray]) -> None:
        self._columns = {name: np.asarray(values) for name, values in columns.items()}
        sizes = {v.shape[0] for v in self._columns.values()}
        if len(sizes) > 1:
            raise ValueError(f"columns of different lengths: {sorted(sizes)}")
        self._rows = sizes.pop() if sizes else 0

    def __getitem__(self, name: str) -> np.ndarray:
        """The column ``name``."""
        return self._columns[name]

    def __getattr__(self, name: str) -> np.ndarray:
        """The column ``name``, as an attribute."""
        columns = self.__dict__.get("_columns", {})
        if name in columns:
            return columns[name]
        raise AttributeError(f"no column {name!r} (columns: {', '.join(columns)})")

    def __iter__(self) -> Iterator[str]:
        """The column names."""
        return iter(self._columns)

    def __len__(self) -> int:
        """The number of rows."""
        return self._rows

    def rows(self) -> list[dict]:
        """The rows as dicts (column -> Python value)."""
        return [{k: v[i].item() if hasattr(v[i], "item") else v[i] for k, v in self._columns.items()}
                for i in range(self._rows)]

    def where(self, mask: np.ndarray) -> Table:
        """The rows where ``mask`` is true."""
        return type(self)({k: v[mask] for k, v in self._columns.items()})

    def __repr__(self) -> str:
        """The number of rows and the column names."""
        return f"{type(self).__name__}({self._rows} rows: {', '.join(self._columns)})"


class Faults(Table):
    """Injected faults, one row each (:data:`FAULT_COLUMNS`)."""

    def active(self, times: np.ndarray, channel: str | None = None, kind: str | None = None) -> np.ndarray:
        """Whether a fault (of ``channel`` and ``kind``, when given) acts at each of ``times`` (start <= t < end)."""
        t = np.asarray(times, dtype=float)
        mask = np.zeros(t.shape, dtype=bool)
        for row in self.rows():
            if (channel is None or row["channel"] == channel) and (kind is None or row["kind"] == kind):
                mask |= (t >= row["start"]) & (t < row["end"])
        return mask


def _seconds(times: np.ndarray, offset: float) -> np.ndarray:
    """Times from the origin plus ``offset``, rounded as the stamps' nanoseconds divide into seconds.

    So 0.6, not 0.6000000000000001: a window's bounds and a fault's start compare with them as written.
    """
    return np.round((np.asarray(times, dtype=float) + offset) * 1e9) / 1e9


def _window(times: np.ndarray, start: float, end: float) -> np.ndarray:
    return (times >= start) & (times < end)


class RunTruth:
    """The ground truth a recording holds (see the module docstring).

    Args:
        path: A recording directory or MCAP file; one still being written reads up to its last complete chunk.

    Raises:
        rimd_sim.io.reader.RecordingError: The path does not exist or is not MCAP.
    """

    def __init__(self, path: str | Path) -> None:
        self.data = recorded.load(path)
        self._offset = self.data.origin_ns * 1e-9   # the tables' times count from stamp 0, not from the origin

    @property
    def covered_until(self) -> float:
        """The time up to which every recorded channel holds its samples (s; -inf: none recorded yet)."""
        ends = [float(_seconds(c.time[-1] + 1.0 / c.rate, self._offset)) for c in self.data.channels.values()
                if c.time.size]
        return min(ends) if ends else -math.inf

    def events(self, start: float = 0.0, end: float = math.inf) -> Table:
        """The impact events whose contact starts in ``[start, end)`` (:data:`EVENT_COLUMNS`)."""
        cols = {name: self.data.events.get(name, np.zeros(0)) for name in EVENT_COLUMNS}
        cols["time"] = _seconds(cols["time"], self._offset)
        for name in ("cycle_index", "index"):
            cols[name] = cols[name].astype(np.int64)
        return Table(cols).where(_window(cols["time"], start, end))

    def motor_states(self, start: float = 0.0, end: float = math.inf) -> Table:
        """The motor states stamped in ``[start, end)`` (:data:`MOTOR_COLUMNS`)."""
        cols = {name: self.data.motor.get(name, np.zeros(0)) for name in MOTOR_COLUMNS}
        cols["time"] = _seconds(cols["time"], self._offset)
        cols["cycle_index"] = cols["cycle_index"].astype(np.int64)
        return Table(cols).where(_window(cols["time"], start, end))

    def faults(self, start: float = 0.0, end: float = math.inf) -> Faults:
        """The faults acting at some time of ``[start, end)``, one row each (:data:`FAULT_COLUMNS`)."""
        rows: dict[int, dict] = {}
        for e in self.data.fault_events:
            t = float(_seconds(e["time"], self._offset))
            row = rows.setdefault(int(e["id"]), {"id": int(e["id"]), "channel": e["channel"], "kind": e["kind"],
                                                 "start": t, "end": math.inf, "magnitude": float(e["magnitude"]),
                                                 "detail": e["detail"]})
            if e["event"] == "end":
                row["end"] = t
            else:
                row.update(start=t, detail=e["detail"])
        kept = [r for r in rows.values() if r["start"] < end and r["end"] > start]
        kept.sort(key=lambda r: (r["start"], r["id"]))
        cols = {name: np.array([r[name] for r in kept],
                               dtype=object if name in ("channel", "kind", "detail") else
                               np.int64 if name == "id" else float)
                for name in FAULT_COLUMNS}
        return Faults(cols)

    def channel(self, name: str, start: float = 0.0, end: float = math.inf) -> Table:
        """A channel's samples in ``[start, end)``: ``time`` (s), ``index`` and ``value`` (its unit).

        Args:
            name: The channel (:data:`CHANNEL_TOPICS`: ``impact_force``...) or its topic.
            start: The window's start (s).
            end: The window's end (s), left out.

        Raises:
            InputError: An unknown channel, with the closest names.
        """
        topic = CHANNEL_TOPICS.get(name, name)
        if topic not in CHANNEL_TOPICS.values():
            import difflib

            close = difflib.get_close_matches(name, list(CHANNEL_TOPICS), n=2, cutoff=0.6)
            raise InputError(f"channel {name!r} refused: must be one of {', '.join(CHANNEL_TOPICS)} (or its topic)"
                             + (f"; did you mean {' or '.join(close)}?" if close else ""))
        ch = self.data.channels.get(topic)
        if ch is None:
            return Table({"time": np.zeros(0), "index": np.zeros(0, dtype=np.int64), "value": np.zeros(0)})
        time = _seconds(ch.time, self._offset)
        keep = _window(time, start, end)
        return Table({"time": time[keep], "index": ch.index[keep].astype(np.int64), "value": ch.values[keep]})
