"""Where the Rerun stream goes: an ``.rrd`` file, a spawned viewer, a viewer at a URL, or a web viewer on loopback.

:class:`RerunStream` owns the recording stream and any viewer process it started; ``close()`` flushes and
is safe to call twice (a context manager).

Usage reporting: Rerun's viewer reports anonymous usage unless its configuration
(``<config dir>/rerun/analytics.json``) says ``analytics_enabled: false``. Unless ``analytics`` is true,
this module points ``XDG_CONFIG_HOME`` of this process and of the viewers it starts at a private
directory whose ``rerun/analytics.json`` turns reporting off. The user's own Rerun configuration is
neither read nor changed; ``analytics=True`` leaves the environment alone (then the user's choice, e.g.
``rerun analytics enable|disable``, applies).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rimd_sim.dependencies import installed, missing_extra
from rimd_sim.errors import UnavailableError

__all__ = ["MEMORY_LIMIT_RULE", "SINKS", "RerunStream", "SinkError", "SinkSpec", "analytics_off_environment",
           "memory_limit_problem", "require_rerun", "spec_from_parameters"]

SINKS = ("save", "spawn", "connect", "serve_web")
APPLICATION_ID = "rimd_rig"

#: What the serve_web sink's server keeps for a viewer that connects or reloads later: about half a minute of the
#: display stream, the series' styles (static) and the layout. The live view shows seconds; the recording keeps
#: everything. The server's memory levels off once the history is full, the sooner the smaller it is
#: (docs/benchmarks.md, "Soak").
SERVER_HISTORY = "4MiB"

#: A memory limit as Rerun's ``--memory-limit`` and ``--server-memory-limit`` read it (re_memory's MemoryLimit):
#: ``0``, a size in bytes with a decimal (kB, MB, GB, TB) or binary (KiB, MiB, GiB, TiB) unit or a plain ``B``,
#: a percentage of the machine's memory, or no limit.
_MEMORY_LIMIT = re.compile(r"0|unlimited|none|max|∞|(?P<size>\d+(\.\d+)?)(kB|MB|GB|TB|KiB|MiB|GiB|TiB)|\d+B"
                           r"|(?P<percent>\d+(\.\d+)?)%")
#: That rule in words.
MEMORY_LIMIT_RULE = "a Rerun memory limit (64MiB, 1GiB, 10% of the machine's, 0, unlimited)"


class SinkError(UnavailableError):
    """The sink cannot be opened (bad name, unwritable path, viewer did not start); one clear line."""


def require_rerun(feature: str = "the Rerun bridge", alternative: str = "or run with --no-rerun") -> None:
    """Refuse a Rerun feature without the Rerun SDK (the extra ``rerun``), before anything starts.

    Raises:
        SinkError: rerun-sdk is not installed; the message names the feature, the extra and ``alternative``.
    """
    if not installed("rerun"):
        raise SinkError(missing_extra("rerun", feature, alternative))


def memory_limit_problem(value: str) -> bool | str:
    """A parameter ``check``: True when Rerun reads ``value`` as a memory limit, else False or what is wrong.

    The rule is :data:`MEMORY_LIMIT_RULE`. Checked before a viewer or server starts: Rerun would refuse the value
    only in the process it starts, out of sight.
    """
    match = _MEMORY_LIMIT.fullmatch(value.replace(" ", ""))
    if match is None:
        return False
    if match["percent"] is not None and float(match["percent"]) > 100:
        return "a percentage of the machine's memory is at most 100%"
    return True


#: Values that :func:`memory_limit_problem` refuses (for the generated bad-input tests).
BAD_MEMORY_LIMITS = ("", "1G", "64 mib", "-1MiB", "150%", "lots")


@dataclass(frozen=True)
class SinkSpec:
    """Which sink and its settings.

    Attributes:
        kind: One of :data:`SINKS`.
        path: ``save``: the ``.rrd`` file to write.
        url: ``connect``: gRPC URL of a viewer or server (``rerun+http://HOST:PORT/proxy``).
        grpc_port: ``spawn``/``serve_web``: gRPC port of the viewer or server started (0 = a free one).
        web_port: ``serve_web``: HTTP port of the web viewer (0 = a free one).
        memory_limit: ``spawn``: memory limit of the viewer started (it drops the oldest data beyond it).
        server_memory_limit: ``serve_web``: what the server keeps for a viewer that connects later (Rerun's
            ``--server-memory-limit``: beyond it the oldest data goes; the blueprint stays).
        analytics: Leave Rerun's usage reporting to the user's configuration (default: off).
    """

    kind: str
    path: str = ""
    url: str = "rerun+http://127.0.0.1:9876/proxy"
    grpc_port: int = 0
    web_port: int = 0
    memory_limit: str = "1GiB"
    server_memory_limit: str = SERVER_HISTORY
    analytics: bool = False

    def validate(self) -> None:
        """Raise :class:`SinkError` naming the value and the rule when the spec cannot work.

        Every sink needs the Rerun SDK: without it the error names the extra (:func:`require_rerun`).
        """
        require_rerun()
        if self.kind not in SINKS:
            raise SinkError(f"unknown sink {self.kind!r}: one of {', '.join(SINKS)}")
        if self.kind == "save":
            if not self.path:
                raise SinkError("sink 'save' needs a path (.rrd)")
            parent = Path(self.path).expanduser().resolve().parent
            try:
                parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise SinkError(f"cannot create {parent} for {self.path}: {exc.strerror}") from None
            if not os.access(parent, os.W_OK) or Path(self.path).is_dir():
                raise SinkError(f"cannot write {self.path}: not a writable file location")
        if self.kind == "connect" and not self.url.startswith(("rerun://", "rerun+http://", "rerun+https://")):
            raise SinkError(f"url {self.url!r} is not a Rerun gRPC URL (rerun+http://HOST:PORT/proxy)")
        for name in ("grpc_port", "web_port"):
            if not 0 <= getattr(self, name) <= 65535:
                raise SinkError(f"{name} {getattr(self, name)} is not a port number (0..65535)")
        for name in ("memory_limit", "server_memory_limit"):
            problem = memory_limit_problem(getattr(self, name))
            if problem is not True:
                raise SinkError(f"{name} {getattr(self, name)!r} is not a memory limit: "
                                + (problem if isinstance(problem, str) else f"must be {MEMORY_LIMIT_RULE}"))


def spec_from_parameters(params: Mapping[str, Any]) -> SinkSpec:
    """The sink of a ``rimd_rerun: ros__parameters:`` section (flat names; defaults for missing ones).

    Shared by the node and by a bring-up that wants to refuse a bad section before starting anything:
    ``spec_from_parameters(section).validate()`` raises :class:`SinkError` naming the value and the rule.
    """
    save_path = str(params.get("save_path", "") or "")
    if not save_path:
        save_path = f"rimd_{datetime.now(UTC).strftime('%Y%m%dT%H%M%SZ')}.rrd"
    try:
        return SinkSpec(str(params.get("sink", "serve_web")), path=save_path,
                        url=str(params.get("url", SinkSpec.url)), grpc_port=int(params.get("grpc_port", 0)),
                        web_port=int(params.get("web_port", 0)),
                        memory_limit=str(params.get("memory_limit", SinkSpec.memory_limit)),
                        server_memory_limit=str(params.get("server_memory_limit", SinkSpec.server_memory_limit)),
                        analytics=bool(params.get("analytics", False)))
    except (TypeError, ValueError) as exc:
        raise SinkError(f"bad rimd_rerun parameter: {exc}") from None


def _private_config_home() -> Path:
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "rimd" / "rerun_config"


def analytics_off_environment() -> dict[str, str]:
    """Environment variables under which Rerun (SDK and viewer) reports no usage; writes the private config.

    Returns ``{"XDG_CONFIG_HOME": <private dir>}``; ``<private dir>/rerun/analytics.json`` has
    ``analytics_enabled: false``.
    """
    home = _private_config_home()
    config_dir = home / "rerun"
    config_file = config_dir / "analytics.json"
    config = {
        "analytics_enabled": False,
        "analytics_id": "rimd-analytics-off",
        "metadata": {},
        "config_file_path": str(config_file),
        "data_dir_path": str(home / "analytics_data"),
    }
    try:
        config_dir.mkdir(parents=True, exist_ok=True)
        if not config_file.exists() or json.loads(config_file.read_text()) != config:
            tmp = config_file.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps(config))
            tmp.replace(config_file)
    except (OSError, ValueError) as exc:
        raise SinkError(f"cannot write the Rerun analytics-off configuration in {config_dir}: {exc}") from None
    return {"XDG_CONFIG_HOME": str(home)}


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_port(port: int, proc: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SinkError(f"the Rerun viewer exited with status {proc.returncode} before listening on {port}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise SinkError(f"the Rerun viewer did not listen on 127.0.0.1:{port} within {timeout:g} s")


def _check_reachable(url: str, timeout: float = 2.0) -> None:
    """Refuse at once a URL where nothing listens (Rerun would buffer, retry, and drop the data at the end)."""
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    host = parts.hostname or "127.0.0.1"
    port = parts.port or (443 if parts.scheme == "rerun+https" else 9876)
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return
    except OSError as exc:
        raise SinkError(f"no Rerun viewer or server at {url} ({exc.strerror or exc}); start one with "
                        "`rerun` or pick another sink") from None


def _rerun_executable() -> str:
    """The viewer binary itself (not the ``rerun`` console script, a Python wrapper that runs it)."""
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).with_name("rerun")
        if exe.is_file():
            return str(exe)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise SinkError(missing_extra("rerun_cli", "the Rerun viewer"))
    return found


class RerunStream:
    """A Rerun recording stream connected to one sink; owns the viewer process it starts (serve_web).

    Args:
        spec: The sink.
        blueprint: Default layout sent with the stream.
        recording_name: Shown in the viewer's recording list.
    """

    def __init__(self, spec: SinkSpec, blueprint: Any = None, *, recording_name: str = "rimd") -> None:
        """Open the sink (raises :class:`SinkError` with one clear line)."""
        spec.validate()
        self.spec = spec
        self._proc: subprocess.Popen | None = None
        self._closed = False
        self.viewer_url = ""
        if not spec.analytics:
            os.environ.update(analytics_off_environment())  # before the SDK's first use; inherited by viewers
        import rerun as rr

        self.rec = rr.RecordingStream(APPLICATION_ID, send_properties=True)
        self.rec.send_recording_name(recording_name)
        try:
            if spec.kind == "save":
                self.rec.save(str(Path(spec.path).expanduser()), default_blueprint=blueprint)
                self.viewer_url = str(spec.path)
            elif spec.kind == "connect":
                _check_reachable(spec.url)
                self.rec.connect_grpc(spec.url, default_blueprint=blueprint)
                self.viewer_url = spec.url
            elif spec.kind == "spawn":
                import rerun as rr

                if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                            or os.environ.get("WAYLAND_DISPLAY")):
                    raise SinkError("no display for a viewer window (DISPLAY and WAYLAND_DISPLAY unset): save an "
                                    ".rrd, connect to a viewer elsewhere, or serve the web viewer")

                port = spec.grpc_port or _free_port()
                rr.spawn(port=port, memory_limit=spec.memory_limit, default_blueprint=blueprint,
                         executable_path=_rerun_executable(), recording=self.rec)
                self.viewer_url = f"rerun+http://127.0.0.1:{port}/proxy"
            else:  # serve_web: a Rerun server + web viewer bound to loopback, owned by this stream
                grpc_port = spec.grpc_port or _free_port()
                web_port = spec.web_port or _free_port()
                cmd = [_rerun_executable(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
                       "--web-viewer-port", str(web_port), "--server-memory-limit", spec.server_memory_limit]
                # Its own process group, so that a Ctrl-C to ours does not stop it before the last flush;
                # close() stops that group.
                self._proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.DEVNULL, start_new_session=True)
                _wait_port(grpc_port, self._proc, timeout=15.0)
                url = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
                self.rec.connect_grpc(url, default_blueprint=blueprint)
                self.viewer_url = f"http://127.0.0.1:{web_port}/?url={url}"
        except SinkError:
            self.close()
            raise
        except (OSError, RuntimeError, ValueError) as exc:
            self.close()
            raise SinkError(f"cannot open Rerun sink {spec.kind!r}: {exc}") from None

    def close(self) -> str:
        """Flush everything logged, close the sink (an ``.rrd`` gets its footer) and stop the server we own.

        Returns "" or, when the last flush failed (viewer gone), why; safe to call twice.
        """
        if self._closed:
            return ""
        self._closed = True
        problem = ""
        rec = getattr(self, "rec", None)
        if rec is not None:
            try:
                rec.flush(timeout_sec=10.0)
            except RuntimeError as exc:  # the viewer or server went away: nothing more can be delivered
                problem = f"last data not delivered to {self.viewer_url}: {exc}"
            finally:
                rec.disconnect()
        if self._proc is not None and self._proc.poll() is None:
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(self._proc.pid, sig)
                except ProcessLookupError:
                    break
                try:
                    self._proc.wait(5.0)
                    break
                except subprocess.TimeoutExpired:
                    continue
        return problem

    def __enter__(self) -> RerunStream:
        """Return the stream."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the stream."""
        self.close()
