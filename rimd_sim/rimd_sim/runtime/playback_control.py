"""Foxglove's timeline driving a replay: the mapping and the state machine, without ROS and without the SDK.

The Foxglove WebSocket protocol's playback control (capability ``playbackControl``): the server announces the
time range of its data; the client's player sends a request each time the user acts on the timeline, with the
command it wants (Play or Pause), the speed it shows and, when the user moved the cursor, a seek time; the server
answers with its state (Playing, Paused or Ended, the current time, the speed, whether it sought) and also
broadcasts the state whenever it changes for another reason.

:class:`PlaybackControl` does this over a replay's controls (:class:`ReplayControls`; the bridge node gives the
replay's rosbag2-named services, a test can give a :class:`~rimd_sim.runtime.replay.Player`):

* a request becomes the replay's calls (:func:`plan`, on the replay's state read when it arrives): Pause while
  playing -> ``pause`` (first: nothing is published from a seek's time before the pause); a seek time ->
  ``seek``; a speed other than the replay's rate -> ``set_rate``; Play while paused -> ``resume`` (last: the
  replay plays from the seek's time at the new rate); Play at the end plays again from the start (a seek to it
  first), as a media player does. The answer is the replay's state read back after the calls, with ``did_seek``
  when a seek was done. A seek or a rate the replay refuses comes back as an error naming the replay with the
  replay's own message (the other calls of the request are made);
* :meth:`PlaybackControl.poll` reads the replay's state; when what the clients were last told changes (status,
  speed, or a jump: a seek by someone else, a new pass of a loop) it returns the state to broadcast. A replay
  that stops answering (it exits at the end unless ``keep_alive``) is reported Ended, once;
* :meth:`PlaybackControl.now_ns` is the playback time (the time broadcast to the clients and the log time of the
  messages forwarded): the replay's position as last read, moved on at its rate while playing (at most
  :data:`MAX_EXTRAPOLATION_S` past the last reading, and never backwards except at a jump), within the range.

Times are the recording's log times (the time base of the replay's ``~/seek``, its ``/clock`` and
``metadata.yaml``); the range is the part the replay plays (its ``start_offset`` to the last message, or to the
end of its ``playback_duration``).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from rimd_sim.errors import UnavailableError
from rimd_sim.runtime.replay import PlayerState

__all__ = ["MAX_EXTRAPOLATION_S", "PlaybackControl", "PlaybackReport", "PlaybackRequest", "ReplayControls",
           "ReplayUnavailable", "plan", "requested_speed"]

#: The playback time runs on from the last reading of the replay's position for at most this long (s).
MAX_EXTRAPOLATION_S = 0.5


class ReplayUnavailable(UnavailableError):
    """The replay did not answer (not running, or not in time); the message says which service and why."""


class ReplayControls(Protocol):
    """A replay's controls, as its services offer them (each may raise :class:`ReplayUnavailable`)."""

    def state(self) -> PlayerState:
        """Where the playback stands (``~/get_state``)."""
        ...

    def seek(self, t_ns: int) -> tuple[bool, str]:
        """``~/seek`` to a log time: (accepted, the replay's message)."""
        ...

    def set_rate(self, rate: float) -> tuple[bool, str]:
        """``~/set_rate``: (accepted, the replay's message)."""
        ...

    def pause(self) -> tuple[bool, str]:
        """``~/pause``: (it was playing, the replay's message)."""
        ...

    def resume(self) -> tuple[bool, str]:
        """``~/resume``: (it was paused, the replay's message)."""
        ...


@dataclass(frozen=True)
class PlaybackRequest:
    """A client's playback control request: the command (``play``: Play, else Pause), speed, seek time (ns)."""

    play: bool
    speed: float
    seek_ns: int | None = None
    request_id: str = ""


@dataclass(frozen=True)
class PlaybackReport:
    """The state told to the clients: ``playing``, ``paused`` or ``ended``; the playback time (ns); the speed."""

    status: str
    current_ns: int
    speed: float
    did_seek: bool = False


def requested_speed(speed: float) -> float:
    """The speed a client asked for, as the number it meant (7 significant digits).

    The protocol carries a 32-bit float: 0.1 arrives as 0.10000000149. NaN and infinities pass through (the
    replay refuses them).
    """
    return float(f"{speed:.7g}") if math.isfinite(speed) else speed


def plan(request: PlaybackRequest, state: PlayerState) -> list[tuple[str, Any]]:
    """The replay's calls for a request, in order (see the module docstring).

    Each is ``("pause", None)``, ``("seek", t_ns)``, ``("set_rate", rate)`` or ``("resume", None)``.
    """
    calls: list[tuple[str, Any]] = []
    if not request.play and not state.paused:
        calls.append(("pause", None))
    seek = request.seek_ns
    if seek is None and request.play and state.ended:
        seek = state.start_ns   # Play at the end: from the start again
    if seek is not None:
        calls.append(("seek", int(seek)))
    speed = requested_speed(request.speed)
    if not math.isclose(speed, state.rate, rel_tol=1e-9):
        calls.append(("set_rate", speed))
    if request.play and state.paused:
        calls.append(("resume", None))
    return calls


class PlaybackControl:
    """A replay driven by the playback control of Foxglove clients. See the module docstring.

    Args:
        controls: The replay's controls.
        name: The replay as the error messages name it (``/rimd_replay``).
        clock: Monotonic seconds (for the playback time between two readings).
    """

    def __init__(self, controls: ReplayControls, name: str, *, clock: Callable[[], float] = time.monotonic) -> None:
        self._controls = controls
        self.name = name
        self._clock = clock
        self._busy = threading.Lock()     # one request or poll at a time: no reading between a request's calls
        self._lock = threading.Lock()     # the fields below
        self._state: PlayerState | None = None
        self._read_at = 0.0
        self._gone = False
        self._told: tuple[str, float, tuple[int, int]] | None = None
        self._floor: int | None = None

    @property
    def state(self) -> PlayerState | None:
        """The replay's state as last read (None: never read)."""
        return self._state

    @property
    def time_range(self) -> tuple[int, int] | None:
        """The part the replay plays, as log times (ns), once read."""
        state = self._state
        return None if state is None else (state.start_ns, state.end_ns)

    # -- the playback time -------------------------------------------------------------------------------------
    def _observe(self, state: PlayerState) -> None:
        with self._lock:
            before = self._state
            if before is None or state.position_ns < before.position_ns or \
                    (state.passes, state.seeks) != (before.passes, before.seeks):
                self._floor = None   # a jump: the time may go back
            self._state, self._read_at = state, self._clock()

    def now_ns(self) -> int | None:
        """The playback time (ns), or None before the replay's first answer."""
        with self._lock:
            state = self._state
            if state is None:
                return None
            t = state.position_ns
            if state.status == "playing" and not self._gone:
                ahead = min(max(self._clock() - self._read_at, 0.0), MAX_EXTRAPOLATION_S)
                t += round(ahead * state.rate * 1e9)
            t = min(max(t, state.start_ns), state.end_ns)
            if self._floor is not None:
                t = max(t, self._floor)
            self._floor = t
            return t

    def _report(self, did_seek: bool = False) -> PlaybackReport:
        state = self._state
        assert state is not None   # called once the replay has answered
        status = "ended" if self._gone else state.status
        now = self.now_ns()
        assert now is not None
        report = PlaybackReport(status, now, state.rate, did_seek)
        self._told = (status, state.rate, (state.passes, state.seeks))
        return report

    # -- the replay changed ------------------------------------------------------------------------------------
    def poll(self) -> tuple[PlaybackReport | None, str | None]:
        """Read the replay's state; what to tell the clients.

        Returns:
            The state to broadcast when the clients' picture changed (else None), and a line to show them when the
            replay stopped or started answering (else None).
        """
        with self._busy:
            try:
                state = self._controls.state()
            except ReplayUnavailable as exc:
                if self._state is None or self._gone:
                    return None, None
                self._gone = True
                return self._report(), f"playback: the replay {self.name} stopped answering ({exc})"
            back = self._gone
            self._gone = False
            self._observe(state)
            told = self._told
            if told is not None and told == (state.status, state.rate, (state.passes, state.seeks)):
                return None, None
            jumped = told is not None and told[2] != (state.passes, state.seeks)
            return self._report(did_seek=jumped), (f"playback: the replay {self.name} answers again" if back else None)

    # -- a client's request ------------------------------------------------------------------------------------
    def handle(self, request: PlaybackRequest) -> tuple[PlaybackReport | None, list[str]]:
        """Carry out a client's request.

        Returns:
            The state to answer with (None when the replay was never reached), and the error lines to show, each
            naming the replay and the call, with the replay's own words.
        """
        errors: list[str] = []
        state: PlayerState | None
        with self._busy:
            try:   # the calls are planned on the state now, not as last read (someone may have acted since)
                state = self._controls.state()
                self._observe(state)
            except ReplayUnavailable as exc:
                state = self._state
                if state is None:
                    return None, [f"playback: the replay {self.name} is not answering ({exc})"]
            did_seek = False
            for call, argument in plan(request, state):
                try:
                    accepted, message = (getattr(self._controls, call)(argument) if argument is not None
                                         else getattr(self._controls, call)())
                except ReplayUnavailable as exc:
                    errors.append(f"playback: {call} not done: the replay {self.name} is not answering ({exc})")
                    continue
                if call == "seek":
                    did_seek = accepted
                if not accepted and call in ("seek", "set_rate"):   # pause/resume: already so (another client)
                    errors.append(f"playback: {self.name} ~/{call} refused: {message}")
            try:
                self._observe(self._controls.state())
                self._gone = False
            except ReplayUnavailable as exc:
                self._gone = True
                errors.append(f"playback: the replay {self.name} is not answering ({exc})")
            return self._report(did_seek), errors
