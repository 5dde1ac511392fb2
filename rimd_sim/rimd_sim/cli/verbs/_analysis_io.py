"""Shared plumbing of the analysis verbs: argument checks, progress on stderr and the times of their last line.

The files they write (CSV, strict JSON, parameter files) come from the library, :mod:`rimd_sim.analysis.outputs`;
its writers are re-exported here for the verbs.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from rimd_sim.analysis.outputs import (  # noqa: F401 - re-exported
    jsonable,
    write_columns,
    write_csv,
    write_json,
    write_summary,
)
from rimd_sim.cli import CommandError

#: ``gap`` of :func:`add_model_arguments`: the gap is the configuration's unless ``--gap-mm`` is given.
CONFIG_GAP = "config"


def add_model_arguments(parser, out: str, *, gap: float | str | None = None,
                        f_range: tuple[float, float] | None = None, f_step: float | None = None,
                        gap_note: str = "") -> None:
    """The options every simulation verb shares, each defined once.

    ``--gap-mm`` (when ``gap`` is given: :data:`CONFIG_GAP`, the configuration's gap, or a verb's own default in
    mm, a paper figure's), ``--f-min``/``--f-max`` (``f_range``), ``--f-step``, ``--config`` and ``--out``
    (default ``out``). Read the configuration with :func:`load_model_config`.
    """
    from rimd_sim.cli import gap_mm

    if gap is not None:
        default = ("the configuration's (0 in config/rimd.yaml)" if gap == CONFIG_GAP
                   else f"{gap:g}, whatever the configuration's")
        parser.add_argument("--gap-mm", type=gap_mm(), default=None, help=f"gap (mm), default {default}{gap_note}")
        parser.set_defaults(verb_gap_mm=gap)
    add_frequency_grid(parser, f_range, f_step)
    add_config_arguments(parser)
    parser.add_argument("--out", type=Path, default=Path(out), help="output directory")


def parameter_setting(text: str) -> tuple[str, Any]:
    """``NAME=VALUE`` of ``--set``, the value typed.

    A number as Python reads one (``1.8``, ``1e-4``: YAML 1.1 reads the latter as text), else as YAML does
    (``hertz``, ``true``, ``[a, b]``).
    """
    import argparse

    import yaml

    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name or not value.strip():
        raise argparse.ArgumentTypeError(f"--set {text!r} refused: must be NAME=VALUE, for example "
                                         "natural_frequency=1.8 or contact.model=hertz")
    for number in (int, float):   # 1e-4 is a number here (YAML 1.1 would read it as text)
        try:
            return name, number(value)
        except ValueError:
            pass
    try:
        parsed = yaml.safe_load(value)
    except yaml.YAMLError:
        parsed = value
    return name, parsed


def add_config_arguments(parser, help_text: str = "ROS parameter YAML (default config/rimd.yaml)") -> None:
    """``--config FILE`` and ``--set NAME=VALUE`` (repeatable): the configuration, read by :func:`read_config`."""
    parser.add_argument("--config", type=Path, default=None, help=help_text)
    parser.add_argument("--set", dest="settings", action="append", type=parameter_setting, default=[],
                        metavar="NAME=VALUE",
                        help="a parameter over the file's, named as in the file with dots (mass=0.2, "
                             "contact.stiffness=6e6); repeatable; checked as the file is")


def read_config(args, extra: dict | None = None):  # SimConfig
    """``--config`` with every ``--set`` over it (then ``extra``), validated as a parameter file is.

    Raises:
        ConfigError: For an unknown name or a refused value, naming it (and the closest names).
    """
    from rimd_sim.settings.config import load_config

    overrides = dict(getattr(args, "settings", None) or [])
    overrides.update(extra or {})
    return load_config(args.config, overrides or None)


def load_model_config(args):  # SimConfig
    """The verb's configuration: ``--config`` and ``--set``, with the gap of ``--gap-mm`` (or the verb's default gap).

    Sets ``args.gap_mm`` to the gap used (mm), for the verb's titles and files.
    """
    given = getattr(args, "gap_mm", None)
    verb_default = getattr(args, "verb_gap_mm", None)
    config = read_config(args)
    if given is None and verb_default not in (None, CONFIG_GAP):
        if args.config is not None and config.rig.gap != verb_default * 1e-3:
            print(f"note: gap {verb_default:g} mm, this verb's default, instead of the configuration's "
                  f"{config.rig.gap * 1e3:g} mm (give --gap-mm to choose)", file=sys.stderr)
        given = verb_default
    if given is not None:
        config = config.with_parameters({"gap": given * 1e-3})
    args.gap_mm = config.rig.gap * 1e3
    return config


def add_frequency_grid(parser, f_range: tuple[float, float] | None, f_step: float | None, *,
                       words: tuple[str, str, str] = ("lowest motor frequency", "highest motor frequency",
                                                      "frequency step")) -> None:
    """``--f-min``/``--f-max`` (when ``f_range`` is given) and ``--f-step`` (``f_step``), in Hz, positive."""
    from rimd_sim.cli import positive_float

    low, high = f_range if f_range is not None else (None, None)
    for option, default, word in zip(("--f-min", "--f-max", "--f-step"), (low, high, f_step), words, strict=True):
        if default is not None:
            parser.add_argument(option, type=positive_float(option, "Hz"), default=default,
                                help=f"{word} (Hz), default {default:g}")


def add_map_arguments(parser, transient: int) -> None:
    """The options of the maps that classify each trajectory (``rimd peterka``, ``rimd basins``).

    The cycles up to the cap, the early stop, the worker processes and the Dask scheduler.
    """
    from rimd_sim.cli import count

    parser.add_argument("--transient-cycles", type=count("--transient-cycles", 0), default=transient,
                        help=f"cycles dropped first at the cap, default {transient} (a settled motion stops sooner)")
    parser.add_argument("--measure-cycles", type=count("--measure-cycles", 6), default=72,
                        help="cycles classified at the cap, default 72")
    parser.add_argument("--fixed-length", action="store_true", help="run every trajectory to the cap (no early stop)")
    parser.add_argument("--workers", type=count("--workers"), default=None, help="processes (default: all cores)")
    add_scheduler_argument(parser)


def add_accept_invalid_argument(parser) -> None:
    """``--accept-invalid``: exit 0 even when some points lie outside the model's valid domain."""
    parser.add_argument("--accept-invalid", action="store_true",
                        help="exit 0 even when some points lie outside the model's valid domain (they stay marked "
                             "in the files; default: exit status 3)")


def validity_exit(verb: str, sentence: str, accept: bool, where: str) -> int:
    """Print the valid domain's last line of ``rimd VERB`` and return the exit status.

    ``sentence``: :meth:`rimd_sim.model.validity.ValidityDomain.sentence` (empty when every point is valid);
    ``where``: where the outputs mark the points (``the invalid_rule column of sweep.csv``). Returns 0 when
    every point is valid or ``accept`` (``--accept-invalid``), else :data:`rimd_sim.cli.EXIT_INVALID` (3).
    """
    from rimd_sim.cli import EXIT_INVALID

    if not sentence:
        return 0
    print(f"rimd {verb}: {sentence}: see {where}" + (" (accepted: --accept-invalid)" if accept else ""), flush=True)
    return 0 if accept else EXIT_INVALID


def add_scheduler_argument(parser) -> None:
    """``--scheduler tcp://HOST:PORT``: run the tasks on a Dask cluster (docs/analyses.md)."""
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run the tasks on this Dask scheduler (default: $RIMD_DASK_SCHEDULER, else local "
                             "processes)")


def check_range(name: str, lo: float, hi: float, *, allow_zero: bool = False, unit: str = "") -> None:
    """Refuse a range unless ``0 < lo <= hi`` (``0 <= lo`` with ``allow_zero``), naming the options and values.

    The options are ``--{name}-min{unit}`` and ``--{name}-max{unit}`` (``unit`` for example ``-mm``).
    """
    lo_opt, hi_opt = f"--{name}-min{unit}", f"--{name}-max{unit}"
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise CommandError(f"{lo_opt} {lo:g} / {hi_opt} {hi:g} refused: must be finite")
    if lo < 0 or (lo == 0 and not allow_zero):
        raise CommandError(f"{lo_opt} {lo:g} refused: must be {'>= 0' if allow_zero else '> 0'}")
    if lo > hi:
        raise CommandError(f"{lo_opt} {lo:g} > {hi_opt} {hi:g}: need min <= max")


def check_positive(option: str, value: float, *, minimum: float = 0.0, inclusive: bool = False) -> None:
    """Refuse ``value`` unless it is finite and above ``minimum`` (or equal to it with ``inclusive``)."""
    ok = math.isfinite(value) and (value >= minimum if inclusive else value > minimum)
    if not ok:
        rule = f">= {minimum:g}" if inclusive else f"> {minimum:g}"
        raise CommandError(f"{option} {value!r} refused: must be {rule}")


#: Seconds between two progress lines when stderr is not a terminal (a log file, CI, a test capturing it).
LOG_INTERVAL = 30.0

_BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt}{unit} [{elapsed}<{remaining}, {rate_noinv_fmt}]"
_LINE_FORMAT = "{desc}: {n_fmt}/{total_fmt}{unit} [{elapsed}<{remaining}, {rate_noinv_fmt}]"
_LAST_LINE_FORMAT = "{desc}: {n_fmt}/{total_fmt}{unit} in {elapsed_s:.1f} s ({rate_noinv_fmt})"


class Progress:
    """The ``progress(done, total)`` callable the analyses call, shown on stderr with tqdm.

    On a terminal: a tqdm bar rewritten in place (count, rate, time left), left on screen when the work is
    done. When stderr is not a terminal: no bar and no carriage returns, but whole lines in tqdm's format,
    one every :data:`LOG_INTERVAL` seconds while the work runs and one at the end, for example
    ``rimd peterka: 31/31 gap rows in 19.8 s (1.57 gap rows/s)``: the time of the units counted, from the creation
    of the object (create it when the work starts) to the last unit done; the verb's files come after (its last
    line times them: :class:`VerbClock`). The bar appears at the first call (only then is the total
    known) and ends when ``done`` reaches ``total`` or at :meth:`close`, whichever comes first. Nothing is
    printed if the work never reported progress (a refusal before it started stays one line).
    """

    def __init__(self, verb: str, what: str, *, file: TextIO | None = None, interval: float = LOG_INTERVAL) -> None:
        """Report ``rimd VERB``'s progress in units of ``what`` (plural, e.g. "gap rows") on ``file``."""
        self.desc = f"rimd {verb}"
        self.unit = f" {what}"
        self.interval = interval
        self._file = file
        self._bar: Any = None   # a tqdm bar (tqdm has no type annotations)
        self._t0 = self._last_line = time.monotonic()
        self._started = False
        self._done = 0
        self._total = 0
        self._closed = False

    def __call__(self, done: int, total: int) -> None:
        """Record that ``done`` of ``total`` units are finished."""
        if self._closed:
            return
        now = time.monotonic()
        if not self._started:
            self._start(total)
        self._done, self._total = min(done, total), total
        if self._bar is not None:
            self._bar.total = total
            self._bar.update(self._done - self._bar.n)
        elif self._done < total and now - self._last_line >= self.interval:
            self._print(_LINE_FORMAT, now)
            self._last_line = now
        if self._done >= total:
            self.close()

    def close(self) -> None:
        """End the bar (or print the last line); safe to call twice, and a no-op if nothing started."""
        if self._closed or not self._started:
            self._closed = True
            return
        self._closed = True
        if self._bar is not None:
            self._bar.close()
        else:
            self._print(_LAST_LINE_FORMAT, time.monotonic())

    def __enter__(self) -> Progress:
        """Use as ``with progress_printer(...) as progress:`` to close the bar however the work ends."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bar."""
        self.close()

    def _start(self, total: int) -> None:
        from tqdm import tqdm

        self._started = True
        self._file = self._file if self._file is not None else sys.stderr  # sys.stderr of now, not of import
        if _is_terminal(self._file):
            self._bar = tqdm(total=total, desc=self.desc, unit=self.unit, file=self._file, dynamic_ncols=True,
                             leave=True, bar_format=_BAR_FORMAT)
            # Elapsed time, rate and ETA from the start of the work, not from its first report.
            self._bar.start_t -= time.monotonic() - self._t0

    def _print(self, bar_format: str, now: float) -> None:
        from tqdm import tqdm

        line = tqdm.format_meter(self._done, self._total, now - self._t0, prefix=self.desc, unit=self.unit,
                                 bar_format=bar_format)
        line = " ".join(line.split()).replace("( ", "(")  # tqdm pads the rate to 5 characters
        print(line, file=self._file, flush=True)


def _is_terminal(file: TextIO) -> bool:
    """Whether ``file`` is a terminal with a size (tqdm shows nothing on a pseudo-terminal of 0 columns or rows)."""
    try:
        size = os.get_terminal_size(file.fileno())
        return file.isatty() and size.columns > 0 and size.lines > 0
    except (AttributeError, OSError, ValueError):
        return False


class VerbClock:
    """The wall times an analysis verb's last line gives: what it computed, its files, and the whole verb.

    Make it first thing in the verb's ``main`` (the verb's start); call :meth:`writing` when the computation is
    over and the verb starts writing its files; after the last file (its figure included) is written,
    :meth:`times` gives the clause, for example ``map computed in 56.1 s on 2 process(es), files written in
    0.8 s, 57.9 s in all``:

    * the computation's clause, the verb's words (``map computed in 56.1 s on 2 process(es)``): the analysis' own
      wall time, which ``summary.json`` holds as ``wall_seconds``;
    * ``files written in``: from :meth:`writing` to the files written (tables, arrays, summary, figure);
    * ``in all``: from the verb's start to the files written: the imports its ``main`` makes (numba, matplotlib),
      reading the configuration, the computation and the files. Not counted: the interpreter's start and the
      imports before the verb's ``main`` runs, nor the exit (a benchmark times the process, benchmarks/bench_wall.py).

    Each time is rounded to 0.1 s, so the parts may not add up to the whole to the last digit.
    """

    def __init__(self) -> None:
        """Start the clock: the verb's start."""
        self._start = time.perf_counter()
        self._writing: float | None = None

    def writing(self) -> None:
        """Mark the end of the computation: the verb starts writing its files."""
        self._writing = time.perf_counter()

    def times(self, computed: str) -> str:
        """``COMPUTED, files written in B s, C s in all`` (the class docstring), timed now.

        Before :meth:`writing` was called, the files count as written in no time.
        """
        now = time.perf_counter()
        files = 0.0 if self._writing is None else now - self._writing
        return f"{computed}, files written in {files:.1f} s, {now - self._start:.1f} s in all"


def progress_printer(verb: str, what: str) -> Progress:
    """A ``progress(done, total)`` callable for ``rimd VERB``, counting ``what``, on stderr (see :class:`Progress`)."""
    return Progress(verb, what)


def class_runs(frequencies, labels) -> list[dict]:
    """Consecutive frequencies of the same class as ``{"class", "f_from_hz", "f_to_hz"}`` runs."""
    runs: list[dict] = []
    for f, label in zip(frequencies, labels, strict=True):
        if runs and runs[-1]["class"] == label:
            runs[-1]["f_to_hz"] = float(f)
        else:
            runs.append({"class": label, "f_from_hz": float(f), "f_to_hz": float(f)})
    return runs
