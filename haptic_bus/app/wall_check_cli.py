"""``haptic-bus check`` and ``haptic-bus region``: one wall loop judged, and the seed's Fig. 4 drawn.

    haptic-bus check --mass M --friction B --period T --stiffness K --damping B_w [--delay D] [--velocity MODEL]
                     [--position-resolution M [--coulomb N]] [--transmission STIFFNESS:DAMPING:MOTOR_MASS] [--json]
    haptic-bus region --mass M --friction B --period T [--delay D] [--velocity MODEL] --png FILE [--mark K,B ...]

Both describe the loop by the same device arguments (the handle's ``m`` kg and ``b`` N s/m, ``T`` s, the
loop delay in samples and the velocity model).  Exit status: ``check`` 0 passive, 1 not passive; ``region``
0 once the PNG is written; both 2 for invalid input, before any file is touched.
"""

from __future__ import annotations

import argparse
import pathlib

from haptic_bus.app.arguments import (
    DAMPING_ALLOWED,
    DELAY_ALLOWED,
    EXIT_NO,
    EXIT_OK,
    FRICTION_ALLOWED,
    MASS_ALLOWED,
    PERIOD_ALLOWED,
    STIFFNESS_ALLOWED,
    a_real,
    add_command,
    number,
)
from haptic_bus.errors import ParameterError
from haptic_bus.validation import writable_file


def add_wall_check_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Register ``check`` and ``region`` on ``subparsers``; each sets ``handler``."""
    check = add_command(subparsers, "check", "judge one wall loop's passivity", _check)
    _add_device_arguments(check)
    check.add_argument("--stiffness", type=a_real("stiffness", STIFFNESS_ALLOWED), required=True, help="wall stiffness K, N/m")
    check.add_argument("--damping", type=a_real("damping", DAMPING_ALLOWED), required=True, help="wall damping B, N s/m")
    check.add_argument("--json", action="store_true", help="one JSON object on stdout")
    check.add_argument("--position-resolution", type=number("--position-resolution", 0.0, 1e6, "m"), metavar="M",
                       help="encoder resolution Delta, m per 0x6064 increment: judge the quantisation condition too "
                            "(average velocity: Coulomb friction >= K Delta/2 + B Delta/T, any delay)")
    check.add_argument("--coulomb", type=number("--coulomb", 0.0, 1e6, "N"), metavar="N",
                       help="the handle's Coulomb friction f_c, N, for the quantisation condition (only with "
                            "--position-resolution; 0 N when not given)")
    check.add_argument("--transmission", metavar="STIFFNESS:DAMPING:MOTOR_MASS",
                       help="judge a two-mass device: the handle (--mass, --friction) coupled by a spring N/m and a "
                            "damper N s/m to a motor-side mass kg, where the drive senses and applies the torque "
                            "(e.g. 20000:2:0.3)")

    region = add_command(subparsers, "region", "write the seed's Fig. 4 (alpha-beta passive regions) as PNG",
                         _region)
    _add_device_arguments(region)
    region.add_argument("--png", required=True, help="output PNG file (.png is added if missing)")
    region.add_argument("--mark", type=_mark, action="append", metavar="K,B",
                        help="mark the wall K N/m, B N s/m on the plane, with the exact verdict (repeatable)")


def _add_device_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mass", type=a_real("mass", MASS_ALLOWED), required=True, help="handle mass m, kg")
    parser.add_argument("--friction", type=a_real("friction", FRICTION_ALLOWED), required=True, help="viscous friction b, N s/m")
    parser.add_argument("--period", type=a_real("period", PERIOD_ALLOWED), required=True, help="sampling period T, s")
    parser.add_argument("--delay", type=a_real("delay", DELAY_ALLOWED), default=0,
                        help="loop delay D in samples, real in [0, 1000] (0: the seed's ideal loop, 1: a CiA-402 "
                             "synchronous cycle, 0.3: torque applied on reception 0.3 T after SYNC)")
    parser.add_argument("--velocity", default="point", metavar="MODEL",
                        help="what the drive's velocity is: point (v at SYNC, the seed's assumption), average "
                             "(encoder difference over T, most drives), window:SECONDS (difference over a shorter "
                             "window), lowpass:SECONDS (first-order filter)")


def _check(args: argparse.Namespace) -> int:
    import json

    from haptic_bus.analysis.check import check_passivity, format_check

    if args.coulomb is not None and args.position_resolution is None:
        raise ParameterError("--coulomb", args.coulomb, "with --position-resolution M: only the quantisation condition "
                             "uses it")
    if args.transmission is not None:
        if args.position_resolution is not None:
            raise ParameterError("--position-resolution", args.position_resolution,
                                 "no --transmission with it: the quantisation condition is derived for a rigid handle")
        return _check_two_mass(args)
    report = check_passivity(args.mass, args.friction, args.period, args.stiffness, args.damping, args.delay,
                             args.velocity, out_of_band=True, position_resolution=args.position_resolution,
                             coulomb=0.0 if args.coulomb is None else args.coulomb)  # named as the user typed them
    print(json.dumps(report.to_dict()) if args.json else format_check(report))
    return EXIT_OK if report.passive else EXIT_NO


def _check_two_mass(args: argparse.Namespace) -> int:
    import json

    from haptic_bus.analysis.transmission import Transmission
    from haptic_bus.analysis.two_mass_check import check_two_mass, format_two_mass

    report = check_two_mass(args.mass, args.friction, args.period, args.stiffness, args.damping, args.delay,
                            args.velocity, Transmission.parse(args.transmission))
    print(json.dumps(report.to_dict()) if args.json else format_two_mass(report))
    return EXIT_OK if report.passive else EXIT_NO


def _mark(text: str) -> tuple[float, float]:
    """``K,B`` (N/m, N s/m), both finite and > 0 (a point of the alpha-beta plane)."""
    parts = text.split(",")
    try:
        K, B = (float(part) for part in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not K,B (two numbers: N/m, N s/m)") from None
    if not (0 < K < float("inf") and 0 < B < float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: K and B must be finite and > 0 (alpha = B/(KT) and beta = b/B "
                                         "are points of the plane only then)")
    return K, B


def _region(args: argparse.Namespace) -> int:
    from haptic_bus.analysis.loop import WallLoop
    from haptic_bus.analysis.velocity import VelocityModel

    loop = WallLoop(args.mass, args.friction, args.period, 0.0, 0.0, args.delay, VelocityModel.parse(args.velocity))
    marks = [loop.with_wall(K, B) for K, B in args.mark or []]
    path = pathlib.Path(args.png)
    if not path.name:  # '', '.' or '/': with_name raised ValueError, a traceback
        raise ParameterError("--png", args.png, "a PNG file's path (empty: none given)", "region")
    if path.suffix.lower() != ".png":
        path = path.with_name(path.name + ".png")
    writable_file("--png", path, context="region")  # before the minutes of work, not after
    from haptic_bus.app.plots import plot_region

    print(f"wrote {plot_region(path, loop.m, loop.b, loop.T, delay=loop.delay, velocity=loop.velocity, marks=marks)}")
    return EXIT_OK
