"""Faults of the instruments, on demand and deterministic: what DAQ software must survive.

A fault (:class:`FaultSpec`) acts on one channel from ``start`` (simulation time, s) for ``duration`` (s;
0 = until cleared), with a ``magnitude`` where the kind has one (:data:`FAULT_KINDS`). The
:class:`FaultLayer` applies the faults in force to the data of :class:`~rimd_sim.instruments.rig_simulator.RigSimulator`
at three places, and never to the physics (the truth stream and the other channels are unchanged):

* before the instrument (on the noise-free physical values): ``clock_drift`` (the channel's samples are
  taken at the drifted instants of its own clock, interpolated linearly on the model's exact grid; its
  indices, stamps and ``sample_rate`` stay nominal, as a real device's do);
* on the readings (after filters, noise, quantisation and clipping): ``stuck``, ``offset``, ``gain``,
  ``spike``, ``noise_burst``, ``saturate``, ``disconnect``; readings are then clipped again to the range in
  force and ``saturated_count`` counts every clipped sample;
* on the blocks the DAQ receives: ``dropout`` (nothing is published; ``first_index`` jumps), ``block_loss``
  (a seeded fraction of blocks is never sent), ``delay`` (blocks held back by a latency plus a seeded
  jitter of up to half of it; a jitter longer than a block period delivers blocks out of order).

Random choices (lost blocks, jitter, spike instants and signs, burst noise) come from a stream per fault
seeded by ``(seed, channel, fault number)``: the same seed and schedule give the same data bit for bit,
however the simulation time is cut into calls. The instrument's own noise stream is not touched, so after
a fault ends the channel is again sample for sample what it would have been without the fault (except
after ``clock_drift``, whose accumulated clock offset stays, as a real device's does).

``disconnect`` gives the upper end of the range (the rail) with every sample counted as saturated: an
IEPE/ICP front end (the accelerometer, the force sensor) with no sensor on its constant-current input
drives its output to the compliance voltage, which the DAQ reads as its top rail, and the laser
sensors report an out-of-range value when they lose their target. Zero would look like a quiet,
healthy sensor; the rail is what a DAQ must learn to recognise.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from rimd_sim.errors import CommandError
from rimd_sim.settings.config import CHANNEL_NAMES, ChannelConfig

__all__ = [
    "FAULT_KINDS",
    "MOTOR",
    "FaultEvent",
    "FaultLayer",
    "FaultSpec",
    "parse_fault_entry",
    "validate_fault",
]

#: The pseudo-channel of the motor.
MOTOR = "motor"


@dataclass(frozen=True)
class KindRule:
    """What a fault kind does with its magnitude and the rule the magnitude must meet."""

    stage: str          # "pre", "post", "block" or "motor"
    magnitude: str      # meaning of the magnitude ("" = none)
    low: float | None   # bounds of the magnitude (None = open)
    high: float | None
    low_open: bool = False
    rule: str = ""


FAULT_KINDS: dict[str, KindRule] = {
    "dropout": KindRule("block", "", None, None, rule="ignored (must be finite)"),
    "block_loss": KindRule("block", "fraction of blocks lost", 0.0, 1.0, rule="must be a fraction within [0, 1]"),
    "delay": KindRule("block", "latency (s); jitter up to half of it", 0.0, 10.0, low_open=True,
                      rule="must be a latency in s within (0, 10]"),
    "stuck": KindRule("post", "", None, None, rule="ignored (must be finite)"),
    "offset": KindRule("post", "offset added (SI unit of the channel)", None, None, rule="must be finite"),
    "gain": KindRule("post", "factor applied to the reading", None, None, rule="must be finite"),
    "spike": KindRule("post", "outliers per second", 0.0, None, low_open=True,
                      rule="must be a rate > 0 per s, at most the channel's sample rate"),
    "noise_burst": KindRule("post", "standard deviation of the added noise (SI)", 0.0, None, low_open=True,
                            rule="must be finite and > 0"),
    "saturate": KindRule("post", "limit of the shrunk range (SI, symmetric)", 0.0, None, low_open=True,
                         rule="must be finite and > 0"),
    "disconnect": KindRule("post", "", None, None, rule="ignored (must be finite)"),
    "clock_drift": KindRule("pre", "clock error in ppm (fast > 0)", 0.0, 10_000.0, low_open=True,
                            rule="must be within (0, 10000] ppm (a fast clock; a slow one would need samples from "
                                 "the future of the block and is not supported)"),
    "motor_slip": KindRule("motor", "fraction of the frequency lost", 0.0, 1.0,
                           rule="must be a fraction within [0, 1]"),
}


@dataclass(frozen=True)
class FaultSpec:
    """One fault as scheduled.

    Attributes:
        channel: A channel name of the configuration, or ``motor``.
        kind: A key of :data:`FAULT_KINDS`.
        start: Simulation time it starts (s, exact).
        duration: Its length (s, exact); 0 = until cleared.
        magnitude: See :data:`FAULT_KINDS`.
        number: Running number of the fault since the simulator started (seeds its random stream).
    """

    channel: str
    kind: str
    start: Fraction
    duration: Fraction
    magnitude: float
    number: int = 0

    @property
    def end(self) -> Fraction | None:
        """Simulation time it ends (None: until cleared)."""
        return self.start + self.duration if self.duration > 0 else None


@dataclass(frozen=True)
class FaultEvent:
    """A fault started or ended at ``time`` (simulation time, s)."""

    time: Fraction
    event: str      # "start" or "end"
    fault: FaultSpec
    detail: str = ""


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise CommandError(f"{name} = {value!r} refused: must be a number")
    value = float(value)
    if not math.isfinite(value):
        raise CommandError(f"{name} = {value!r} refused: must be finite")
    return value


def validate_fault(channel: Any, kind: Any, start: Any, duration: Any, magnitude: Any, *, now: Fraction,
                   channels: Mapping[str, ChannelConfig], after: Any = 0.0
                   ) -> tuple[str, str, Fraction, Fraction, float]:
    """Check a fault request; returns ``(channel, kind, start, duration, magnitude)`` with exact times.

    ``start`` is simulation time, 0 meaning ``now`` (the next block boundary); ``after`` (with ``start`` 0) is
    a time relative to ``now``, for a client that does not know how long the rig has run.

    Raises:
        CommandError: Naming the field and the rule it broke.
    """
    if not isinstance(kind, str) or kind not in FAULT_KINDS:
        raise CommandError(f"kind = {kind!r} refused: must be one of {', '.join(FAULT_KINDS)}"
                           + _closest(kind, list(FAULT_KINDS)))
    rule = FAULT_KINDS[kind]
    names = list(channels)
    if rule.stage == "motor":
        if channel != MOTOR:
            raise CommandError(f"channel = {channel!r} refused: kind '{kind}' acts on the channel 'motor'")
    elif not isinstance(channel, str) or channel not in channels:
        allowed = ", ".join(names)
        raise CommandError(f"channel = {channel!r} refused: must be one of {allowed}" + _closest(channel, names)
                           + (f" (kind '{kind}' is a sensor fault; 'motor' takes motor_slip)" if channel == MOTOR
                              else ""))
    start_s = _number("start", start)
    after_s = _number("after", after)
    duration_s = _number("duration", duration)
    magnitude = _number("magnitude", magnitude)
    if duration_s < 0:
        raise CommandError(f"duration = {duration_s!r} refused: must be >= 0 s (0 = until cleared)")
    if start_s < 0:
        raise CommandError(f"start = {start_s!r} refused: must be >= 0 s of simulation time (0 = next block boundary)")
    if after_s < 0 or after_s > MAX_AHEAD_S:
        raise CommandError(f"after = {after_s!r} refused: must be >= 0 and <= {MAX_AHEAD_S} s (seconds of simulation "
                           "time from when the request arrives)")
    if after_s and start_s:
        raise CommandError(f"after = {after_s!r} refused: give start (simulation time) or after (relative to now), "
                           f"not both (start = {start_s!r})")
    t_start = now + Fraction(repr(after_s)) if after_s else now if start_s == 0 else Fraction(repr(start_s))
    if t_start < now:
        raise CommandError(f"start = {start_s!r} refused: in the past (simulation time is {float(now):.6f} s); "
                           "must be 0 (next block boundary), a time from now on, or use after (seconds from now)")
    lo_bad = rule.low is not None and (magnitude <= rule.low if rule.low_open else magnitude < rule.low)
    hi_bad = rule.high is not None and magnitude > rule.high
    if kind == "spike" and channel in channels and magnitude > channels[channel].sample_rate:
        hi_bad = True
    if lo_bad or hi_bad:
        raise CommandError(f"magnitude = {magnitude!r} refused: for kind '{kind}' it {rule.rule}")
    return channel, kind, t_start, Fraction(repr(duration_s)), magnitude


#: Longest a fault may be scheduled ahead (s of simulation time): one day, as the rig's other commands.
MAX_AHEAD_S = 86_400

#: The fields of a fault entry: ``start`` (simulation time) or ``after`` (relative to when it is injected).
ENTRY_FIELDS = ("channel", "kind", "start", "after", "duration", "magnitude")


def _closest(name: Any, known: Sequence[str]) -> str:
    """``; did you mean X?`` for the known names closest to ``name`` (difflib's ratio >= 0.6), else ''."""
    import difflib

    close = difflib.get_close_matches(name, list(known), n=2, cutoff=0.6) if isinstance(name, str) else []
    return f"; did you mean {' or '.join(close)}?" if close else ""


def check_scenario(entries: Sequence[Any], channels: Mapping[str, ChannelConfig]) -> None:
    """Check a fault scenario before anything runs.

    Each entry is read as :func:`parse_fault_entry` and :func:`validate_fault` read it at the start of a run
    (simulation time 0).

    Raises:
        CommandError: Naming the entry (``faults[2]``), the field and its rule (with the closest names).
    """
    for i, entry in enumerate(entries):
        if isinstance(entry, str) and not entry.strip():
            continue
        where = f"faults[{i}]"
        fields = parse_fault_entry(entry, where)
        try:
            validate_fault(fields["channel"], fields["kind"], fields["start"], fields["duration"], fields["magnitude"],
                           now=Fraction(0), channels=channels, after=fields["after"])
        except CommandError as exc:
            raise CommandError(f"{where}: {exc}") from None


def parse_fault_entry(entry: Any, where: str) -> dict[str, Any]:
    """One scenario entry as a dict of ``channel, kind, start, after, duration, magnitude``.

    An entry is a mapping (a scenario file) or a string ``"channel=impact_force kind=dropout start=5
    duration=1 magnitude=0"`` (the simulator's ``faults`` parameter: ROS parameters hold no list of maps).

    Raises:
        CommandError: Naming ``where`` (for example ``faults[2]``), the field and the rule.
    """
    if isinstance(entry, str):
        fields: dict[str, Any] = {}
        for token in entry.split():
            key, sep, value = token.partition("=")
            if not sep:
                raise CommandError(f"{where} = {entry!r} refused: '{token}' is not key=value")
            fields[key] = value if key in ("channel", "kind") else _float_field(where, key, value)
        entry = fields
    if not isinstance(entry, Mapping):
        raise CommandError(f"{where} = {entry!r} refused: must be a mapping of " + ", ".join(ENTRY_FIELDS))
    unknown = set(entry) - set(ENTRY_FIELDS)
    if unknown:
        raise CommandError(f"{where}.{sorted(unknown)[0]} refused: unknown field (fields: {', '.join(ENTRY_FIELDS)})")
    for key in ("channel", "kind"):
        if key not in entry:
            raise CommandError(f"{where}.{key} missing: every fault needs channel, kind and start or after")
    if ("start" in entry) == ("after" in entry):
        raise CommandError(f"{where}: give start (s of simulation time) or after (s from when the fault is injected), "
                           "one of the two")
    out = {"channel": entry["channel"], "kind": entry["kind"], "start": entry.get("start", 0.0),
           "after": entry.get("after", 0.0), "duration": entry.get("duration", 0.0),
           "magnitude": entry.get("magnitude", 0.0)}
    for key in ("start", "after", "duration", "magnitude"):
        if isinstance(out[key], int) and not isinstance(out[key], bool):
            out[key] = float(out[key])
    return out


def _float_field(where: str, key: str, value: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise CommandError(f"{where}.{key} = {value!r} refused: must be a number") from None


# ---- application -----------------------------------------------------------------------------------------


@dataclass
class _Active:
    spec: FaultSpec
    end: Fraction | None
    rng: np.random.Generator
    started: bool = False
    ended: bool = False
    stuck_value: float | None = None


@dataclass
class _Drift:
    """A clock drift on a channel: sample window [n0, n1) and ratio d / (1 + d)."""

    n0: int
    n1: int | None
    ratio: float
    fault: _Active


@dataclass
class _ChannelState:
    rate: Fraction
    config: ChannelConfig
    hist_first: int = 0
    hist: np.ndarray = field(default_factory=lambda: np.zeros(0))
    last: float | None = None
    drifts: list[_Drift] = field(default_factory=list)
    held: list[tuple[Fraction, int, Any]] = field(default_factory=list)


class FaultLayer:
    """The faults of one simulator and their state. See the module docstring.

    Args:
        channels: The channels' configurations.
        seed: The simulator's seed.
    """

    def __init__(self, channels: Sequence[ChannelConfig], seed: int) -> None:
        self._seed = int(seed)
        self._ch = {c.name: _ChannelState(Fraction(repr(c.sample_rate)), c) for c in channels}
        self._faults: list[_Active] = []
        self._count = 0
        self._held_seq = 0

    # ---- scheduling --------------------------------------------------------------------------------

    def configure(self, channels: Sequence[ChannelConfig]) -> None:
        """Take new channel parameters (ranges); the rates never change while running."""
        for c in channels:
            self._ch[c.name].config = c

    def add(self, channel: str, kind: str, start: Fraction, duration: Fraction, magnitude: float) -> FaultSpec:
        """Schedule a validated fault (see :func:`validate_fault`)."""
        spec = FaultSpec(channel, kind, start, duration, magnitude, self._count)
        self._count += 1
        key = (CHANNEL_NAMES.index(channel) if channel in CHANNEL_NAMES else len(CHANNEL_NAMES), spec.number)
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(self._seed, spawn_key=(1000,) + key)))
        active = _Active(spec, spec.end, rng)
        self._faults.append(active)
        if kind == "clock_drift":
            st = self._ch[channel]
            n1 = None if spec.end is None else _ceil(spec.end * st.rate)
            d = magnitude * 1e-6
            st.drifts.append(_Drift(_ceil(start * st.rate), n1, d / (1.0 + d), active))
        return spec

    def clear(self, now: Fraction) -> tuple[int, int]:
        """End every fault in force at ``now``, cancel those not started; returns ``(ended, cancelled)``."""
        ended = cancelled = 0
        keep = []
        for f in self._faults:
            if f.spec.start >= now and not f.started:
                cancelled += 1
                f.ended = True
                for st in self._ch.values():
                    st.drifts = [d for d in st.drifts if d.fault is not f]
                continue
            if f.end is None or f.end > now:
                f.end = now
                ended += 1
                if f.spec.kind == "clock_drift":
                    st = self._ch[f.spec.channel]
                    for d in st.drifts:
                        if d.fault is f:
                            d.n1 = _ceil(now * st.rate)
            keep.append(f)
        self._faults = keep
        return ended, cancelled

    def active(self, t: Fraction) -> list[FaultSpec]:
        """Faults in force at ``t``."""
        return [f.spec for f in self._faults if f.spec.start <= t and (f.end is None or t < f.end)]

    def pending(self) -> int:
        """Faults known and not yet ended."""
        return sum(1 for f in self._faults if not f.ended)

    @property
    def empty(self) -> bool:
        """No fault known and no delayed block held (the data path can skip the layer)."""
        return not self._faults and not any(st.drifts or st.held for st in self._ch.values())

    # ---- the data path -------------------------------------------------------------------------------

    def _window(self, f: _Active, rate: Fraction) -> tuple[int, int | None]:
        return _ceil(f.spec.start * rate), (None if f.end is None else _ceil(f.end * rate))

    def pre(self, name: str, first: int, raw: np.ndarray) -> np.ndarray:
        """Noise-free values of a pass (samples ``first ..``), sampled at the channel's drifted instants."""
        st = self._ch[name]
        n = raw.size
        if not st.drifts:
            self._keep_history(st, first, raw, 2)
            return raw
        idx = np.arange(first, first + n, dtype=np.float64)
        lag = np.zeros(n)
        for d in st.drifts:
            if d.n1 is not None and d.n1 <= d.n0:
                continue
            span = idx - d.n0
            np.clip(span, 0.0, None if d.n1 is None else float(d.n1 - d.n0), out=span)
            lag += span * d.ratio
        pos = idx - lag
        if st.hist.size:
            grid = np.concatenate([np.arange(st.hist_first, st.hist_first + st.hist.size, dtype=np.float64), idx])
            values = np.concatenate([st.hist, raw])
        else:
            grid, values = idx, raw
        out = np.interp(pos, grid, values)
        need = int(math.ceil(float(lag.max()) if n else 0.0)) + 2
        self._keep_history(st, first, raw, need)
        return out

    @staticmethod
    def _keep_history(st: _ChannelState, first: int, raw: np.ndarray, need: int) -> None:
        if raw.size >= need:
            st.hist = raw[raw.size - need:].copy()
            st.hist_first = first + raw.size - need
        else:
            keep = min(st.hist.size, need - raw.size)
            st.hist = np.concatenate([st.hist[st.hist.size - keep:], raw])
            st.hist_first = first + raw.size - st.hist.size

    def post(self, name: str, first: int, x: np.ndarray, clipped: np.ndarray | None) -> tuple[np.ndarray,
                                                                                              np.ndarray | None]:
        """Apply the reading faults to the readings ``x`` of samples ``first ..``; returns new readings and mask."""
        st = self._ch[name]
        n = x.size
        if not self._faults:   # the rig's usual pass: nothing to apply
            if n:
                st.last = float(x[-1])
            return x, clipped
        touched = False
        cfg = st.config
        lo_range, hi_range = cfg.range_min, cfg.range_max
        lim_lo = np.full(n, lo_range) if n else None
        lim_hi = np.full(n, hi_range) if n else None
        forced = None
        for f in self._faults:
            spec = f.spec
            if spec.channel != name or FAULT_KINDS[spec.kind].stage != "post":
                continue
            n0, n1 = self._window(f, st.rate)
            a = max(n0 - first, 0)
            b = n if n1 is None else min(n1 - first, n)
            if a >= b:
                continue
            touched = True
            m = spec.magnitude
            kind = spec.kind
            if kind == "offset":
                x[a:b] += m
            elif kind == "gain":
                x[a:b] *= m
            elif kind == "stuck":
                if f.stuck_value is None:
                    f.stuck_value = float(x[a - 1]) if a > 0 else (st.last if st.last is not None else float(x[a]))
                x[a:b] = f.stuck_value
            elif kind == "noise_burst":
                x[a:b] += m * f.rng.standard_normal(b - a)
            elif kind == "spike":
                # One uniform per sample (so the draws do not depend on how passes cut the time): a spike
                # where u < p, negative in its lower half.
                p = m / float(st.rate)
                u = f.rng.random(b - a)
                where = np.flatnonzero(u < p)
                if where.size:
                    signs = np.where(u[where] < 0.5 * p, -1.0, 1.0)
                    x[a + where] += signs * 0.25 * (hi_range - lo_range)
            elif kind == "saturate":
                assert lim_lo is not None and lim_hi is not None   # n > 0 here: a < b <= n
                np.maximum(lim_lo[a:b], -m, out=lim_lo[a:b])
                np.minimum(lim_hi[a:b], m, out=lim_hi[a:b])
            elif kind == "disconnect":
                if forced is None:
                    forced = np.zeros(n, dtype=bool)
                forced[a:b] = True
        if n:
            if touched:
                if forced is not None:
                    x[forced] = hi_range
                over = (x < lim_lo) | (x > lim_hi)
                if forced is not None:
                    over |= forced
                if over.any():
                    np.clip(x, lim_lo, lim_hi, out=x)
                    if forced is not None:
                        x[forced] = hi_range
                    clipped = over if clipped is None else (clipped | over)
            st.last = float(x[-1])
        return x, clipped

    def deliver(self, name: str, block: Any, t0: Fraction, t1: Fraction) -> list[Any]:
        """The blocks of a channel the DAQ receives at the end of ``[t0, t1)``, given the block computed for it."""
        st = self._ch[name]
        send = True
        for f in self._faults:
            spec = f.spec
            if spec.channel != name or FAULT_KINDS[spec.kind].stage != "block":
                continue
            if not (spec.start < t1 and (f.end is None or t0 < f.end)):
                continue
            if spec.kind == "dropout":
                send = False
            elif spec.kind == "block_loss":
                if f.rng.random() < spec.magnitude and send:
                    send = False
            elif spec.kind == "delay" and send:
                jitter = f.rng.random() * 0.5 * spec.magnitude
                release = t1 + Fraction(round((spec.magnitude + jitter) * 1e9), 1_000_000_000)
                heapq.heappush(st.held, (release, self._held_seq, block))
                self._held_seq += 1
                send = False
        out = []
        while st.held and st.held[0][0] <= t1:
            out.append(heapq.heappop(st.held)[2])
        if send:
            out.append(block)
        return out

    def events(self, t0: Fraction, t1: Fraction) -> list[FaultEvent]:
        """Starts and ends of faults in ``[t0, t1)``, in time order; faults over and done are forgotten."""
        events = []
        for f in self._faults:
            if not f.started and f.spec.start < t1:
                f.started = True
                events.append(FaultEvent(max(f.spec.start, t0), "start", f.spec, _describe(f.spec)))
            if f.started and not f.ended and f.end is not None and f.end < t1:
                f.ended = True
                events.append(FaultEvent(max(f.end, t0), "end", f.spec,
                                         "cleared" if f.end != f.spec.end else "duration elapsed"))
        events.sort(key=lambda e: (e.time, e.fault.number))
        self._faults = [f for f in self._faults if not f.ended]
        return events


def _ceil(x: Fraction) -> int:
    return -((-x.numerator) // x.denominator)


def _describe(spec: FaultSpec) -> str:
    rule = FAULT_KINDS[spec.kind]
    what = f"{spec.kind} on {spec.channel} from t = {float(spec.start):.6f} s"
    what += f" for {float(spec.duration):g} s" if spec.duration > 0 else " until cleared"
    if rule.magnitude:
        what += f", {rule.magnitude} {spec.magnitude:g}"
    return what

