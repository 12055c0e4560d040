"""CiA-301 strictness canopen's :class:`~canopen.LocalNode` leaves out, for the slaves we build on it.

canopen's SDO server looks every object up with ``LocalNode._find_object``, which ignores the
sub-index of a plain variable: ``0x6041:01`` reads 0x6041.  CiA 301 wants abort 0x06090011
("sub-index does not exist") there, before any other check of the access.
:class:`StrictLocalNode` adds that rule at the one place canopen looks objects up.
"""

from __future__ import annotations

from typing import Any

from canopen import LocalNode, SdoAbortedError
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from drives.cia301 import SdoAbort


class StrictLocalNode(LocalNode):
    """canopen's LocalNode whose SDO server aborts 0x06090011 for a sub-index other than 0 on a
    plain variable (read or write alike)."""

    def _find_object(self, index: int, subindex: int) -> Any:
        found = super()._find_object(index, subindex)
        if subindex and isinstance(found, ODVariable) and not isinstance(found.parent, (ODRecord, ODArray)):
            raise SdoAbortedError(SdoAbort.NO_SUBINDEX)
        return found
