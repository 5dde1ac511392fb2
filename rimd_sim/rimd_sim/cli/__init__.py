"""The ``rimd`` command: one console command with subcommands (verbs).

Each verb is a module with ``add_arguments(parser)`` and ``main(args) -> int``, in the manner of the
``ros2bag`` verbs, listed in :data:`VERBS`. A verb listed before its module exists answers, on stderr, that it
is not implemented (and what is missing, when its entry says), with exit status 2; it never prints fake output.

Rules for verb modules: keep the module import light (import rclpy, numpy and friends inside ``main``),
so that ``rimd --help`` stays fast and works even where a heavy dependency is broken; report a failure by
raising :class:`CommandError`, and let the libraries' errors through: every error of the family
(:mod:`rimd_sim.errors`) is rendered here, in :func:`main`, as one line (``rimd VERB: message``, exit status 1).
A verb does not catch an error to re-raise it as another or to print it; it catches one only to add what only
it knows (the option as typed, that the experiment itself ran).

Exit status: 0 success, 1 failure (any :class:`RimdError`, or an ``OSError`` such as an output directory that
cannot be made, in one line naming the file), 2 usage error (argparse) or not implemented yet, 3 an analysis ran
and wrote its files but some of its points lie outside the model's valid domain (:mod:`rimd_sim.model.validity`;
its last line says how many and which rules; ``--accept-invalid`` makes it 0), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

from rimd_sim import __version__
from rimd_sim.analysis import figures
from rimd_sim.runtime import collector

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
#: An analysis wrote its files, but some points lie outside the model's valid domain (docs/analyses.md).
EXIT_INVALID = 3
EXIT_INTERRUPTED = 130


# The product's one exception family (rimd_sim.errors): a verb raises CommandError (or lets a library's
# RimdError through) for a failure the user can act on; main() prints it as one line and exits 1.
from rimd_sim.errors import CommandError, RimdError  # noqa: E402, F401 - CommandError: the verbs' import


def error_line(verb: str, error: BaseException) -> str:
    """The one line ``rimd VERB`` prints on stderr for ``error`` (a :class:`RimdError` or an ``OSError``).

    An ``OSError`` names its file and the system's reason (``/out/x: Not a directory``), without the errno.
    A message of several lines is joined into one.
    """
    if isinstance(error, OSError) and error.strerror:
        files = [str(f) for f in (error.filename, error.filename2) if f is not None]
        text = ": ".join([" -> ".join(files), error.strerror] if files else [error.strerror])
    else:
        text = str(error) or type(error).__name__
    if "\n" in text:
        text = "; ".join(part.strip() for part in text.splitlines() if part.strip())
    return f"rimd {verb}: {text}"


def number(option: str, unit: str = "", *, ge: float | None = None, gt: float | None = None,
           le: float | None = None, lt: float | None = None, zero: str = "",
           integer: bool = False) -> Callable[[str], float]:
    """An argparse ``type`` for a numeric option: finite, within its bounds, refused naming the option as typed.

    The bounds are in the option's own unit (``--gap-mm`` in mm), and so is the refusal:
    ``--gap-mm 2400 refused: must be >= 0 and <= 50 mm``. ``zero``: 0 is also allowed and means that.
    """
    parts = [f"{op} {b:g}" for op, b in ((">=", ge), (">", gt), ("<=", le), ("<", lt)) if b is not None]
    rule = ("must be " + (f"0 ({zero}) or " if zero else "") + " and ".join(parts) + (f" {unit}" if unit else "")
            if parts else "must be a finite number")

    def convert(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} {text!r} refused: must be "
                                             + ("an integer" if integer else "a number")) from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{option} {text} refused: must be finite; {rule}")
        if zero and value == 0:
            return value
        if ((ge is not None and value < ge) or (gt is not None and value <= gt) or (le is not None and value > le)
                or (lt is not None and value >= lt)):
            raise argparse.ArgumentTypeError(f"{option} {text} refused: {rule}")
        return value

    convert.__name__ = "integer" if integer else "number"   # what argparse says for a value it cannot convert
    # For the tests that sweep every verb's options (mypy types no attribute of a function).
    convert.option, convert.rule = option, rule  # type: ignore[attr-defined]
    return convert


def count(option: str, minimum: int = 1, maximum: int | None = None) -> Callable[[str], int]:
    """An integer >= ``minimum`` (and <= ``maximum``), see :func:`number`."""
    return cast(Callable[[str], int], number(option, ge=minimum, le=maximum, integer=True))   # integer: int()


def simulator_parameter(option: str, name: str, *, scale: float = 1.0,
                        unit: str | None = None) -> Callable[[str], float]:
    """An option that sets the simulator parameter ``name``, possibly in another unit (``--gap-mm``: ``gap`` in mm).

    Its bounds are the parameter's own declaration (:mod:`rimd_sim.settings.config`), scaled, so the refusal names
    the option as typed, in its unit: ``--gap-mm 2400 refused: must be >= 0 and <= 50 mm``.
    """
    from rimd_sim.settings.config import PARAMETERS

    p = PARAMETERS[name]

    def scaled(bound: float | None) -> float | None:
        return None if bound is None else round(bound * scale, 12)

    zero = p.zero if isinstance(p.zero, str) else ("" if not p.zero else "allowed")
    return number(option, p.unit if unit is None else unit, ge=scaled(p.ge), gt=scaled(p.gt), le=scaled(p.le),
                  lt=scaled(p.lt), zero=zero)


def nonnegative_float(option: str, unit: str = "") -> Callable[[str], float]:
    """A number >= 0 (see :func:`number`)."""
    return number(option, unit, ge=0)


def positive_float(option: str, unit: str = "") -> Callable[[str], float]:
    """A number > 0 (see :func:`number`)."""
    return number(option, unit, gt=0)


def gap_mm(option: str = "--gap-mm") -> Callable[[str], float]:
    """The gap in mm, within the bounds of the simulator's ``gap`` (see :func:`simulator_parameter`)."""
    return simulator_parameter(option, "gap", scale=1e3, unit="mm")


#: The simulator's real_time_factor as an option: 0 (as fast as possible) or within [0.001, 1e6].
real_time_factor = number("--real-time-factor", zero="as fast as possible", ge=1e-3, le=1e6)


@dataclass(frozen=True)
class Verb:
    """One subcommand of ``rimd``.

    Attributes:
        name: The subcommand, as typed (``rimd <name>``).
        summary: One line for ``rimd --help``.
        module: Import path of the module providing ``add_arguments`` and ``main``; None while the verb is
            not implemented.
        missing: While ``module`` is None, what is missing, in a few words (said with the refusal; may be empty).
    """

    name: str
    summary: str
    module: str | None = None
    missing: str = ""

VERBS: tuple[Verb, ...] = (
    Verb("rig", "bring up the rig from config: recorder, Rerun bridge and simulator",
         "rimd_sim.cli.verbs.rig"),
    Verb("experiment", "stepped frequency sweep through /rig/set_motor_frequency, recorded",
         "rimd_sim.cli.verbs.experiment"),
    Verb("analyze", "analyse a recording (REC.mcap): impacts, peak force vs frequency, phase planes",
         "rimd_sim.cli.verbs.analyze"),
    Verb("identify", "identify the rig's parameters from a recording: a twin of that rig",
         "rimd_sim.cli.verbs.identify"),
    Verb("fit-table", "the parameter set that best reproduces a table of impact resonances (paper Table 1)",
         "rimd_sim.cli.verbs.fit_table"),
    Verb("fit-paper", "the parameter set that reproduces the paper's findings together: Table 1, forces, doubling",
         "rimd_sim.cli.verbs.fit_paper"),
    Verb("paper", "the paper's figures in its layout and validation.md: every published finding against the twin",
         "rimd_sim.cli.verbs.paper"),
    Verb("sweep", "simulated peak force F_i/mg versus frequency ratio for a gap, up, down or from rest",
         "rimd_sim.cli.verbs.sweep"),
    Verb("bifurcation", "bifurcation diagram: stroboscopic l sin(theta)/A0 versus frequency ratio, up, down, rest",
         "rimd_sim.cli.verbs.bifurcation"),
    Verb("continue", "continuation of periodic orbits in frequency (or a parameter): stability, period doubling, "
         "fold, Neimark-Sacker, grazing", "rimd_sim.cli.verbs.continuation"),
    Verb("peterka", "Peterka diagram: impact regimes (p impacts / n cycles) in the (frequency, gap) plane",
         "rimd_sim.cli.verbs.peterka"),
    Verb("map", "steady motion, peak force and impact velocity over any two parameters (mass x natural frequency, ...)",
         "rimd_sim.cli.verbs.map"),
    Verb("poincare", "phase plane, Poincare map and largest Lyapunov exponent of the simulated motion",
         "rimd_sim.cli.verbs.poincare"),
    Verb("basins", "basins of attraction of coexisting motions over initial (theta, theta')",
         "rimd_sim.cli.verbs.basins"),
    Verb("pulse", "one impact at a given velocity: force and acceleration at 1 MHz, double peak and ringing",
         "rimd_sim.cli.verbs.pulse"),
    Verb("faults", "run a fault scenario (SCENARIO.yaml) against a running rig through /rig/inject_fault",
         "rimd_sim.cli.verbs.faults"),
    Verb("motor", "set the running rig's motor frequency (FREQ Hz) and print its answer", "rimd_sim.cli.verbs.motor"),
    Verb("perturb", "add a velocity (V m/s) to the hammer of the running rig", "rimd_sim.cli.verbs.perturb"),
    Verb("inject", "inject one fault (CHANNEL KIND) into the running rig, now, after S s or at a time",
         "rimd_sim.cli.verbs.inject"),
    Verb("pause", "pause the running rig (simulation time frozen)", "rimd_sim.cli.verbs.trigger"),
    Verb("resume", "resume the paused rig", "rimd_sim.cli.verbs.trigger"),
    Verb("reset", "put the hammer back to its initial state (a new run on /rig/session)", "rimd_sim.cli.verbs.trigger"),
    Verb("clear-faults", "end every fault of the running rig and cancel the scheduled ones",
         "rimd_sim.cli.verbs.trigger"),
    Verb("status", "a live view of the running rig: rates, indices, gaps, lateness, motor, faults, impacts",
         "rimd_sim.cli.verbs.status"),
    Verb("rerun", "show a recording (REC.mcap) in the Rerun viewer, or save it as .rrd", "rimd_sim.cli.verbs.rerun"),
    Verb("replay", "replay a recording (REC) on its topics, alone or driven from Foxglove's timeline (--foxglove)",
         "rimd_sim.cli.verbs.replay"),
    Verb("crop", "a time window of a recording (REC) as a new rosbag2 MCAP recording, like ros2 bag convert",
         "rimd_sim.cli.verbs.crop"),
    Verb("node", "run one node of the rig (NAME), with --ros-args", "rimd_sim.cli.verbs.node"),
    Verb("info", "print the version and facts about the environment", "rimd_sim.cli.verbs.info"),
    Verb("warmup", "compile the physics once, ahead, into numba's cache (set-up runs it)", "rimd_sim.cli.verbs.warmup"),
)


def not_implemented_message(verb: Verb) -> str:
    """Return the line a verb without a module prints on stderr."""
    return f"rimd {verb.name}: not implemented yet" + (f" ({verb.missing})" if verb.missing else "")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the argument parser of ``rimd`` with one sub-parser per verb.

    ``only``: the verb about to run; the others get a sub-parser with their summary alone, without importing
    their modules (each imports what its options need: a study point or ``rimd --help`` then pays for one verb,
    not for all). ``None`` builds every verb's options (the docs generator, the tests).
    """
    parser = argparse.ArgumentParser(
        prog="rimd",
        description="Digital twin of the RIMD vibro-impact test rig (ROS 2 Jazzy).",
    )
    parser.add_argument("--version", action="version", version=f"rimd {__version__}")
    subparsers = parser.add_subparsers(dest="verb", metavar="<command>", title="commands")
    for verb in VERBS:
        if verb.module is None:
            sub = subparsers.add_parser(
                verb.name,
                help=f"{verb.summary} [not implemented yet]",
                description=f"{verb.summary}. {not_implemented_message(verb)}",
            )
            sub.add_argument("arguments", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
            sub.set_defaults(_main=_not_implemented_main(verb))
        elif only is not None and verb.name != only:
            subparsers.add_parser(verb.name, help=verb.summary, description=verb.summary)
        else:
            module = importlib.import_module(verb.module)
            sub = subparsers.add_parser(verb.name, help=verb.summary, description=verb.summary)
            module.add_arguments(sub)
            sub.set_defaults(_main=module.main)
    return parser


def _not_implemented_main(verb: Verb):
    def main(args: argparse.Namespace) -> int:
        del args
        print(not_implemented_message(verb), file=sys.stderr)
        return EXIT_USAGE

    return main


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``rimd`` with ``argv`` (default ``sys.argv[1:]``) and return the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # The verb is the first word that is not an option (``rimd`` itself takes only --help and --version).
    parser = build_parser(next((a for a in argv if not a.startswith("-")), ""))
    args = parser.parse_args(argv)
    if args.verb is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    try:
        return int(args._main(args) or EXIT_OK)
    except (RimdError, OSError) as error:   # the one place errors become lines: no verb translates or prints them
        print(error_line(args.verb, error), file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"rimd {args.verb}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def entry() -> int:
    """The ``rimd`` executable: :func:`main` in a process of its own, set for one.

    Its cycle collector (:mod:`rimd_sim.runtime.collector`: young objects collected less often, what the process
    has built frozen at the end so that its exit does not walk it again), and its figures drawn in a worker
    process started before the computation (:mod:`rimd_sim.analysis.figures`). A program that calls :func:`main`
    keeps its own collector and draws in its own process. An unknown piece in ``RIMD_PLAIN``
    (:mod:`rimd_sim.runtime.plain`) is refused here, exit status 2.
    """
    try:
        collector.configure()
    except RimdError as error:
        print(f"rimd: {error}", file=sys.stderr)
        return EXIT_USAGE
    figures.use_own_process()
    try:
        return main()
    finally:
        collector.keep_what_exists()


if __name__ == "__main__":
    sys.exit(entry())
