"""The simulator node's runtime on a fake clock, without ROS: what it sent, logged and asked to match."""

from __future__ import annotations

from dataclasses import dataclass, field

from harness.clock import FakeClock
from rimd_sim.runtime.simulator import SimulatorRuntime, load_settings

S = 1_000_000_000
#: The wall clock (ns) when the fake monotonic clock reads 100 s.
WALL0 = 1_790_000_000 * S + 123_456_789


@dataclass
class Rig:
    """A runtime on a fake clock with what it sent, logged and asked to match."""

    rt: SimulatorRuntime
    clock: FakeClock
    sent: list[tuple[str, bytes]] = field(default_factory=list)
    logs: list[tuple[str, str]] = field(default_factory=list)
    matches: list[dict] = field(default_factory=list)

    def on(self, key: str) -> list[bytes]:
        """The messages sent on output ``key``."""
        return [data for k, data in self.sent if k == key]

    def said(self, text: str, level: str | None = None) -> bool:
        """Whether a log line (of ``level``) contains ``text``."""
        return any(text in line and (level is None or lvl == level) for lvl, line in self.logs)

    def run(self, passes: int) -> None:
        """``passes`` passes of the pacing loop without waiting (as fast as possible)."""
        for _ in range(passes):
            assert not self.rt.step().stopped


def make_rig(start: bool = True, **values) -> Rig:
    """A runtime with the parameters ``values`` (flat names), started unless ``start`` is False."""
    clock = FakeClock()
    rig = Rig(None, clock)  # type: ignore[arg-type]
    config, settings = load_settings(values)
    rig.rt = SimulatorRuntime(config, settings, send=lambda key, data: rig.sent.append((key, data)),
                              log=lambda level, line: rig.logs.append((level, line)), clock=clock,
                              wall_ns=lambda: WALL0 + round((clock.now - 100.0) * S), match=rig.matches.append,
                              warm_up=False)
    if start:
        rig.rt.start()
    return rig
