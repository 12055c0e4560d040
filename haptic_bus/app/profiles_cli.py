"""``haptic-bus profiles list|show|check [NAME_OR_PATH] [--json]`` and ``profiles new NAME``: operator
parameter profiles.

Exit status: 0 ok (passive, written), 1 the gate refuses (not passive, or below the profile's safety
margin, or the strict bandwidth rule fails) or the drive cannot be read, 2 invalid input (one line on
stderr; for ``check``, a profile that still lacks values ``profiles new`` asked for: each listed).
``check`` prints, for every summed wall the scene can put on the handle, the very report
``haptic-bus check`` prints for those numbers.  ``new`` writes a commented profile
(:mod:`haptic_bus.app.profile_template`), from what a drive states with ``--from-drive``.

Every ``haptic-bus`` command builds this parser: this module imports the standard library and
light tables only, and each command imports the profiles, the gates and the analysis (numpy) in
its handler, so that ``haptic-bus run --help`` or a command refused at its arguments does not.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import pathlib
import shlex
import sys
import tomllib
from typing import TYPE_CHECKING, Any

from haptic_bus.analysis.loop import FRICTION_RANGE, MASS_RANGE
from haptic_bus.app.arguments import as_typed, error_line, number, timeout
from haptic_bus.app.drive_address import DriveAddress, add_address_arguments, drive_address
from haptic_bus.app.json_ready import json_ready
from haptic_bus.errors import NAMES_SHOWN, DriveError, HapticBusError, ParameterError, Refusal
from haptic_bus.profile.files import DEFAULT_PROFILE, resolve_profile, shipped_profiles
from haptic_bus.profile.plant import ONE_AXIS_TABLES
from haptic_bus.profile.reader import NAME_PATTERN, misspelling, read_document
from haptic_bus.profile.scene import FORCE_RANGE
from haptic_bus.validation import NOT_YET, new_file, some_names

if TYPE_CHECKING:
    from haptic_bus.analysis.check import CheckReport
    from haptic_bus.analysis.loop import DeviceLoop
    from haptic_bus.analysis.two_mass_check import TwoMassReport
    from haptic_bus.analysis.velocity import VelocityModel
    from haptic_bus.app.profiles import AxesProfile, Profile

EXIT_OK, EXIT_NO, EXIT_INVALID = 0, 1, 2


def _fail(command: str, error: Exception) -> int:
    print(error_line(f"profiles {command}", error), file=sys.stderr)
    return EXIT_INVALID


def _refused(command: str, refusal: Refusal) -> int:
    print(f"haptic-bus profiles {command}: {refusal}", file=sys.stderr)
    return EXIT_NO


def _list_row(profile: Profile | AxesProfile) -> dict[str, Any]:
    """One row of ``profiles list``: the loop (one axis: timing, delay, velocity, m kg, b N s/m; several: the
    axes' names), the period T s, the objects and the gate's worst margin (N s/m); Refusal as :func:`admit`."""
    from haptic_bus.app.profiles import AxesProfile, admit

    decision = admit(profile)
    row: dict[str, Any] = {"status": "ok", "worst_margin": decision.worst_margin, "warnings": len(decision.warnings),
                           "task": profile.task}
    if isinstance(profile, AxesProfile):
        return row | {"axes": [axis.name for axis in profile.axes], "period": profile.period, "objects": len(profile.space)}
    return row | {"timing": profile.loop.timing, "delay": profile.loop.delay, "velocity": str(profile.device.velocity),
                  "mass": profile.device.mass, "friction": profile.device.friction, "period": profile.loop.period,
                  "objects": len(profile.scene)}


def cmd_list(args: argparse.Namespace) -> int:
    """List the shipped profiles, one axis and several, with their loop and gate verdict; 0 if all load, else 1 or 2."""
    from haptic_bus.app.profiles import read_profile

    rows, status = [], EXIT_OK
    for name, path in sorted({**shipped_profiles(), **shipped_profiles(axes=True)}.items()):
        row: dict[str, Any] = {"name": name, "path": str(path), "default": name == DEFAULT_PROFILE}
        try:
            row.update(_list_row(read_profile(path)))
        except ParameterError as error:
            row.update(status="invalid", error=str(error))
            status = EXIT_INVALID
        except Refusal as refusal:
            row.update(status="refused", error=str(refusal))
            status = max(status, EXIT_NO)
        rows.append(row)
    if args.json:
        print(json.dumps(rows))
        return status
    for row in rows:
        mark = "*" if row["default"] else " "
        if row["status"] != "ok":
            print(f"{mark} {row['name']:<18} {row['status'].upper()}: {row['error']}")
            continue
        margin = "-" if row["worst_margin"] is None else f"{row['worst_margin']:+.4g} N s/m"
        warn = f", {row['warnings']} warning(s)" if row["warnings"] else ""
        loop = (f"{len(row['axes'])} axes ({', '.join(row['axes'])})" if "axes" in row else
                f"{row['timing']:<6} m={row['mass']:g} kg b={row['friction']:g} N s/m")
        print(f"{mark} {row['name']:<18} {loop} T={row['period']:g} s  {row['objects']} object(s), "
              f"worst margin {margin}{warn}  -- {row['task']}")
    print("(* = default profile)")
    return status


def cmd_show(args: argparse.Namespace) -> int:
    """Print one profile (default: the default profile) and its gate's decision on it (the coupled gate
    for several axes): 0; 1 the gate refuses it (shown all the same, and the refusal on stderr); 2 invalid."""
    from haptic_bus.app.profile_view import (
        format_axes_profile,
        format_profile,
        gate_decision_to_dict,
        space_decision_to_dict,
    )
    from haptic_bus.app.profiles import AxesProfile, gate_refusal, profile_to_dict, read_profile

    try:
        profile = read_profile(args.profile)
    except ParameterError as error:
        return _fail("show", error)
    if isinstance(profile, AxesProfile):
        space = profile.judge()
        view, as_dict, refusal = format_axes_profile(profile, space), space_decision_to_dict(space), gate_refusal(profile, space)
    else:
        one = profile.judge()
        view, as_dict, refusal = format_profile(profile, one), gate_decision_to_dict(one), gate_refusal(profile, one)
    print(json.dumps(json_ready(profile_to_dict(profile) | {"gate_decision": as_dict})) if args.json else view)
    return EXIT_OK if refusal is None else _refused("show", refusal)


def _check_axes(profile: AxesProfile, as_json: bool) -> int:
    """``check`` of a multi-axis profile: its axes, its scene and the coupled gate's verdict on every wall;
    0 the gate accepts, 1 it refuses."""
    from haptic_bus.app.profile_view import format_axes_profile, space_decision_to_dict

    decision = profile.judge()
    if as_json:  # as a one-axis profile's check: verdict, gate, every wall judged
        gate = space_decision_to_dict(decision)
        walls = gate.pop("walls")
        policy = profile.gate_policy
        print(json.dumps(json_ready({"profile": profile.name, "path": str(profile.path),
                                     "passive": all(wall.verdict.margin >= 0.0 for wall in decision.walls),
                                     "gate": gate | {"safety_margin": policy.safety_margin, "bandwidth": policy.bandwidth},
                                     "walls": walls})))
    else:
        print(format_axes_profile(profile, decision))
    return EXIT_OK if decision.accepted else EXIT_NO


def _still_missing(path: pathlib.Path) -> int | None:
    """Exit 2 with every value a new profile still lacks listed (stdout) and one line on stderr; None if none."""
    from haptic_bus.app.profile_template import missing

    try:
        document = read_document(path)
    except ParameterError:  # unreadable, not TOML, not UTF-8, nested too deep
        return None  # the loader says what is wrong with the file
    if not set(document) <= set(ONE_AXIS_TABLES):  # a misspelt table (the loader names it), or [[axes]]
        return None
    lacking = missing(document)
    if not lacking or any(_misspelt(document, ask.table, ask.name) for ask in lacking):
        return None  # complete, or a missing key misspelt beside it (``masss``): the loader names the misspelling
    print(f"profile {path}: {len(lacking)} value{'s' if len(lacking) > 1 else ''} still missing:")
    for ask in lacking:
        print(f"  {ask.key:<28} {ask.allowed}; {ask.why}")
    print(f"haptic-bus profiles check: error: {path}: still missing {', '.join(a.key for a in lacking)}", file=sys.stderr)
    return EXIT_INVALID


def _misspelt(document: dict[str, Any], table: str, key: str) -> bool:
    """Whether ``document``'s table ``table`` has a key that looks like a misspelling of ``key``."""
    keys = document.get(table)
    return isinstance(keys, dict) and misspelling(key, keys) is not None


def _wall_report(device: DeviceLoop, K: float, B: float) -> CheckReport | TwoMassReport:
    """Every criterion on one contact wall ``K`` N/m, ``B`` N s/m (the quantisation condition with the
    device's); the two-mass report on a device with a transmission."""
    from haptic_bus.analysis.check import check_loop
    from haptic_bus.analysis.two_mass import TwoMassLoop
    from haptic_bus.analysis.two_mass_check import check_two_mass_loop

    if device.transmission is None:
        return check_loop(device.wall(K, B), quantisation=device.quantisation)
    return check_two_mass_loop(TwoMassLoop(device.wall(K, B), device.transmission))


def cmd_check(args: argparse.Namespace) -> int:
    """``haptic-bus check`` on every contact wall of a profile; 0 passive (gate admits), 1 not, 2 invalid
    (a value missing: every one listed); a multi-axis profile: the coupled gate's verdict."""
    from haptic_bus.analysis.check import CheckReport, format_check
    from haptic_bus.analysis.two_mass_check import format_two_mass
    from haptic_bus.app.profile_view import gate_decision_to_dict
    from haptic_bus.app.profiles import AxesProfile, read_profile

    try:
        lacking = _still_missing(resolve_profile(args.profile))
        if lacking is not None:
            return lacking
        read = read_profile(args.profile)
        if isinstance(read, AxesProfile):
            return _check_axes(read, args.json)
        profile = read
        scene = profile.compiled_scene()  # once: its contact walls are the gate's and the report's
        decision = profile.gate().judge(scene)
        loop, device_loop = profile.loop, profile.device_loop()
        walls = []
        for (K, B), names in sorted(scene.contacts().items()):
            walls.append((names, K, B, _wall_report(device_loop, K, B)))
    except HapticBusError as error:
        return _fail("check", error)
    passive = all(report.passive for *_, report in walls)
    status = EXIT_OK if passive and decision.accepted else EXIT_NO
    if args.json:
        print(json.dumps({"profile": profile.name, "path": str(profile.path), "passive": passive,
                          "gate": gate_decision_to_dict(decision) | {"safety_margin": profile.gate_policy.safety_margin,
                                                               "bandwidth": profile.gate_policy.bandwidth},
                          "walls": [{"objects": list(names), "K": K, "B": B, "report": report.to_dict()}
                                    for names, K, B, report in walls]}))
        return status
    print(f"profile {profile.name} ({profile.path}): {len(walls)} contact wall(s),"
          f" timing {loop.timing} (delay {loop.delay:g} samples), velocity {profile.device.velocity}")
    for names, _, _, report in walls:
        print(f"--- {some_names(names)} (summed K, B)")
        print(format_check(report) if isinstance(report, CheckReport) else format_two_mass(report))
    verdict = "passive" if passive else "NOT passive"
    print(f"profile verdict: {verdict}; gate {'accepts' if decision.accepted else 'REFUSES'}"
          f" (safety margin {profile.gate_policy.safety_margin:g} N s/m, bandwidth {profile.gate_policy.bandwidth})")
    for said, lines in (("refused", decision.reasons), ("warning", decision.warnings)):
        for line in lines[:NAMES_SHOWN]:
            print(f"  {said}: {line}")
        if len(lines) > NAMES_SHOWN:
            print(f"  {said}: and {len(lines) - NAMES_SHOWN} more (--json lists every one)")
    return status


def _new_target(args: argparse.Namespace) -> tuple[pathlib.Path, DriveAddress]:
    """The file ``profiles new`` writes and the drive it reads (with ``--from-drive``), checked
    before any bus or file is touched (ParameterError)."""
    if not NAME_PATTERN.match(args.name):
        raise ParameterError("NAME", args.name, "a name of letters, digits, '.', '_', '-' (not starting with '.', '_', '-')",
                             "profiles new")
    address = drive_address(args, "profiles new", node_required=False)
    drive_given = [dest for dest in ("node_id", "modbus", "interface", "channel", "bus_option", "bus_kwargs")
                   if getattr(args, dest)]
    if not args.from_drive and drive_given:
        raise ParameterError("--" + drive_given[0].replace("_", "-"), as_typed(getattr(args, drive_given[0])),
                             "drive options only with --from-drive", "profiles new")
    if args.from_drive and address.node_id is None and not address.modbus:
        raise ParameterError("--from-drive", "without a drive", "--node-id N (and the bus) or --modbus URL", "profiles new")
    if args.velocity is not None:
        velocity_model(args.velocity)
    return new_file("--out", f"{args.name}.toml" if args.out is None else args.out, args.force, context="profiles new"), address


def velocity_model(text: str) -> VelocityModel:
    """``profiles new --velocity``'s model, refused (ParameterError naming the flag, the text as given and
    the range) unless it fits the period the new profile is written with (a window within ``T``): a
    ``window:0.5`` was written into a profile of ``T`` = 1 ms that no reader could then load."""
    from haptic_bus.analysis.velocity import ALLOWED, VelocityModel
    from haptic_bus.app.profile_template import DEFAULT_PERIOD

    try:
        model = VelocityModel.parse(text)
        model.check_period(DEFAULT_PERIOD)
    except ParameterError as error:
        allowed = ALLOWED if error.allowed == ALLOWED else f"{error.allowed} (the profile's loop.period)"
        raise ParameterError("--velocity", text, allowed, "profiles new") from None
    return model


def cmd_new(args: argparse.Namespace) -> int:
    """Write a commented profile (from what the drive states with ``--from-drive``); 0 written, 1 the
    drive cannot be read, 2 invalid input (an existing file without --force, an unwritable folder)."""
    from haptic_bus.app.drive_statement import canopen_statement, modbus_statement
    from haptic_bus.app.profile_template import missing, template
    from haptic_bus.app.whole_file import write_text_whole

    target, address = _new_target(args)
    given: dict[str, Any] = {key: getattr(args, key) for key in ("mass", "friction", "force_limit")
                             if getattr(args, key) is not None}
    if args.velocity is not None:
        given["velocity"] = str(velocity_model(args.velocity))
    statement = None
    try:
        if address.url is not None:
            statement = modbus_statement(address.url, address.unit_id)
        elif args.from_drive:
            statement = canopen_statement(address.bus, address.checked_node_id, args.timeout)
    except DriveError as exc:  # named by the command typed ('haptic-bus profiles: drive error' named only its group)
        print(f"haptic-bus profiles new: drive error: {exc}", file=sys.stderr)
        return EXIT_NO
    command = f"haptic-bus profiles new {args.name}" + (" --from-drive" if statement is not None else "")
    text = template(args.name, statement, given, command, dt.datetime.now(dt.UTC))
    try:  # without --force, created only if it still does not exist: another command may have made it since
        write_text_whole(target, text, replace=args.force)
    except FileExistsError:
        raise ParameterError("--out", str(target), NOT_YET, "profiles new") from None
    except OSError as exc:
        raise ParameterError("--out", str(target), f"a file this user can write ({exc.strerror})", "profiles new") from None
    stated = ", ".join(statement.scaling) if statement is not None else "nothing (no --from-drive)"
    lacking = [ask.key for ask in missing(tomllib.loads(text))]
    print(f"wrote {target}: from the drive {stated}; still to give: {', '.join(lacking)} "
          f"(haptic-bus profiles check {shlex.quote(str(target))} lists them)")
    return EXIT_OK


def _add_new_parser(sub: argparse._SubParsersAction) -> None:
    new = sub.add_parser("new", help="write a commented profile, from what a drive states with --from-drive; it asks "
                                     "for the rest (profiles check lists what is still missing)")
    new.add_argument("name", metavar="NAME", help="the profile's name (letters, digits, '.', '_', '-')")
    new.add_argument("--from-drive", action="store_true",
                     help="read 0x6076, 0x6072 and the CiA-402 factor group (Modbus: the scaling registers) from the "
                          "drive, reads only: with --node-id and the bus options, or --modbus URL")
    add_address_arguments(new)
    new.add_argument("--timeout", type=timeout, default=1.0, help="SDO answer timeout, s (default 1)")
    new.add_argument("--mass", type=number("mass", *MASS_RANGE, "kg"), help="a first guess of the handle's mass, kg")
    new.add_argument("--friction", type=number("friction", *FRICTION_RANGE, "N s/m"),
                     help="a first guess of its viscous friction b, N s/m")
    new.add_argument("--velocity", metavar="MODEL", help="what 0x606C is: point, average, window:SECONDS, lowpass:SECONDS")
    new.add_argument("--force-limit", type=number("force limit", *FORCE_RANGE, "N", low_open=True),
                     help="the most force identify and the walls may ask, N")
    new.add_argument("--out", metavar="FILE", help="the file to write (default NAME.toml here)")
    new.add_argument("--force", action="store_true", help="overwrite an existing --out")
    new.set_defaults(handler=cmd_new)


def add_profiles_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``profiles list|show|check|new`` on ``subparsers``; each leaf sets ``handler``."""
    parser = subparsers.add_parser("profiles", help="operator parameter profiles: list, show, check, new")
    sub = parser.add_subparsers(dest="profiles_command", metavar="{list,show,check,new}", required=True)  # an error names these
    listing = sub.add_parser("list", help="the shipped profiles and their gate verdicts")
    listing.add_argument("--json", action="store_true", help="one JSON array on stdout")
    listing.set_defaults(handler=cmd_list)
    for name, handler, text in (("show", cmd_show, "print a profile and the gate's decision"),
                                ("check", cmd_check, "haptic-bus check on every contact wall of a profile")):
        leaf = sub.add_parser(name, help=text)
        leaf.add_argument("profile", nargs="?", default=DEFAULT_PROFILE,
                          help=f"shipped profile name or TOML path (default {DEFAULT_PROFILE})")
        leaf.add_argument("--json", action="store_true", help="one JSON object on stdout")
        leaf.set_defaults(handler=handler)
    _add_new_parser(sub)
    return parser
