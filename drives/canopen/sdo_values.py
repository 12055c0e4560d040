"""What an SDO carries, by type name: a command line's text into bytes, bytes back into a value.

Type names as service tools spell them: ``u8 u16 u32 u64`` and ``i8 i16 i32 i64`` (CiA 301
UNSIGNEDn / INTEGERn), ``f32 f64`` (REAL32 / REAL64), ``bool`` (BOOLEAN), ``str``
(VISIBLE_STRING, ASCII) and ``hex`` (the bytes as they are: OCTET_STRING, DOMAIN, any type
without a name here).  The byte layout is canopen's (:meth:`canopen.objectdictionary.ODVariable.encode_raw`
and ``decode_raw``: little-endian, as CiA 301 says); this module adds the checks a command
line needs before the bus is touched, each a :class:`~drives.errors.ParameterError` that names
the allowed range.
"""

from __future__ import annotations

import math
import string

from canopen import objectdictionary as od
from canopen.objectdictionary import datatypes as dt

from drives.errors import ParameterError

TYPES: dict[str, int] = {
    "u8": dt.UNSIGNED8, "u16": dt.UNSIGNED16, "u32": dt.UNSIGNED32, "u64": dt.UNSIGNED64,
    "i8": dt.INTEGER8, "i16": dt.INTEGER16, "i32": dt.INTEGER32, "i64": dt.INTEGER64,
    "f32": dt.REAL32, "f64": dt.REAL64, "bool": dt.BOOLEAN, "str": dt.VISIBLE_STRING, "hex": dt.OCTET_STRING,
}
_NAMES = {code: name for name, code in TYPES.items()}
_REAL_LIMITS = {"f32": 3.4028234663852886e38, "f64": 1.7976931348623157e308}
_BOOLEAN_WORDS = {"true": 1, "false": 0}
Value = int | float | str | bytes


def type_name(data_type: int | None) -> str:
    """The name of a CANopen data type code (``"hex"`` for one without a name here, or none)."""
    return _NAMES.get(data_type, "hex") if data_type is not None else "hex"


def _variable(name: str) -> od.ODVariable:
    variable = od.ODVariable(name, 0)
    variable.data_type = TYPES[name]
    return variable


def size(name: str) -> int | None:
    """Bytes of one value of type ``name``; None for ``str`` and ``hex`` (any length)."""
    packer = od.ODVariable.STRUCT_TYPES.get(TYPES[name])
    return None if packer is None else packer.size


def integer_range(name: str) -> tuple[int, int] | None:
    """The smallest and largest value of an integer type (``bool`` is 0..1); None for the others."""
    code = TYPES[name]
    if code == dt.BOOLEAN:
        return 0, 1
    bits = 8 * (size(name) or 0)
    if code in dt.SIGNED_TYPES:
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    if code in dt.UNSIGNED_TYPES:
        return 0, (1 << bits) - 1
    return None


def allowed(name: str) -> str:
    """What a VALUE of type ``name`` may be, in words."""
    limits = integer_range(name)
    if limits is not None:
        return f"{name}: an integer {limits[0]}..{limits[1]} (decimal or 0x-hexadecimal)"
    if name in _REAL_LIMITS:
        return f"{name}: a finite real of magnitude at most {_REAL_LIMITS[name]:.8g}"
    if name == "str":
        return "str: printable ASCII text"
    return "hex: bytes as hexadecimal digit pairs, e.g. 01ff or '01 ff'"


def _parse(name: str, text: str) -> Value:
    """``text`` as a value of type ``name``; ValueError if it is not one."""
    limits = integer_range(name)
    if limits is not None:
        number = _BOOLEAN_WORDS.get(text.lower()) if name == "bool" else None
        number = int(text, 0) if number is None else number
        if not limits[0] <= number <= limits[1]:
            raise ValueError(text)
        return number
    if name in _REAL_LIMITS:
        real = float(text)
        if not math.isfinite(real) or abs(real) > _REAL_LIMITS[name]:
            raise ValueError(text)
        return real
    if name == "str":
        if not all(c in string.printable for c in text):
            raise ValueError(text)
        return text
    return bytes.fromhex(text.replace(":", " "))


def encode_text(name: str, text: str, what: str, low: float | None = None, high: float | None = None) -> bytes:
    """``text`` as the bytes of a ``name`` value; ParameterError (naming ``what``) if it is not
    one, or outside ``low``..``high`` (an EDS's LowLimit/HighLimit)."""
    try:
        value = _parse(name, text)
    except ValueError:
        raise ParameterError(what, text, allowed(name)) from None
    if isinstance(value, (int, float)) and ((low is not None and value < low) or (high is not None and value > high)):
        raise ParameterError(what, text, f"{low if low is not None else '-inf'}..{high if high is not None else 'inf'} "
                                         "(the object's range in the dictionary)")
    return bytes(_variable(name).encode_raw(value))


def decode_bytes(name: str, data: bytes) -> Value | None:
    """The value of type ``name`` in ``data``, or None if ``data`` has not that type's length."""
    expected = size(name)
    if expected is not None and len(data) != expected:
        return None
    value = _variable(name).decode_raw(bytes(data))
    return bytes(value) if isinstance(value, (bytes, bytearray)) else value


def show(name: str, value: Value) -> str:
    """A value as a person reads it: ``592 (0x0250)``, ``-5``, ``0.25``, ``'text'``, ``01 ff``."""
    if isinstance(value, bytes):
        return value.hex(" ") if value else "(no bytes)"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float):
        return f"{value:.9g}"
    if name.startswith("u"):
        return f"{value} (0x{value:0{2 * (size(name) or 1)}X})"
    return str(int(value))
