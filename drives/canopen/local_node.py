"""What canopen's :class:`~canopen.LocalNode` leaves out, for the nodes we build on it.

canopen's SDO server looks every object up with ``LocalNode._find_object``, which ignores the
sub-index of a plain variable: ``0x6041:01`` reads 0x6041.  CiA 301 wants abort 0x06090011
("sub-index does not exist") there, before any other check of the access.
:class:`StrictLocalNode` adds that rule at the one place canopen looks objects up.

canopen's SDO server answers every request in the thread that dispatched it, before it returns.
A download whose verdict takes longer than a receiving thread may wait (a gated upload, judged
in another process while the control thread keeps cycling) is answered later:
:class:`DeferredDownloadServer`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from canopen import LocalNode, SdoAbortedError
from canopen.objectdictionary import ODArray, ODRecord, ODVariable
from canopen.sdo import SdoServer
from canopen.sdo.constants import EXPEDITED, RESPONSE_ABORTED, RESPONSE_DOWNLOAD, SDO_STRUCT, SIZE_SPECIFIED

from drives.cia301 import SdoAbort

_ABORT = struct.Struct("<BHBL")  # abort response: command, index, sub-index, abort code


class StrictLocalNode(LocalNode):
    """canopen's LocalNode whose SDO server aborts 0x06090011 for a sub-index other than 0 on a
    plain variable (read or write alike)."""

    def _find_object(self, index: int, subindex: int) -> Any:
        found = super()._find_object(index, subindex)
        if subindex and isinstance(found, ODVariable) and not isinstance(found.parent, (ODRecord, ODArray)):
            raise SdoAbortedError(SdoAbort.NO_SUBINDEX)
        return found


class DeferredDownloadServer(SdoServer):
    """canopen's SDO server for ``node`` (its id ``node_id``), except that an expedited download to ``index`` sub 0 is
    handed to ``on_download(data)`` unanswered: the node answers it later, from whichever thread has
    the verdict, with :meth:`answer`.  ``on_download`` may raise :class:`canopen.SdoAbortedError`
    to abort it at once.  Every other request is served as canopen serves it."""

    def __init__(self, node: LocalNode, node_id: int, index: int, on_download: Callable[[bytes], None]) -> None:
        super().__init__(0x600 + node_id, 0x580 + node_id, node)
        self.deferred_index = index
        self._on_download = on_download

    def init_download(self, request: bytes) -> None:
        """An expedited download to the deferred object goes to ``on_download``; others to canopen."""
        command, index, subindex = SDO_STRUCT.unpack_from(request)
        if index != self.deferred_index or subindex != 0 or not command & EXPEDITED:
            super().init_download(request)
            return
        self._index, self._subindex = index, subindex  # an abort raised below names them
        size = 4 - ((command >> 2) & 0x3) if command & SIZE_SPECIFIED else 4
        self._on_download(bytes(request[4:4 + size]))

    def answer(self, abort_code: int | None = None) -> None:
        """The deferred download's answer: done (``abort_code`` None), or SDO abort ``abort_code``."""
        index = self.deferred_index
        if abort_code is None:
            response = bytearray(8)
            SDO_STRUCT.pack_into(response, 0, RESPONSE_DOWNLOAD, index, 0)
            self.send_response(response)
        else:
            self.send_response(_ABORT.pack(RESPONSE_ABORTED, index, 0, abort_code))
