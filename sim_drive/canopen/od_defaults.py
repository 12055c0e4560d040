"""Power-on values of a slave's integer objects, read from its object dictionary (the EDS defaults).

canopen types an object as ``ODVariable | ODRecord | ODArray`` and a default as optional; the
slave's resets need the integer default of one entry, and a clear error if the dictionary has
none (a broken EDS), not an ``int(None)`` deep inside a reset.
"""

from __future__ import annotations

from canopen.objectdictionary import ObjectDictionary, ODArray, ODRecord

__all__ = ["default_int"]


def default_int(dictionary: ObjectDictionary, index: int, subindex: int = 0, *, absent: int | None = None) -> int:
    """The integer default of ``index:subindex`` in ``dictionary``.

    ``absent``: the value when the object or sub-index does not exist (None: KeyError then).
    A present entry without an integer default raises ValueError.
    """
    entry = dictionary.indices.get(index)
    if isinstance(entry, (ODRecord, ODArray)):
        variable = entry.get(subindex) if subindex in entry else None  # an ODArray would make up any sub-index
    else:
        variable = entry if subindex == 0 else None
    if variable is None:
        if absent is None:
            raise KeyError(f"0x{index:04X}:{subindex:02X} is not in the object dictionary")
        return absent
    default = variable.default
    if not isinstance(default, int):
        raise ValueError(f"0x{index:04X}:{subindex:02X} has no integer default in the object dictionary ({default!r})")
    return int(default)
