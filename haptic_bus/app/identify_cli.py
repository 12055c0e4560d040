"""``haptic-bus identify``: measure the handle's m, b, Coulomb friction, loop delay and velocity model.

    haptic-bus identify --profile P --node-id N [--interface I --channel C --bitrate R --bus-option K=V ...]
                        [--controller-node-id M]
    haptic-bus identify --profile P --modbus URL [--unit-id U]
        [--duration 20] [--travel 0.01] [--max-delay 4] [--virtual-time] [--json] [--write-profile FILE [--force]]

The profile gives the drive's scaling, the loop period, the force limit and the ``[safety]``
settings (its ``[device]`` numbers are what is being checked, so its scene is not judged).  The
run: a probe that refuses a handle not free to move, ``--duration`` s of a multisine within the
force limit and ``--travel`` m either side of the start, then the fit
(:mod:`haptic_bus.app.identify_run`, :mod:`haptic_bus.identify`).  Output: a table of estimates
with standard errors and 95 % intervals, the residual check, the velocity model 0x606C matches,
and what the data cannot support; or ``--json``.  ``--write-profile FILE`` writes a copy of the
profile with the measured values (:mod:`haptic_bus.app.identify_profile`), only when the data
support them; a file that exists is replaced only with ``--force`` (one that appeared while identify
measured included: the estimates printed, one line naming the file, exit 1).

Exit status: 0 the data support the estimate; 1 the handle was refused (not free to move), the
data cannot support the estimate, the profile could not be written, or a drive/bus error; 2 invalid input (before any bus or
file is touched: an existing --write-profile without --force included); 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import TYPE_CHECKING, Any

from haptic_bus.app.arguments import add_command, node_id, number, whole
from haptic_bus.app.drive_address import DriveAddress, add_address_arguments, drive_address
from haptic_bus.errors import ParameterError
from haptic_bus.identify.bounds import (
    DEFAULT_DURATION,
    DEFAULT_TRAVEL,
    DELAY_SEARCH_RANGE,
    DURATION_RANGE,
    MAX_DELAY,
    TRAVEL_RANGE,
)
from haptic_bus.validation import new_file

if TYPE_CHECKING:  # the fit loads scipy: only when an identification runs
    from haptic_bus.identify import Identification
    from haptic_bus.identify.fit import Estimate, PlantFit

IDENTIFY_HELP = "measure the handle's m, b, Coulomb friction, loop delay and 0x606C's velocity model"


def add_identify_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``identify`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "identify", IDENTIFY_HELP, run_identify)
    parser.add_argument("--profile", required=True, help="profile name or TOML path: scaling, period, force limit, [safety]")
    add_address_arguments(parser)
    parser.add_argument("--controller-node-id", type=node_id,
                        help="this controller's CANopen node id, whose heartbeat the drive watches (default 127)")
    parser.add_argument("--duration", type=number("duration", *DURATION_RANGE, "s"), default=DEFAULT_DURATION,
                        help="seconds of excitation")
    parser.add_argument("--travel", type=number("travel", *TRAVEL_RANGE, "m"), default=DEFAULT_TRAVEL,
                        help="how far the handle may move either side of its start, m (keep it clear of the end stops)")
    parser.add_argument("--max-delay", type=whole("max delay", *DELAY_SEARCH_RANGE), default=MAX_DELAY,
                        help="largest whole loop delay searched, samples")
    parser.add_argument("--virtual-time", action="store_true", help="lock-step with a simulated drive (no pacing)")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.add_argument("--write-profile", metavar="FILE", help="write a copy of the profile with the measured values "
                        "(a new file: --force replaces one that exists)")
    parser.add_argument("--force", action="store_true", help="let --write-profile replace an existing file")
    return parser


def _validate(args: argparse.Namespace) -> tuple[DriveAddress, pathlib.Path | None]:
    """The drive, and the file --write-profile names; conflicting options and an unwritable
    --write-profile refused before anything is touched."""
    from haptic_bus.app.run_links import DEFAULT_CONTROLLER_NODE_ID

    address = drive_address(args, "identify", ("node_id", "controller_node_id"))
    if not address.modbus and (args.controller_node_id or DEFAULT_CONTROLLER_NODE_ID) == address.node_id:
        raise ParameterError("--controller-node-id", args.controller_node_id or DEFAULT_CONTROLLER_NODE_ID,
                             f"a node id other than the drive's ({address.node_id})", "identify")
    if args.write_profile is None:
        return address, None
    # as profiles new: an identified profile is not lost to the next run
    return address, new_file("--write-profile", args.write_profile, args.force, context="identify")


def run_identify(args: argparse.Namespace) -> int:
    """The ``identify`` handler: validate, run, report, write the profile; the exit status."""
    from haptic_bus.app.identify_profile import write_identified_profile
    from haptic_bus.app.identify_run import IdentifyOptions, identify_canopen, identify_modbus
    from haptic_bus.app.profiles import one_axis_only, read_profile
    from haptic_bus.app.run_links import DEFAULT_CONTROLLER_NODE_ID
    from haptic_bus.app.run_options import VIRTUAL, WALL, StopRequest, ended_line
    from haptic_bus.profile.device import TIMINGS

    address, target = _validate(args)
    profile = one_axis_only(read_profile(args.profile), "identify")
    if target is not None and profile.path is not None and target.resolve() == profile.path.resolve():
        raise ParameterError("--write-profile", args.write_profile, "a new file, not the --profile itself", "identify")
    stop = StopRequest()
    options = IdentifyOptions(args.duration, args.travel, pacing=VIRTUAL if args.virtual_time else WALL,
                              max_delay=args.max_delay, stop=stop)
    stop.install()
    if address.url is not None:
        outcome = identify_modbus(profile, address.url, address.unit_id, options)
    else:
        outcome = identify_canopen(profile, address.bus, address.checked_node_id, options,
                                   args.controller_node_id or DEFAULT_CONTROLLER_NODE_ID)
    found = outcome.identification
    written, unwritten = None, None
    if found is not None and found.supported and target is not None and profile.path is not None:
        least = TIMINGS[profile.loop.timing] or 0.0  # the least [loop] delay the profile's timing allows
        try:  # the folder passed the check before the run; it can still refuse (gone, full, /proc): said, not a traceback
            written = write_identified_profile(profile.path, target, found, least, replace=args.force)
        except FileExistsError:  # none there at the check: another program made it while identify measured
            unwritten = (f"write error: --write-profile {target}: a file appeared there during the measurement "
                         f"(--force replaces one); nothing written, the estimates are the ones above")
        except OSError as exc:
            unwritten = (f"write error: --write-profile {target}: {exc.strerror or exc}; nothing written, the "
                         f"estimates are the ones above")
    if args.json:
        print(json.dumps({"exit_reason": outcome.exit_reason, "error": outcome.error, "link": outcome.link,
                          "identification": None if found is None else found.to_dict(),
                          "wrote": None if written is None else str(written), "write_error": unwritten}))
    elif found is not None:
        pacing = "virtual time" if args.virtual_time else "real time"
        print(format_identification(found, f"{profile.name} ({profile.path}); {describe_link(outcome.link)}, {pacing}"))
        if written is not None:
            print(f"wrote {written}")
    if written is not None and (refused := _refusal_of(written)) is not None:
        print(f"haptic-bus identify: {written} holds what was measured, and the gate refuses its walls on that device: "
              f"{refused}", file=sys.stderr)
    if unwritten is not None:
        print(f"haptic-bus identify: {unwritten}", file=sys.stderr)
        return outcome.exit_status or 1
    if outcome.error:
        print(f"haptic-bus identify: {ended_line(outcome.exit_reason, outcome.error)}", file=sys.stderr)
    elif found is not None and not found.supported:
        print("haptic-bus identify: the data cannot support the estimate (see the findings)", file=sys.stderr)
    return outcome.exit_status


def _refusal_of(written: pathlib.Path) -> str | None:
    """Why the gate refuses the written profile's scene on the device it now states (None: it passes):
    the measured ``b``, ``D`` and velocity model can refuse walls the profile's own values passed."""
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.errors import ParameterError, Refusal

    try:
        load_profile(written)
    except (Refusal, ParameterError) as refused:
        return str(refused)
    return None


# --------------------------------------------------------------------------- the human report

def _row(name: str, estimate: Estimate, unit: str) -> str:
    low, high = estimate.interval()
    return f"  {name:<22}{estimate.value:>12.6g} {unit:<8}{estimate.stderr:>11.2g}   [{low:.6g}, {high:.6g}]"


def _delay_words(fit: PlantFit) -> str:
    if fit.whole_delay is not None:
        return f"whole samples: {fit.whole_delay}"
    if fit.fraction_resolved:
        return f"{fit.delay.value:.3f} samples: the fraction resolved to +-{fit.delay.stderr:.2g}"
    return f"fraction not resolved: pessimistic {fit.delay_high:g} samples"


def describe_link(link: dict[str, Any]) -> str:
    """``CANopen node 5 on udp_multicast 239.74.163.1`` or ``Modbus unit 1 at tcp://...``."""
    if link.get("kind") == "modbus":
        return f"Modbus unit {link['unit_id']} at {link['url']}"
    bus = link.get("bus", {})
    return f"CANopen node {link.get('node_id')} on {bus.get('interface', '?')} {bus.get('channel', '')}".rstrip()


def format_identification(found: Identification, source: str) -> str:
    """The human report of one identification."""
    record = found.record
    lines = [f"haptic-bus identify: profile {source}",
             f"probe: {found.probe.message}",
             f"run: {record.cycles} cycles ({record.seconds:.3g} s), excitation {record.excitation_seconds:.3g} s, "
             f"{record.saturated} clipped at the {record.force_limit:.3g} N force limit"]
    fit, velocity = found.fit, found.velocity
    if fit is not None and velocity is not None:
        lines += ["", f"  {'':<22}{'estimate':>12} {'':<8}{'std. error':>11}   95 % interval",
                  _row("mass m", fit.mass, "kg"),
                  _row("viscous friction b", fit.friction, "N s/m"),
                  _row("Coulomb friction Fc", fit.coulomb, "N"),
                  _row("loop delay D", fit.delay, "samples") + f"   {_delay_words(fit)}", ""]
        verdict = ("consistent with the exact model" if fit.residual_rms <= 3 * fit.quantization_rms
                   and fit.residual_correlation <= fit.correlation_bound else "see the findings")
        lines.append(f"residual: {fit.residual_rms:.3g} increments rms over {fit.equations} cycles (rounding alone "
                     f"{fit.quantization_rms:.3g}), |autocorrelation| at lags 3-20 <= {fit.residual_correlation:.2g} "
                     f"(bound {fit.correlation_bound:.2g}): {verdict}; the rounding compensation moved b by "
                     f"{fit.compensation:+.2g} N s/m")
        others = ", ".join(f"{d.model} {d.rms:.4g}" for d in velocity.distances[1:])
        declared = ("" if velocity.declared is None else
                    f"; declared {velocity.declared.model}: {'matches' if velocity.matches_declared else 'CONTRADICTED'}")
        credible = "" if velocity.credible == velocity.best else f", longest credible {velocity.credible}"
        lines.append(f"velocity (0x606C): matches {velocity.best}{credible} (rms {velocity.distances[0].rms:.4g} counts over "
                     f"{velocity.samples} cycles; {others}){declared}")
        lines.append(f"for the gate: b >= {fit.friction_low:.6g} N s/m (b - 3 sigma), D <= {fit.delay_high:.4g} samples, "
                     f"velocity {velocity.credible}")
    for finding in found.findings:
        lines.append(f"{finding.severity}: {finding.topic}: {finding.message}")
    lines.append("verdict: " + ("supported" if found.supported else
                                "REFUSED: the handle is not free to move" if not found.probe.free else
                                "the data cannot support the estimate"))
    return "\n".join(lines)
