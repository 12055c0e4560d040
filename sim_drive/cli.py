"""``haptic-bus sim``: run the simulated drive as a CANopen slave until SIGINT/SIGTERM.

    haptic-bus sim --interface I --channel C --node-id N [--bitrate R] [--timing cia402|ideal]
                   [--profile P] [--bus-option KEY=VALUE ...] [--realtime]
    haptic-bus sim --eds-path

Logs one line per CiA-402 state change (and NMT change) through ``logging``; each line
carries the drive's virtual time.  ``--realtime`` paces nothing (the SYNC producer sets the
pace) but prefixes every line with the wall-clock time it was seen.  With ``--bitrate`` the
run ends with the bus load and worst cycle latency of the worst-case bit-time model.
Exit status: 0 after a clean stop, 2 for bad arguments or parameters, 1 if the bus fails.
"""

from __future__ import annotations

import argparse
import logging
import signal
import socket
import sys
from collections.abc import Sequence
from typing import Any

import can

from drives.bus_config import parse_bus_option
from drives.errors import ParameterError
from sim_drive.bus_timing import BusLoadMeter
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.eds import eds_path
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import load_profile

logger = logging.getLogger("sim_drive")


class _StopSignals:
    """Records SIGINT/SIGTERM from ``__enter__`` to ``__exit__``; :meth:`wait` blocks for the first.

    The handler only appends to a list (a handler that took a lock could deadlock on one the
    interrupted main thread holds), and Python's C-level handler writes a byte to the wake-up
    socket, so the blocking ``recv`` returns even for a signal that came just before it.
    Signal masks are no help: numpy's BLAS threads, started at import time, would take a
    masked signal with its default action.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self) -> "_StopSignals":
        self.received: list[signal.Signals] = []
        self._reader, self._writer = socket.socketpair()
        self._writer.setblocking(False)
        self._previous_fd = signal.set_wakeup_fd(self._writer.fileno(), warn_on_full_buffer=False)
        self._previous = {sig: signal.signal(sig, self._record) for sig in self.SIGNALS}
        return self

    def _record(self, number: int, frame: object) -> None:
        self.received.append(signal.Signals(number))

    def wait(self) -> signal.Signals:
        """The first stop signal received (blocks until there is one)."""
        while not self.received:
            self._reader.recv(64)
        return self.received[0]

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._previous_fd)
        self._reader.close()
        self._writer.close()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``haptic-bus sim``."""
    parser = argparse.ArgumentParser(prog="haptic-bus sim", description="Simulated CiA-402 drive on a CAN bus.")
    parser.add_argument("--eds-path", action="store_true", help="print the path of the shipped EDS and exit")
    parser.add_argument("--interface", help="python-can interface (virtual, udp_multicast, socketcan, ...)")
    parser.add_argument("--channel", help="python-can channel (e.g. vcan0, a multicast group)")
    parser.add_argument("--node-id", type=int, help="CANopen node id 1..127")
    parser.add_argument("--bitrate", type=int, help="bit/s; also enables the bus-load report")
    parser.add_argument("--timing", choices=[t.value for t in Timing],
                        help="cia402 (default) or ideal; default: the profile's [loop] timing")
    parser.add_argument("--profile", help="operator profile (name or TOML path): [device], [loop], [operator_model]")
    parser.add_argument("--bus-option", type=parse_bus_option, action="append", default=[], metavar="KEY=VALUE",
                        help="extra python-can bus argument, e.g. port=43113 (repeatable)")
    parser.add_argument("--realtime", action="store_true", help="timestamp log lines with the wall clock")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``haptic-bus sim``; return the exit status."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if any(a == "--modbus" or a.startswith("--modbus=") for a in args_list):  # the Modbus TCP server
        from sim_drive.modbus_server import main as modbus_main

        return modbus_main(args_list)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2): report, do not exit
        return int(exc.code or 0)
    if args.eds_path:
        print(eds_path())
        return 0
    missing = [name for name in ("interface", "channel", "node_id") if getattr(args, name) is None]
    if missing:
        parser.print_usage(sys.stderr)
        print(f"haptic-bus sim: error: missing --{', --'.join(m.replace('_', '-') for m in missing)}", file=sys.stderr)
        return 2
    fmt = "%(asctime)s %(message)s" if args.realtime else "%(message)s"
    logging.basicConfig(level=logging.INFO, format=fmt, stream=sys.stderr, force=True)
    logging.getLogger("canopen").setLevel(logging.WARNING)
    try:
        profile = load_profile(args.profile) if args.profile else None
        parameters = profile.parameters if profile else DeviceParameters()
        operator = profile.operator if profile else None
        args.timing = args.timing or (profile.timing.value if profile and profile.timing else Timing.CIA402.value)
        meter = BusLoadMeter(args.bitrate, parameters.period) if args.bitrate else None
        config: dict[str, Any] = {"interface": args.interface, "channel": args.channel, **dict(args.bus_option)}
        if args.bitrate:
            config["bitrate"] = args.bitrate
        sim = CanopenSimDrive(config, args.node_id, timing=args.timing, parameters=parameters, operator=operator, bus_meter=meter)
    except ParameterError as exc:
        print(f"haptic-bus sim: error: {exc}", file=sys.stderr)
        return 2
    with _StopSignals() as stop_signals:  # from before the boot-up: an early signal still stops cleanly
        try:
            sim.start()
        except (can.CanError, OSError, ValueError) as exc:
            print(f"haptic-bus sim: error: cannot open the bus: {exc}", file=sys.stderr)
            return 1
        try:
            logger.info("node %d: serving on %s %s (timing %s); EDS %s", args.node_id, args.interface, args.channel, args.timing, eds_path())
            received = stop_signals.wait()
            logger.info("node %d: %s received, stopping", args.node_id, received.name)
        finally:
            sim.stop()
    drive = sim.drive
    logger.info("node %d: stopped after %d SYNCs, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                args.node_id, drive.sync_count, drive.time, drive.operator_energy, drive.wall_energy)
    if meter is not None and meter.cycle_bit_counts:
        logger.info("node %d: bus load %.1f %% at %d bit/s, worst cycle %.1f us", args.node_id, 100 * meter.load(), args.bitrate, 1e6 * meter.worst_latency())
    return 0
