"""The ``haptic-bus`` command line: one subcommand per job.

Exit status, everywhere: 0 ok (passive, accepted, completed); 1 a drive or bus error, or "no"
(not passive, refused); 2 invalid input, checked before any bus or file is touched; 3 an
assumption of the gate broken at run time; 130 interrupted (Ctrl-C).  Every failure a user
can cause is one line on stderr, no traceback.  ``-v``/``-q`` set how much the libraries'
logging says (``-q``: errors only, so ``run`` also shows no live view, no summary and no ``ended:`` line;
``run --no-live``: its summary and ``ended:`` line without the view).
"""

from __future__ import annotations

import argparse
import functools
import logging
import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TextIO, cast

from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
from haptic_bus.app.arguments import (
    DAMPING_ALLOWED,
    EXIT_ASSUMPTION,
    EXIT_INTERRUPTED,
    EXIT_INVALID,
    EXIT_NO,
    EXIT_OK,
    SHARED_CONTEXTS,
    STIFFNESS_ALLOWED,
    OneLineParser,
    a_real,
    add_bus_arguments,
    add_command,
    add_verbosity,
    an_integer,
    bus_arguments,
    error_line,
    node_id,
    refuse_can_options_with_modbus,
    seconds,
    timeout,
)
from haptic_bus.app.early_stop import STOPPED_BEFORE_START, StoppedBeforeStart, handlers_kept, stop_at_once_on_sigterm, stop_noted
from haptic_bus.app.fault_cli import add_fault_reset_parser
from haptic_bus.app.folder_lock import own_folder
from haptic_bus.app.identify_cli import add_identify_parser
from haptic_bus.app.run_arguments import (
    add_link_arguments,
    add_output_arguments,
    add_pacing_arguments,
    as_flag,
    bus_log,
    one_axis_link,
    scheduling,
)
from haptic_bus.app.scan_cli import add_scan_parser
from haptic_bus.app.sdo_cli import add_sdo_parser
from haptic_bus.app.status_cli import add_status_parser
from haptic_bus.app.stdout_reader import ReaderMayGo
from haptic_bus.app.validate_cli import add_validate_parser
from haptic_bus.app.wall_check_cli import add_wall_check_parsers
from haptic_bus.console import LIBRARIES, log_to_stderr, logging_kept
from haptic_bus.validation import folder_path, ids_in_order, writable_folder

if TYPE_CHECKING:
    from haptic_bus.app.profiles import AxesProfile, Profile
    from haptic_bus.app.run_options import RunOptions



# --------------------------------------------------------------------------- shared arguments

def _add_no_plots(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-plots", action="store_true",
                        help="write the record and run.json, draw no pictures (saves seconds of matplotlib and of the "
                             "K-B plane's boundary; haptic-bus plot RUN_DIR draws them later, one axis or several)")


# --------------------------------------------------------------------------- handlers

def _plot(args: argparse.Namespace) -> int:
    from haptic_bus.app.run_folder import read_run_folder
    from haptic_bus.errors import ParameterError

    run_dir = folder_path("RUN_DIR", args.run_dir, context="plot")  # '' is no folder, not '.'
    out_dir = None if args.out is None else folder_path("--out", args.out, context="plot")  # '' is not RUN_DIR
    run = read_run_folder(run_dir)
    if not run.drawable:
        status, error = run.document.get("status"), run.document.get("error")
        said = f"run.json says {status!r}" + (f", {error}" if error else "")
        if status == "running":
            said += ": the run was killed or crashed before its first cycle"
        raise ParameterError("RUN_DIR", str(run.path), "a run folder with cycles recorded in every record, or the loop "
                             f"its gate judged (this run has neither: {said})", "plot")
    out = writable_folder("--out", out_dir or run.path, context="plot")
    notes = run.notes()  # before this command holds a folder: the lock it names is another run's
    # pictures into a run's own folder while that run goes on would be replaced by its own at its end, or cross them
    lock = own_folder(out, "RUN_DIR" if out == run.path else "--out", "plot")
    try:
        for note in notes:
            print(f"note: {note}")
        from haptic_bus.app.run_pictures import render_run

        print(f"wrote {', '.join(str(path) for path in render_run(run, out))}")
    finally:
        lock.release()
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    from haptic_bus.app.demo import format_demo, run_demo
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.run_options import StopRequest, exit_status

    profile = load_profile(args.profile) if args.profile else None
    stop = StopRequest()
    stop.install()  # SIGTERM (a service manager's stop) ends it "stopped", exit 0, as it ends run; Ctrl-C 130
    result = run_demo(args.out, profile, seconds=args.duration, plots=not args.no_plots, stop=stop)
    print(format_demo(result))
    return exit_status(result.summary.exit_reason)


def _run(args: argparse.Namespace) -> int:
    # First: a SIGTERM while the run prepares (seconds: gantry-3d's gate, ~5 s under load; the console script
    # installed the same handler before the command line was imported, haptic_bus.app.entry) ends it at
    # once, as Ctrl-C does then (Python's KeyboardInterrupt: one line, 130); the stop request takes
    # over once the run is about to touch the bus (_prepare_run's last step).
    previous = stop_at_once_on_sigterm()
    try:
        if stop_noted():  # while the console script imported the command line
            raise StoppedBeforeStart
        from haptic_bus.app.run_options import ended_line, exit_status, stopped_in_preflight
        from haptic_bus.app.runner import run  # its imports: a second or more under load
        from haptic_bus.errors import ParameterError

        profile, bus, options, links = _prepare_run(args)
    except StoppedBeforeStart:
        if not args.quiet:  # -q: errors only, and a stop before the start is none
            print(STOPPED_BEFORE_START)
        return EXIT_OK
    except BaseException:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)  # a refused command line ends as it did
        raise
    try:
        result = run(profile, bus, options, **links)
    except ParameterError as error:  # run() names its arguments; the command line names its options
        raise as_flag(error) from None
    summary = result.summary
    if summary is not None and not args.quiet:  # -q: errors only (the summary is in run.json)
        p, late = summary.compute_percentiles, summary.lateness_percentiles
        print(f"cycles {summary.cycles}; peak force {summary.peak_force:.4g} N; saturated {summary.saturated_cycles}; "
              f"port energy {summary.energy:.4g} J (least {summary.least_energy:.4g} J, below zero in "
              f"{summary.observer_active_cycles} cycles, counts rounding within {summary.rounding_bound:.2g} J); "
              f"passivity layer {summary.layer}: lowered {summary.layer_interventions} targets")
        if p:
            print(f"compute p50 {p['p50'] * 1e6:.1f} us, p99 {p['p99'] * 1e6:.1f} us; clock: {summary.clock}")
        if late:
            print(f"start lateness p50 {late['p50'] * 1e6:.1f} us, p99 {late['p99'] * 1e6:.1f} us, "
                  f"max {late['max'] * 1e6:.1f} us; overruns {summary.overruns}; late cycles {summary.late_cycles}")
    where = stopped_in_preflight(result.preflight_stopped)
    if not args.quiet:
        print(f"ended: {result.exit_reason}{where}; wrote {', '.join(str(f) for f in result.files)}")
    if result.error:
        print(f"haptic-bus run: {ended_line(result.exit_reason, result.error)}{where}", file=sys.stderr)
    return exit_status(result.exit_reason)


def _prepare_run(args: argparse.Namespace) -> tuple[Profile | AxesProfile, Any, RunOptions, dict[str, Any]]:
    """``run``'s profile, bus, :class:`~haptic_bus.app.run_options.RunOptions` and the link's keyword
    arguments, read and checked before anything is touched; last, the stop request is installed."""
    from haptic_bus.app.profiles import AxesProfile, load_profile
    from haptic_bus.app.run_links import DEFAULT_CONTROLLER_NODE_ID
    from haptic_bus.app.run_options import VIRTUAL, WALL, RunOptions, StopRequest

    logs_bus = bus_log(args, "run")
    profile = load_profile(args.profile)
    bus: Any
    unit_ids = None
    if isinstance(profile, AxesProfile):  # the node ids (or unit ids) come from [[axes]], or --unit-ids
        _refuse_single_axis_options(args)
        bus, node_id, unit_id = (args.modbus or bus_arguments(args)), None, None
        if args.unit_ids is not None:
            unit_ids = _typed_unit_ids(args, profile)
    else:
        address = one_axis_link(args, "run")
        bus, unit_id = (address.url, address.unit_id) if address.url is not None else (address.bus, None)
        node_id = None if address.url is not None else address.checked_node_id
    stop = StopRequest()
    out_dir = None if args.out is None else folder_path("--out", args.out, context="run")  # created once the bus is known
    options = RunOptions(args.duration, pacing=VIRTUAL if args.virtual_time else WALL, out_dir=out_dir,
                         start_in_contact=args.start_in_contact, live=not (args.quiet or args.no_live), stop=stop,
                         scheduling=scheduling(args.realtime),
                         reset_fault=args.reset_fault, bus_log=logs_bus, plots=not args.no_plots)
    links = {"node_id": node_id, "unit_id": unit_id, "unit_ids": unit_ids,
             "controller_node_id": args.controller_node_id or DEFAULT_CONTROLLER_NODE_ID}
    stop.install()  # from here SIGINT and SIGTERM ask the runner to stop (before enabling, or at a cycle boundary)
    return profile, bus, options, links


def _typed_unit_ids(args: argparse.Namespace, profile: AxesProfile) -> list[int]:
    """``run``'s ``--unit-ids`` read for ``profile``: one per axis, none twice on one server (a server
    each: unit 1 may serve each, but not twice where two ``--modbus`` name one server); a refusal names
    the text typed, not the list it reads as."""
    from haptic_bus.app.run_links import none_twice, shared_place
    from haptic_bus.errors import ParameterError

    unit_ids = ids_in_order("--unit-ids", args.unit_ids, UNIT_IDS, *UNIT_ID_RANGE, distinct=len(args.modbus) == 1)
    size = len(profile.axes)
    if len(unit_ids) != size:
        raise ParameterError("--unit-ids", args.unit_ids, f"{size} Modbus unit ids, one per axis ({profile.name} has "
                             f"{size} axes)")
    twice = shared_place(args.modbus, unit_ids) if len(args.modbus) == size else None
    if twice is not None:
        raise ParameterError("--unit-ids", args.unit_ids, f"{UNIT_IDS}, {none_twice(*twice)}")
    return unit_ids


def _refuse_single_axis_options(args: argparse.Namespace) -> None:
    """A multi-axis profile names its drives in ``[[axes]]`` (or ``--unit-ids`` over Modbus): the
    options that name one drive are refused (exit 2) before anything is touched, and so are CAN
    bus options beside ``--modbus`` and ``--unit-ids`` without it."""
    from haptic_bus.errors import ParameterError

    given = [(flag, value) for flag, value in (("--node-id", args.node_id), ("--unit-id", args.unit_id)) if value]
    if given:
        raise ParameterError(*given[0], "none with a multi-axis profile: the bus options (the node ids come from "
                             "[[axes]]), or --modbus URL (once, or once per axis) with --unit-ids", "run")
    if args.modbus:
        refuse_can_options_with_modbus(args, "run", ("controller_node_id",), "--unit-ids")
    elif args.unit_ids is not None:
        raise ParameterError("--unit-ids", args.unit_ids, "a Modbus option: give it with --modbus URL", "run")


def _upload(args: argparse.Namespace) -> int:
    """0 accepted; 1 refused by the gate, or no controller on the node (silent, or another device);
    2 invalid input, an object index the controller does not have included (asked before any write)."""
    from haptic_bus.errors import DriveError, Refusal
    from haptic_bus.node.upload import upload_walls
    from haptic_bus.validation import real_in_range, whole_in_range

    index = whole_in_range("object", args.object, 0, 255, context="upload")
    K = real_in_range("stiffness", args.stiffness, 0.0, 1e15, unit="N/m", context="upload")
    B = real_in_range("damping", args.damping, 0.0, 1e15, unit="N s/m", context="upload")
    bus = bus_arguments(args)
    try:
        print(upload_walls(bus, args.node_id, {index: (K, B)}, timeout=args.timeout))
    except Refusal as error:  # the node's 0x2002 text
        print(f"haptic-bus upload: {error.reasons[0]}", file=sys.stderr)
        return EXIT_NO
    except DriveError as error:  # no controller there: the node's own words, not "drive error"
        print(f"haptic-bus upload: {error.message}", file=sys.stderr)
        return EXIT_NO
    return EXIT_OK


def _report(args: argparse.Namespace) -> int:
    from haptic_bus.app.profiles import admit, one_axis_only, read_profile
    from haptic_bus.app.report import write_report

    profile = one_axis_only(read_profile(args.profile), "report")  # refused before its scene is judged
    admit(profile)
    for path in write_report(profile, writable_folder("--out", args.out, context="report")):
        print(f"wrote {path}")
    return EXIT_OK


def _bench(argv: Sequence[str], in_place: bool) -> int:
    """``haptic-bus bench ARGS`` becomes ``python -m haptic_bus.bench ARGS`` in this process (same
    pid, signals, streams and exit status): the bench sits above the application and measures it,
    so the application never imports the bench (POSIX exec).  A program's call (not ``in_place``) runs
    it as a child on the same streams and returns its status; the child has a process group of its own,
    so a Ctrl-C reaches it once, forwarded by this process (the bench writes the sections done, exit 130)."""
    sys.stdout.flush()
    sys.stderr.flush()
    command = [sys.executable, "-m", "haptic_bus.bench", *argv]
    if in_place:
        os.execv(sys.executable, command)
    import subprocess

    child = subprocess.Popen(command, process_group=0)
    try:
        return child.wait()
    except KeyboardInterrupt:
        child.send_signal(signal.SIGINT)
        return child.wait()


def _sim(argv: Sequence[str], in_place: bool) -> int:
    """``haptic-bus sim ARGS``, served by this process whoever called: it returns when its drive stops."""
    from haptic_bus.app.rig import sim_main

    return sim_main(list(argv))


# --------------------------------------------------------------------------- parser

def build_parser() -> OneLineParser:
    """The argument parser of every subcommand that haptic_bus itself parses."""
    from haptic_bus._version import __version__

    parser = OneLineParser(prog="haptic-bus", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"haptic-bus {__version__}")
    add_verbosity(parser, None)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    def command(name: str, help_text: str, handler: Callable[[argparse.Namespace], int]) -> argparse.ArgumentParser:
        return add_command(sub, name, help_text, handler)

    add_wall_check_parsers(sub)

    plot = command("plot", "draw a run folder's pictures again: timeline with events, force against position, "
                           "the K-B plane", _plot)
    plot.add_argument("run_dir", metavar="RUN_DIR", help="a folder haptic-bus run or demo wrote (run.json, record.csv)")
    plot.add_argument("--out", help="folder for the PNGs (default: RUN_DIR)")

    demo = command("demo", "simulated drive + controller on a virtual CAN bus, in virtual time", _demo)
    demo.add_argument("--out", default="haptic-bus-demo", help="output directory for PNGs, the CSV record and run.json")
    demo.add_argument("--profile", help="profile name or TOML path (default: the shipped default)")
    demo.add_argument("--duration", type=seconds, help="virtual seconds to run (default: 2, or a multi-axis hand's whole tour)")
    _add_no_plots(demo)

    run = command("run", "run a profile's controller against a drive on a CAN bus or over Modbus", _run)
    run.add_argument("profile", help="profile name or TOML path")
    add_link_arguments(run)
    run.add_argument("--duration", type=seconds, default=10.0, help="seconds to run")
    add_pacing_arguments(run)
    run.add_argument("--start-in-contact", choices=("refuse", "ramp"),
                     help="a start inside an object: refuse, or ramp the force in (default: the profile's [start])")
    add_output_arguments(run)
    _add_no_plots(run)
    run.add_argument("--no-live", action="store_true",
                     help="no live view and no progress lines (pre-flight, scaling): the summary and the ended: line "
                          "only, for a script (-q: not those either)")
    run.add_argument("--reset-fault", action="store_true",
                     help="before commissioning, reset a drive found in FAULT (as haptic-bus fault-reset does; logged "
                          "in run.json's events with the error code it had); without it a faulted drive is refused")

    upload = command("upload", "change a running controller's wall K and B over the bus (gated); exit 0 accepted, 1 refused "
                               "or no controller answered on the node, 2 invalid input (an object the scene lacks included)",
                     _upload)
    add_bus_arguments(upload)
    upload.add_argument("--node-id", type=node_id, required=True, help="the controller's CANopen node id")
    upload.add_argument("--object", type=an_integer("object", "an integer in [0, 255]"), required=True,
                        help="scene object index (0x2100 + index)")
    upload.add_argument("--stiffness", type=a_real("stiffness", STIFFNESS_ALLOWED), required=True, help="K, N/m")
    upload.add_argument("--damping", type=a_real("damping", DAMPING_ALLOWED), required=True, help="B, N s/m")
    upload.add_argument("--timeout", type=timeout, default=1.0,
                        help="SDO timeout, s (the commit waits for the gate's verdict, at least 30 s)")

    from haptic_bus.app.profiles_cli import add_profiles_parser

    add_profiles_parser(sub)

    add_identify_parser(sub)
    add_validate_parser(sub)
    add_scan_parser(sub)
    add_status_parser(sub)
    add_fault_reset_parser(sub)
    add_sdo_parser(sub)

    report = command("report", "the seed's Figs. 4-6 for a profile, as PNGs, plus a markdown summary", _report)
    report.add_argument("profile", help="profile name or TOML path")
    report.add_argument("--out", required=True, help="output directory")

    sub.add_parser("bench", help="run time against error, the bus against its limit (see: haptic-bus bench --help)",
                   add_help=False)
    sub.add_parser("sim", help="run the simulated CiA-402 drive (see: haptic-bus sim --help)", add_help=False)
    return parser


# commands that parse their own arguments, told whether they may take the process (``in_place``: not a program's call)
_PASS_THROUGH: dict[str, Callable[[Sequence[str], bool], int]] = {"sim": _sim, "bench": _bench}


def _configure_logging(verbose: int | None, quiet: bool | None) -> None:
    levels = {None: logging.WARNING, 0: logging.WARNING, 1: logging.INFO}
    level = logging.CRITICAL if quiet else levels.get(verbose, logging.DEBUG)
    log_to_stderr(level, "%(levelname)s %(name)s: %(message)s")
    library_level = {None: logging.CRITICAL, 0: logging.CRITICAL, 1: logging.WARNING}.get(verbose, logging.DEBUG)
    for name in LIBRARIES:  # their chatter ("Transfer aborted ...", "... not properly shut down") only on -v
        logging.getLogger(name).setLevel(library_level)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``haptic-bus``; returns the exit status.  A program's call (``argv`` given) gets
    SIGINT's and SIGTERM's handlers back as it had them (``run``, ``identify`` and ``validate`` install
    their stop request), and its logging as it had it (each command configures the root logger and
    the libraries' levels for its own output); the console script's process (``argv`` None) keeps the
    command's until it exits (:func:`~haptic_bus.app.early_stop.exiting`,
    :func:`~haptic_bus.app.early_stop.handlers_kept`, :func:`~haptic_bus.console.logging_kept`)."""
    if argv is None:
        sys.stdout = cast(TextIO, ReaderMayGo(sys.stdout))  # ``| head``: the command goes on to its end
        return _command(list(sys.argv[1:]))
    with handlers_kept(), logging_kept():
        return _command(list(argv), in_place=False)


def _command(argv: list[str], in_place: bool = True) -> int:
    """:func:`main` for ``argv``: the command's exit status (``in_place`` False: a program's call, which
    a pass-through command must return to)."""
    try:
        if argv and argv[0] in _PASS_THROUGH:
            return _PASS_THROUGH[argv[0]](argv[1:], in_place)
        try:
            args = _command_parser().parse_command(argv)
        except SystemExit as done:  # help (0), or a usage error (2) whose one line argparse has printed
            return int(done.code or 0)
        _configure_logging(args.verbose, args.quiet)
        return _dispatch(args)
    except KeyboardInterrupt:
        print("haptic-bus: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # a reader that stopped reading (| head): nothing failed here
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK


@functools.cache
def _command_parser() -> OneLineParser:
    """:func:`build_parser`'s parser, built once per process (10 ms; parsing leaves it as it was): what
    :func:`main` parses with, however often a process calls it (the plugin's and the tests' in-process runs)."""
    return build_parser()


def _dispatch(args: argparse.Namespace) -> int:
    from haptic_bus.errors import AssumptionBroken, DriveError, HapticBusError, ParameterError

    try:
        return int(args.handler(args))
    except ParameterError as error:  # a run's folder (run, demo, validate) names RunOptions.out_dir: said as --out
        print(error_line(args.command, as_flag(error) if error.context in SHARED_CONTEXTS else error), file=sys.stderr)
        return EXIT_INVALID
    except DriveError as error:
        print(f"haptic-bus {args.command}: drive error: {error}", file=sys.stderr)
        return EXIT_NO
    except AssumptionBroken as error:
        print(f"haptic-bus {args.command}: {error}", file=sys.stderr)
        return EXIT_ASSUMPTION
    except HapticBusError as error:  # a Refusal, or another error raised on purpose
        print(f"haptic-bus {args.command}: {error}", file=sys.stderr)
        return EXIT_NO

