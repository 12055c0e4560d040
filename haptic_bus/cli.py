"""The ``haptic-bus`` command line: one subcommand per job, exit 0 ok / 1 verdict "no" / 2 bad input."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Callable, Sequence

from haptic_bus.errors import HapticBusError
from haptic_bus.check_report import check_report, format_check
from haptic_bus.loop import WallLoop

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


def _check(args: argparse.Namespace) -> int:
    loop = WallLoop(args.mass, args.friction, args.period, args.stiffness, args.damping, args.delay)
    report = check_report(loop)
    print(json.dumps(report) if args.json else format_check(report))
    return EXIT_OK if report["passive"] else EXIT_NO


def _region(args: argparse.Namespace) -> int:
    from haptic_bus.plots import plot_region

    loop = WallLoop(args.mass, args.friction, args.period, 0.0, 0.0, args.delay)
    plot_region(args.png, loop.m, loop.b, loop.T, delay=loop.delay)
    print(f"wrote {args.png}")
    return EXIT_OK


def _sim(argv: Sequence[str]) -> int:
    from sim_drive.cli import main as sim_main

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

    sub.add_parser("sim", help="run the simulated CiA-402 drive (see: haptic-bus sim --help)", add_help=False)
    return parser


_PASS_THROUGH: dict[str, Callable[[Sequence[str]], int]] = {"sim": _sim}


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
        return EXIT_INVALID


if __name__ == "__main__":
    sys.exit(main())
