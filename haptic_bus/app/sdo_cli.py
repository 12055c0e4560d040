"""``haptic-bus sdo read|write``: one object of a drive, read or written, named from its dictionary.

CANopen: an SDO upload or download of ``INDEX[:SUB]`` (:class:`drives.canopen.client.NodeClient`).
The object's name and type come from the dictionary: the standard CiA-301/402 objects
(:func:`drives.canopen.service_dictionary.standard_dictionary`), or the drive's own EDS with ``--eds
FILE``; ``--type`` (:data:`TYPE_NAMES`, :mod:`drives.canopen.sdo_values`) overrides it, and is
needed to write an object the dictionary does not know.  A read of an unknown object without
``--type`` shows its bytes.  Modbus (``--modbus``): the object's register in the register map
(:mod:`drives.modbus.register_map`), its type fixed by the map.

Everything a user can get wrong is refused before the bus is touched (exit 2): the object
(index 0x0001..0xFFFF, sub-index 0..255), a value for a read or none for a write, the type, the
value against the type's range (and the EDS's limits), an EDS that cannot be read, on Modbus an
object the map lacks or one it says is read-only.  An SDO abort is one line naming the object
and the abort code's meaning (exit 1), as is silence or a bus failure.
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING, Any

from drives.object_access import parse_object
from haptic_bus.app.arguments import EXIT_OK, add_command
from haptic_bus.app.drive_address import DriveAddress, add_drive_arguments, drive_address
from haptic_bus.errors import DriveProtocolError, ParameterError

if TYPE_CHECKING:
    from canopen import objectdictionary as od

SDO_HELP = "read or write one object of a drive (SDO on CANopen, its register on Modbus), named from its dictionary"
TYPE_NAMES = ("u8", "u16", "u32", "u64", "i8", "i16", "i32", "i64", "f32", "f64", "bool", "str", "hex")  # sdo_values.TYPES


def add_sdo_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``sdo`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "sdo", SDO_HELP, run_sdo)
    parser.add_argument("action", choices=("read", "write"), help="read (SDO upload) or write (SDO download)")
    parser.add_argument("object", metavar="INDEX[:SUB]",
                        help="the object, e.g. 0x6041, 0x1018:04 (sub-index hexadecimal, as printed; 0 if omitted)")
    parser.add_argument("value", nargs="?", metavar="VALUE", help="what to write (write only), in the object's type")
    add_drive_arguments(parser)
    parser.add_argument("--type", metavar="T", help=f"CANopen: the value's type, one of {' '.join(TYPE_NAMES)} "
                                                    "(default: the dictionary's)")
    parser.add_argument("--eds", metavar="FILE", help="CANopen: the drive's EDS or DCF, for names, types and limits "
                                                      "(default: the standard CiA-301/402 objects)")
    return parser


def _check_action(args: argparse.Namespace) -> None:
    if args.action == "read" and args.value is not None:
        raise ParameterError("VALUE", args.value, "no value with read (sdo write INDEX[:SUB] VALUE writes one)")
    if args.action == "write" and args.value is None:
        raise ParameterError("VALUE", None, "the value to write after INDEX[:SUB]")


def run_sdo(args: argparse.Namespace) -> int:
    """Read or write the object; print it; exit status (module docstring)."""
    address = drive_address(args)
    index, subindex = parse_object(args.object)
    _check_action(args)
    if args.type is not None and args.type not in TYPE_NAMES:
        raise ParameterError("--type", args.type, " ".join(TYPE_NAMES))
    if address.modbus:
        given = [(flag, value) for flag, value in (("--type", args.type), ("--eds", args.eds)) if value is not None]
        if given:
            raise ParameterError(*given[0], "only without --modbus (its register map fixes the type)")
        result = _modbus(address, index, subindex, args.value, args.timeout)
    else:
        result = _canopen(address, index, subindex, args)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        verb = "wrote" if args.action == "write" else "read"
        meaning = f": {result['meaning']}" if result.get("meaning") else ""
        print(f"{result['drive']}: {verb} {result['object']} {result['name']} = {result['shown']} "
              f"({result['type']}, {result['where']}){meaning}")
    return EXIT_OK


# --------------------------------------------------------------------------- CANopen

def _canopen(address: DriveAddress, index: int, subindex: int, args: argparse.Namespace) -> dict[str, Any]:
    from drives.canopen.client import NodeClient
    from drives.canopen.master_dictionary import object_name
    from drives.canopen.service_dictionary import find_variable, load_dictionary

    node_id = address.checked_node_id
    dictionary = load_dictionary(args.eds, node_id)
    variable = find_variable(dictionary, index, subindex)
    label = f"0x{index:04X}:{subindex:02X}"
    name = object_name(dictionary, index, subindex)
    type_name = _type_for(args.type, variable, label, args.action)
    data = None if args.value is None else _encoded(type_name, args.value, variable)
    with NodeClient(address.bus, node_id, args.timeout, dictionary) as client:
        if data is None:
            data = client.upload(index, subindex)
        else:
            client.download(index, subindex, data)
        client.check_receive()
        drive = client.name
    transfer = "SDO download" if args.action == "write" else "SDO upload"
    return _result(drive, label, name, type_name, data, index, subindex, transfer)


def _type_for(given: str | None, variable: od.ODVariable | None, label: str, action: str) -> str:
    """The type to use: ``--type``, else the dictionary's, else (a read only) the raw bytes."""
    from drives.canopen.sdo_values import type_name

    if given is not None:
        return given
    if variable is not None:
        return type_name(variable.data_type)
    if action == "write":
        raise ParameterError("--type", None, f"a type for {label}, which the dictionary does not know "
                                             f"({' '.join(TYPE_NAMES)}; or --eds FILE with the drive's dictionary)")
    return "hex"


def _encoded(type_name: str, text: str, variable: od.ODVariable | None) -> bytes:
    """``text`` as the bytes of a ``type_name`` value, within the dictionary's limits where it has them."""
    from drives.canopen.sdo_values import encode_text

    low = getattr(variable, "min", None)
    high = getattr(variable, "max", None)
    return encode_text(type_name, text, "VALUE", low, high)


def _result(drive: str, label: str, name: str, type_name: str, data: bytes, index: int, subindex: int,
            where: str) -> dict[str, Any]:
    """What was read or written, JSON-ready; DriveProtocolError if ``data`` is not a ``type_name`` value."""
    from drives.canopen.sdo_values import decode_bytes, show, size
    from drives.drive_status import describe_value

    value = decode_bytes(type_name, data)
    if value is None:
        raise DriveProtocolError(drive, f"{label} ({name}) is {len(data)} byte(s), a {type_name} has {size(type_name)}: "
                                        "read it with --type hex, or give its type")
    meaning = describe_value(index, subindex, value) if isinstance(value, int) else None
    as_json = value.hex() if isinstance(value, bytes) else value
    return {"drive": drive, "object": label, "index": index, "subindex": subindex, "name": name, "type": type_name,
            "value": as_json, "raw": data.hex(), "shown": show(type_name, value), "meaning": meaning, "where": where}


# --------------------------------------------------------------------------- Modbus

def _modbus(address: DriveAddress, index: int, subindex: int, text: str | None, timeout: float) -> dict[str, Any]:
    from drives.modbus.objects import ModbusObjects
    from drives.modbus.register_map import REGISTERS, register_for_object

    label = f"0x{index:04X}:{subindex:02X}"
    mapped = ", ".join(f"0x{r.obj.index:04X}" for r in REGISTERS if r.obj is not None)
    try:
        if subindex:
            raise KeyError(label)
        register = register_for_object(index)
    except KeyError:
        raise ParameterError("object", label, f"an object of the Modbus register map: {mapped}") from None
    value: int | None = None
    if text is not None:
        if register.access != "rw":
            raise ParameterError("object", label, f"a writable object ({register.label} is read-only)")
        low, high = register.range or (0, 0)
        try:
            value = int(text, 0)
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise ParameterError("VALUE", text, f"{register.kind}: an integer {low}..{high} (decimal or 0x-hexadecimal)")
    with ModbusObjects(address.url or "", address.unit_id, timeout) as unit:
        if value is None:
            value = int(unit.read_register(register))
        else:
            unit.write_register(register, value)
        drive = unit.name
    from drives.drive_status import describe_value

    obj = register.obj
    name = obj.name if obj is not None else register.name
    shown = f"{value} (0x{value & 0xFFFFFFFF:0{4 * register.count}X})" if register.kind.startswith("u") else str(value)
    return {"drive": drive, "object": label, "index": index, "subindex": subindex, "name": name, "type": register.kind,
            "value": value, "raw": None, "shown": shown, "meaning": describe_value(index, subindex, value),
            "where": f"register 0x{register.address:04X}"}
