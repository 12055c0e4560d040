"""The ``haptic-bus`` command line: one subcommand per job, exit 0 ok / 1 verdict "no" / 2 bad input."""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import Callable, Sequence

from drives.bus_config import parse_bus_option
from drives.errors import DriveError, HapticBusError, ParameterError
from haptic_bus.analysis.check import check_loop, format_check
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.app.profiles_cli import add_profiles_parser
from haptic_bus.control.gate import GateRefusal

EXIT_OK, EXIT_NO, EXIT_INVALID = 0, 1, 2


class _OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_INVALID, f"{self.prog}: error: {message}\n")


def _add_device_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mass", type=float, required=True, help="handle mass m, kg")
    parser.add_argument("--friction", type=float, required=True, help="viscous friction b, N s/m")
    parser.add_argument("--period", type=float, required=True, help="sampling period T, s")
    parser.add_argument("--delay", type=float, default=0, help="loop delay d in whole samples (0: ideal, 1: CiA-402 sync)")


def _add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--interface", help="python-can interface (socketcan, virtual, udp_multicast, ...)")
    parser.add_argument("--channel", help="python-can channel (can0, vcan0, a multicast group, ...)")
    parser.add_argument("--bitrate", type=int, help="bit/s")
    parser.add_argument("--bus-option", type=parse_bus_option, action="append", default=[], metavar="KEY=VALUE",
                        help="extra python-can bus argument, e.g. port=43113 (repeatable)")


def _check(args: argparse.Namespace) -> int:
    loop = WallLoop(args.mass, args.friction, args.period, args.stiffness, args.damping, args.delay)
    report = check_loop(loop)
    print(json.dumps(report.to_dict()) if args.json else format_check(report))
    return EXIT_OK if report.passive else EXIT_NO


def _region(args: argparse.Namespace) -> int:
    from haptic_bus.app.plots import plot_region

    loop = WallLoop(args.mass, args.friction, args.period, 0.0, 0.0, args.delay)
    plot_region(args.png, loop.m, loop.b, loop.T, delay=loop.delay)
    print(f"wrote {args.png}")
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    from haptic_bus.app.demo import format_demo, run_demo
    from haptic_bus.app.profiles import load_profile

    profile = load_profile(args.profile) if args.profile else None
    result = run_demo(args.out, profile, seconds=args.duration)
    print(format_demo(result))
    return EXIT_NO if result.summary.error else EXIT_OK


def _bus_arguments(args: argparse.Namespace) -> dict:
    bus = dict(args.bus_option)
    for key in ("interface", "channel", "bitrate"):
        if getattr(args, key) is not None:
            bus[key] = getattr(args, key)
    return bus


def _run(args: argparse.Namespace) -> int:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.runner import RunOptions, install_stop_signals, run_canopen, run_modbus

    profile = load_profile(args.profile)
    options = RunOptions(args.duration, realtime=not args.virtual_time,
                         out_dir=None if args.out is None else pathlib.Path(args.out))
    install_stop_signals(options.stop)
    if args.modbus:
        summary, _ = run_modbus(profile, args.modbus, args.unit_id, options)
    elif args.node_id is None:
        raise ParameterError("--node-id", None, "the drive's CANopen node id 1..127 (or give --modbus URL)", "run")
    else:
        summary, _ = run_canopen(profile, _bus_arguments(args), args.node_id, options, args.controller_node_id)
    p, late = summary.compute_percentiles, summary.lateness_percentiles
    print(f"cycles {summary.cycles}; peak force {summary.peak_force:.4g} N; saturated {summary.saturated_cycles}; "
          f"observer: interface energy {summary.interface_energy:.4g} J (below zero in {summary.observer_active_cycles} "
          f"cycles), wall {summary.wall_energy:.4g} J")
    if p:
        print(f"compute p50 {p['p50'] * 1e6:.1f} us, p99 {p['p99'] * 1e6:.1f} us; clock: {summary.clock}")
    if late:
        print(f"start lateness p50 {late['p50'] * 1e6:.1f} us, p99 {late['p99'] * 1e6:.1f} us, "
              f"max {late['max'] * 1e6:.1f} us; overruns {summary.overruns}")
    if summary.error:
        print(f"haptic-bus run: error: {summary.error}", file=sys.stderr)
        return EXIT_NO
    return EXIT_OK


def _upload(args: argparse.Namespace) -> int:
    from haptic_bus.control.node import UploadRefused, upload_walls
    from haptic_bus.validation import real_in_range, whole_in_range

    index = whole_in_range("object", args.object, 0, 255, context="upload")
    K = real_in_range("stiffness", args.stiffness, 0.0, 1e15, unit="N/m", context="upload")
    B = real_in_range("damping", args.damping, 0.0, 1e15, unit="N s/m", context="upload")
    try:
        print(upload_walls(_bus_arguments(args), args.node_id, {index: (K, B)}, timeout=args.timeout))
    except UploadRefused as error:
        print(f"haptic-bus upload: {error.reason}", file=sys.stderr)
        return EXIT_NO
    return EXIT_OK


def _report(args: argparse.Namespace) -> int:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.report import write_report

    for path in write_report(load_profile(args.profile), args.out):
        print(f"wrote {path}")
    return EXIT_OK


def _bench(argv: Sequence[str]) -> int:
    from haptic_bus.bench import main as bench_main

    return bench_main(list(argv))


def _sim(argv: Sequence[str]) -> int:
    from haptic_bus.app.rig import sim_main

    return sim_main(list(argv))


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand that haptic_bus itself parses."""
    parser = _OneLineParser(prog="haptic-bus", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_OneLineParser)

    check = sub.add_parser("check", help="judge one wall loop's passivity")
    _add_device_arguments(check)
    check.add_argument("--stiffness", type=float, required=True, help="wall stiffness K, N/m")
    check.add_argument("--damping", type=float, required=True, help="wall damping B, N s/m")
    check.add_argument("--json", action="store_true", help="one JSON object on stdout")
    check.set_defaults(handler=_check)

    region = sub.add_parser("region", help="write the seed's Fig. 4 (alpha-beta passive regions) as PNG")
    _add_device_arguments(region)
    region.add_argument("--png", required=True, help="output PNG file")
    region.set_defaults(handler=_region)

    demo = sub.add_parser("demo", help="simulated drive + controller on a virtual CAN bus, in virtual time")
    demo.add_argument("--out", default="haptic-bus-demo", help="output directory for PNGs and the CSV record")
    demo.add_argument("--profile", help="profile name or TOML path (default: the shipped default)")
    demo.add_argument("--duration", type=float, default=2.0, help="virtual seconds to run")
    demo.set_defaults(handler=_demo)

    run = sub.add_parser("run", help="run a profile's controller against a drive on a CAN bus")
    run.add_argument("profile", help="profile name or TOML path")
    _add_bus_arguments(run)
    run.add_argument("--node-id", type=int, help="the drive's CANopen node id")
    run.add_argument("--modbus", metavar="URL", help="a Modbus drive instead: tcp://HOST:PORT or rtu:/dev/ttyUSB0")
    run.add_argument("--unit-id", type=int, default=1, help="Modbus unit id")
    run.add_argument("--duration", type=float, default=10.0, help="seconds to run")
    run.add_argument("--controller-node-id", type=int, default=127,
                     help="this controller's CANopen node id: its heartbeat, which the drive watches, and gated wall uploads")
    run.add_argument("--virtual-time", action="store_true", help="lock-step with a simulated drive (no pacing)")
    run.add_argument("--out", help="directory for the CSV record")
    run.set_defaults(handler=_run)

    upload = sub.add_parser("upload", help="change a running controller's wall K and B over the bus (gated)")
    _add_bus_arguments(upload)
    upload.add_argument("--node-id", type=int, required=True, help="the controller's CANopen node id")
    upload.add_argument("--object", type=int, required=True, help="scene object index (0x2100 + index)")
    upload.add_argument("--stiffness", type=float, required=True, help="K, N/m")
    upload.add_argument("--damping", type=float, required=True, help="B, N s/m")
    upload.add_argument("--timeout", type=float, default=1.0, help="SDO timeout, s")
    upload.set_defaults(handler=_upload)

    add_profiles_parser(sub)

    report = sub.add_parser("report", help="the seed's Figs. 4-6 for a profile, as PNGs, plus a markdown summary")
    report.add_argument("profile", help="profile name or TOML path")
    report.add_argument("--out", required=True, help="output directory")
    report.set_defaults(handler=_report)

    sub.add_parser("bench", help="run time against error, the bus against its limit (see: haptic-bus bench --help)",
                   add_help=False)
    sub.add_parser("sim", help="run the simulated CiA-402 drive (see: haptic-bus sim --help)", add_help=False)
    return parser


_PASS_THROUGH: dict[str, Callable[[Sequence[str]], int]] = {"sim": _sim, "bench": _bench}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``haptic-bus``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in _PASS_THROUGH:
        return _PASS_THROUGH[argv[0]](argv[1:])
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except HapticBusError as error:
        print(f"haptic-bus {args.command}: error: {error}", file=sys.stderr)
        return EXIT_NO if isinstance(error, GateRefusal) else EXIT_INVALID
    except DriveError as error:
        print(f"haptic-bus {args.command}: drive error: {error}", file=sys.stderr)
        return EXIT_NO


if __name__ == "__main__":
    sys.exit(main())
