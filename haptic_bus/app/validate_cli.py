"""``haptic-bus validate PROFILE``: does the closed loop on the device behave as the profile's model predicts?

    haptic-bus validate PROFILE --interface I --channel C --node-id N [--controller-node-id M]
    haptic-bus validate PROFILE --modbus URL [--unit-id U]
        [--virtual-time | --realtime | --no-realtime] [--out DIR] [--no-bus-log] [--no-plots]
        [--travel 0.01] [--tolerance 5] [--json]

No operator needed: the handle is held by a gentle spring and damper the gate accepts and probed
by a small periodic multisine through the run's own cycle (:mod:`~haptic_bus.app.validate_run`);
the measured response is compared with the model's exact prediction (:mod:`haptic_bus.validate`).
Output: the verdict ("the model holds to within X % up to f Hz", or how the device differs:
extra delay, resonance, filter, mass or friction, each with its uncertainty), the run's folder
with ``validate.json``, ``validate-bode.png`` and ``validate-re-z.png`` beside ``record.csv`` and
``run.json``; or ``--json``.

Exit status: 0 the model holds; 1 the device differs (findings named), the measurement cannot tell
(its uncertainty above the tolerance), the run was refused or a drive error; 2 invalid input
(before any bus or file is touched); 3 an assumption broken at run time; 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from haptic_bus.app.arguments import EXIT_NO, EXIT_OK, add_command, number
from haptic_bus.app.run_arguments import (
    add_link_arguments,
    add_output_arguments,
    add_pacing_arguments,
    bus_log,
    one_axis_link,
    scheduling,
)
from haptic_bus.identify.bounds import DEFAULT_TRAVEL, TRAVEL_RANGE

VALIDATE_HELP = "check the closed loop on the device against the model's exact prediction (no operator needed)"
TOLERANCE_RANGE = (0.1, 100.0)  # percent


def add_validate_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``validate`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "validate", VALIDATE_HELP, run_validate)
    parser.add_argument("profile", help="profile name or TOML path: the model checked, the loop, the force limit, [safety]")
    add_link_arguments(parser)
    add_pacing_arguments(parser)
    add_output_arguments(parser)
    parser.add_argument("--no-plots", action="store_true", help="write validate.json and the record, draw no pictures")
    parser.add_argument("--travel", type=number("travel", *TRAVEL_RANGE, "m"), default=DEFAULT_TRAVEL,
                        help="how far the probe may move the handle either side of its rest position, m")
    parser.add_argument("--tolerance", type=number("tolerance", *TOLERANCE_RANGE, "%"), default=5.0,
                        help="relative difference from the prediction the model may leave at any frequency, percent")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    return parser


def run_validate(args: argparse.Namespace) -> int:
    """Run ``haptic-bus validate``; return the exit status (module docstring)."""
    from haptic_bus.app.profiles import admit, one_axis_only, read_profile
    from haptic_bus.app.run_links import DEFAULT_CONTROLLER_NODE_ID
    from haptic_bus.app.run_options import VIRTUAL, WALL, RunOptions, StopRequest, exit_status
    from haptic_bus.app.validate_run import validate_drive
    from haptic_bus.validation import folder_path

    logs_bus = bus_log(args, "validate")
    profile = one_axis_only(read_profile(args.profile), "validate")  # refused before its scene is judged
    admit(profile)
    address = one_axis_link(args, "validate")
    bus: Any = address.url if address.url is not None else address.bus
    out_dir = None if args.out is None else folder_path("--out", args.out, context="validate")
    stop = StopRequest()
    options = RunOptions(1.0, pacing=VIRTUAL if args.virtual_time else WALL, out_dir=out_dir, live=False, stop=stop,
                         scheduling=scheduling(args.realtime),
                         bus_log=logs_bus)
    stop.install()
    outcome = validate_drive(profile, bus, options, travel=args.travel, tolerance=args.tolerance / 100.0,
                             node_id=None if address.url is not None else address.checked_node_id,
                             unit_id=address.unit_id if address.url is not None else None,
                             controller_node_id=args.controller_node_id or DEFAULT_CONTROLLER_NODE_ID,
                             pictures=not args.no_plots)
    result, validation = outcome.result, outcome.validation
    files = [str(path) for path in outcome.files]
    if outcome.cannot_tell is not None:
        if args.json:
            print(json.dumps({"verdict": "cannot tell", "summary": outcome.cannot_tell, "exit_reason": result.exit_reason,
                              "files": files}))
        print(f"haptic-bus validate: {outcome.cannot_tell} (the run's files: {result.folder})", file=sys.stderr)
        return EXIT_NO
    if validation is None:
        if args.json:
            print(json.dumps({"exit_reason": result.exit_reason, "error": result.error, "files": files}))
        print(f"haptic-bus validate: {no_verdict_line(result.exit_reason, result.error)}", file=sys.stderr)
        status = exit_status(result.exit_reason)
        return status if status != EXIT_OK else EXIT_NO
    if args.json:
        print(json.dumps({**validation.to_dict(), "summary": validation.summary(), "exit_reason": result.exit_reason,
                          "files": files}, allow_nan=False))
    else:
        plan = validation.plan
        print(f"probe: {validation.amplitude:.3g} N peak, {plan.bins.size} tones {plan.frequencies[0]:.3g}.."
              f"{plan.frequencies[-1]:.4g} Hz, hold K {validation.hold.stiffness:.4g} N/m B {validation.hold.damping:.3g} N s/m, "
              f"{plan.cycles * plan.period:.3g} s of the drive's time")
        print(validation.summary())
        print(f"wrote {', '.join(files)}")
    return EXIT_OK if validation.holds else EXIT_NO


def no_verdict_line(exit_reason: str, error: str | None) -> str:
    """What validate says of a run that gave no verdict (it ended ``exit_reason`` with ``error``): a
    run that "completed" without every probe cycle lost its drive; one stopped by SIGTERM measured
    too little (exit 1 either way, as identify)."""
    from haptic_bus.app.run_options import ended_line

    reason = exit_reason if exit_reason != "completed" else "drive error"
    said = error or ("stopped (SIGTERM) before the probe's last period: no verdict" if exit_reason == "stopped" else
                     "the run ended before the probe's last period")
    return ended_line(reason, said)
