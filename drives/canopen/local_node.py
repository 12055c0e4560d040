"""CiA-301 strictness canopen's :class:`~canopen.LocalNode` leaves out, for the slaves we build on it.

canopen's SDO server looks objects up with ``LocalNode._find_object``, which ignores the
sub-index of a plain variable: ``0x6041:01`` reads 0x6041.  CiA 301 wants abort 0x06090011
("sub-index does not exist") there.  :func:`refuse_subindex_on_variables` installs the check
as the node's first read and write callback, so it runs before any other.
"""

from __future__ import annotations

from typing import Any

from canopen import LocalNode, SdoAbortedError
from canopen.objectdictionary import ODVariable

from drives.cia301 import SdoAbort


def _check(subindex: int, od: Any) -> None:
    if subindex and isinstance(od, ODVariable) and od.parent is None:
        raise SdoAbortedError(SdoAbort.NO_SUBINDEX)


def refuse_subindex_on_variables(node: LocalNode) -> None:
    """Make ``node``'s SDO server abort 0x06090011 for a sub-index other than 0 on a plain variable.

    Call it before adding any other read/write callback.
    """

    def on_read(index: int, subindex: int, od: Any) -> None:
        _check(subindex, od)

    def on_write(index: int, subindex: int, od: Any, data: bytes) -> None:
        _check(subindex, od)

    node.add_read_callback(on_read)
    node.add_write_callback(on_write)
