"""What a parsed ``haptic-bus sim`` command line asks to simulate: each axis' plant, timing and node or
unit, the operator, and the CANopen slave's bus.

The hidden truth and the operator given on the command line (``--mass``, ``--friction``, ...,
``--operator``) override the profile's (issue 20).  Every function raises
:class:`~haptic_bus.errors.ParameterError` naming the option or the profile's key and the allowed
range; :mod:`sim_drive.serve` prints it as the command's one line.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

from drives.bus_config import merge_bus_options
from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from haptic_bus.errors import ParameterError
from haptic_bus.validation import ids_in_order, one_or_one_each, typed_repeat, whole_in_range
from sim_drive.operator import OperatorModel, operator_from_spec
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import SimulatedDevice, read_simulated_device

TRUTH_FLAGS = {"mass": "mass", "friction": "friction", "coulomb": "coulomb_friction", "velocity_noise": "velocity_noise",
               "noise_seed": "noise_seed", "transmission": "transmission",
               "extra_delay": "extra_delay"}  # argparse dest -> DeviceParameters field


def overridden(parameters: DeviceParameters, operator: OperatorModel | None,
               args: argparse.Namespace) -> tuple[DeviceParameters, OperatorModel | None]:
    """``parameters`` and ``operator`` with the command line's truth and operator; ParameterError names the flag."""
    given = {field: getattr(args, dest) for dest, field in TRUTH_FLAGS.items() if getattr(args, dest) is not None}
    try:
        parameters = dataclasses.replace(parameters, **given)
    except ParameterError as exc:
        flag = next(dest for dest, field in TRUTH_FLAGS.items() if field == exc.name)
        raise ParameterError("--" + flag.replace("_", "-"), exc.value, exc.allowed) from None
    return parameters, operator if args.operator is None else operator_from_spec(args.operator)


def refuse_truth_with_axes(args: argparse.Namespace) -> None:
    """ParameterError naming the first hidden-truth or operator flag given with a multi-axis profile: each
    axis takes its truth from its ``[[axes]]`` entry and the hand in space from ``[space.operator]``, so such
    a flag had no axis to go to and was dropped without a word (``--mass 50`` served the profile's masses)."""
    for dest in (*TRUTH_FLAGS, "operator"):
        if getattr(args, dest) is not None:
            raise ParameterError("--" + dest.replace("_", "-"), getattr(args, dest),
                                 "none with a multi-axis --profile: each axis' hidden truth is its [[axes]] entry's "
                                 "[axes.device] and the hand is [space.operator] (edit a copy of the profile)")


def bus_config(args: argparse.Namespace) -> dict[str, Any]:
    """The CANopen slave's python-can arguments; ParameterError for a key given twice with different values."""
    named = [(key, getattr(args, key)) for key in ("interface", "channel", "bitrate") if getattr(args, key)]
    return merge_bus_options(named, args.bus_option, *args.bus_kwargs)


def drive_setup(args: argparse.Namespace) -> tuple[DeviceParameters, OperatorModel | None, str]:
    """Device parameters, operator model and timing of one axis from ``--profile`` (a one-axis profile)
    and ``--timing``; ParameterError if invalid."""
    axis, operator = read_simulated_device(args.profile).one_axis() if args.profile else (None, None)
    parameters, operator = overridden(axis.parameters if axis else DeviceParameters(), operator, args)
    timing = args.timing or (axis.timing if axis else Timing.CIA402).value
    return parameters, operator, timing


def profile_axes(args: argparse.Namespace) -> SimulatedDevice | None:
    """The device of a ``--profile`` with ``[[axes]]``, each axis its own plant and node or unit (None: no
    profile, or a one-axis profile, which every axis runs); ParameterError if the profile is invalid."""
    device = read_simulated_device(args.profile) if args.profile else None
    return device if device is not None and device.multi_axis else None


def node_id(args: argparse.Namespace) -> int:
    """``--node-id``: the CANopen slave's node id; ParameterError naming the flag otherwise."""
    return whole_in_range("--node-id", args.node_id, *NODE_ID_RANGE, allowed=NODE_IDS)


def unit_id(args: argparse.Namespace) -> int:
    """``--unit-id``: the Modbus server's unit id (default 1), one haptic-bus run can reach; ParameterError naming
    the flag otherwise."""
    from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS

    return whole_in_range("--unit-id", UNIT_ID_RANGE[0] if args.unit_id is None else args.unit_id, *UNIT_ID_RANGE,
                          allowed=UNIT_IDS)


def node_ids(text: str) -> list[int]:
    """``--node-ids 5,6,7``: distinct CANopen node ids, one per axis; ParameterError otherwise."""
    return ids_in_order("--node-ids", text, NODE_IDS, *NODE_ID_RANGE, distinct=True)


def axes_setup(args: argparse.Namespace) -> tuple[list[Any], Any, list[int]]:
    """``(axes, hand, coordinates)`` for ``--node-ids``; ParameterError if the arguments or the profile are invalid."""
    from sim_drive.space_operator import SpaceHand

    nodes = node_ids(args.node_ids)
    if args.node_id is not None or args.eds is not None:
        raise ParameterError("--node-ids", args.node_ids, "without --node-id and --eds (one dictionary kind: --od)")
    if args.transmission is not None:  # the hand in space pushes each axis' handle where its encoder is
        raise ParameterError("--transmission", args.transmission, "one axis only (--node-id): no hand in space on "
                             "the far side of a transmission")
    device = profile_axes(args)
    if device is not None:
        refuse_truth_with_axes(args)
        known = [axis.node_id for axis in device.axes]
        unknown = [n for n in nodes if n not in known]
        if unknown:
            raise ParameterError("--node-ids", args.node_ids, f"node ids of the profile's [[axes]]: {known}")
        chosen = [known.index(n) for n in nodes]
        axes = [(n, device.axes[i].parameters, args.timing or device.axes[i].timing) for n, i in zip(nodes, chosen)]
        return axes, device.make_hand(), chosen
    parameters, _, timing = drive_setup(args)
    return [(n, parameters, timing) for n in nodes], SpaceHand(len(nodes)), list(range(len(nodes)))


def modbus_axes_setup(args: argparse.Namespace) -> tuple[list[Any], Any]:
    """``(axes, hand)`` for several Modbus axes: each (unit id, parameters, timing) in axis order;
    ParameterError if the arguments or the profile are invalid (module docstring of the options)."""
    from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
    from sim_drive.space_operator import SpaceHand

    listening = [url for url in args.modbus if not url.rstrip("/").endswith(":0")]  # port 0: any free port, each its own
    if len(set(listening)) < len(listening):  # a second server cannot listen where the first does ("Could not start listen")
        repeated, how_often = typed_repeat(listening)
        raise ParameterError("--modbus", repeated, f"each address once ({how_often}): every --modbus is a server of its own "
                             "(one server for several axes: one --modbus with --unit-ids)")
    # a unit id may repeat on servers of their own (unit 1 on each is the default), never on one
    given = ids_in_order("--unit-ids", args.unit_ids, UNIT_IDS, *UNIT_ID_RANGE,
                         distinct=len(args.modbus) == 1) if args.unit_ids else None
    if args.unit_id is not None:
        raise ParameterError("--unit-id", args.unit_id, "--unit-ids for several axes (one unit id per axis)")
    device = profile_axes(args)
    if device is not None:
        refuse_truth_with_axes(args)
        one_or_one_each("--modbus", args.modbus, len(device.axes), "axis")
        stated = [axis.unit_id for axis in device.axes]
        units = given or (stated if None not in stated else [UNIT_ID_RANGE[0]] * len(args.modbus))
        if len(units) != len(device.axes) or (len(args.modbus) == 1 and len(set(units)) != len(units)):
            raise ParameterError("--unit-ids", args.unit_ids, f"one unit id per axis of the profile ({len(device.axes)}), "
                                 "or several --modbus addresses, one per axis")
        return [(unit, axis.parameters, args.timing or axis.timing) for unit, axis in zip(units, device.axes)], \
            device.make_hand()
    units = given or [UNIT_ID_RANGE[0]] * len(args.modbus)
    one_or_one_each("--modbus", args.modbus, len(units), "unit")
    parameters, _, timing = drive_setup(args)
    return [(unit, parameters, timing) for unit in units], SpaceHand(len(units))
