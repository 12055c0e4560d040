"""SDO access to the drive with canopen's errors turned into ours.

canopen's SDO client raises :class:`canopen.SdoAbortedError` (abort code only) and
:class:`canopen.SdoCommunicationError`; the master wants errors that name the drive, the
object and its name: :class:`~drives.errors.DriveRefusal` (with ``code``, ``index``,
``subindex``) and :class:`~drives.errors.DriveTimeout`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import canopen
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from drives.canopen.master_dictionary import object_name
from drives.cia301 import sdo_abort_text
from drives.cia402 import DataType
from drives.errors import DriveProtocolError, DriveRefusal, DriveTimeout


class SdoAccess:
    """SDO uploads and downloads to ``node`` with typed errors naming ``name`` and the object.

    ``before`` runs before every transfer (the master makes sure canopen's notifier reads the
    bus, which the SDO client needs); ``timeout`` is canopen's response timeout in s.
    """

    def __init__(self, name: str, node: canopen.RemoteNode, timeout: float, before: Callable[[], None]) -> None:
        self.name = name
        self.node = node
        self.timeout = timeout
        self._before = before
        node.sdo.RESPONSE_TIMEOUT = timeout

    @contextmanager
    def waiting(self, timeout: float) -> Iterator[None]:
        """Meanwhile ``timeout`` s for each answer (a download the device answers once it has acted on it)."""
        before = self.timeout
        self.timeout = self.node.sdo.RESPONSE_TIMEOUT = timeout
        try:
            yield
        finally:
            self.timeout = self.node.sdo.RESPONSE_TIMEOUT = before

    @contextmanager
    def translated(self, what: str, index: int, subindex: int) -> Iterator[None]:
        """Run a canopen SDO operation on ``index:subindex``; re-raise its errors as ours."""
        self._before()
        try:
            yield
        except SdoAbortedError as exc:
            name = object_name(self.node.object_dictionary, index, subindex)
            raise DriveRefusal(
                self.name,
                f"SDO abort {what} 0x{index:04X}:{subindex:02X} ({name}): 0x{exc.code:08X} {sdo_abort_text(exc.code)}",
                exc.code, index, subindex,
            ) from exc
        except SdoCommunicationError as exc:
            name = object_name(self.node.object_dictionary, index, subindex)
            stopped = _stopped(self.node)  # a node in NMT STOPPED drops the request
            late = "; the request went out, so a drive that answers late may still apply it" if what == "writing" \
                and not stopped else ""
            raise DriveTimeout(
                self.name, f"no SDO answer {what} 0x{index:04X}:{subindex:02X} ({name}) within {self.timeout:.3g} s: {exc}"
                           f"{stopped}{late}"
            ) from exc
        except (struct.error, ValueError, TypeError, IndexError, KeyError) as exc:  # canopen met an answer it cannot parse
            name = object_name(self.node.object_dictionary, index, subindex)
            raise DriveProtocolError(
                self.name, f"malformed SDO answer {what} 0x{index:04X}:{subindex:02X} ({name}): {exc}"
            ) from exc

    def upload(self, index: int, subindex: int = 0) -> bytes:
        """Read ``index:subindex`` as raw bytes."""
        with self.translated("reading", index, subindex):
            return self.node.sdo.upload(index, subindex)

    def download(self, index: int, subindex: int, data: bytes) -> None:
        """Write raw ``data`` to ``index:subindex``."""
        with self.translated("writing", index, subindex):
            self.node.sdo.download(index, subindex, bytes(data))

    def read_int(self, index: int, subindex: int, data_type: DataType) -> int:
        """Read an integer object of ``data_type``; DriveProtocolError if the answer is too short."""
        data = self.upload(index, subindex)
        if len(data) < data_type.size:
            raise DriveProtocolError(
                self.name, f"0x{index:04X}:{subindex:02X} answered {len(data)} bytes, {data_type.name} needs {data_type.size}"
            )
        return int(struct.unpack_from("<" + data_type.struct_format, data)[0])

    def write_int(self, index: int, subindex: int, data_type: DataType, value: int) -> None:
        """Write an integer object of ``data_type``."""
        self.download(index, subindex, struct.pack("<" + data_type.struct_format, value))

    def read_real(self, index: int, subindex: int, fmt: str) -> float:
        """Read a REAL32 (``"<f"``) or REAL64 (``"<d"``) object."""
        data = self.upload(index, subindex)
        if len(data) != struct.calcsize(fmt):
            raise DriveProtocolError(
                self.name, f"0x{index:04X}:{subindex:02X} answered {len(data)} bytes, expected {struct.calcsize(fmt)}"
            )
        return float(struct.unpack(fmt, data)[0])


def _stopped(node: canopen.RemoteNode) -> str:
    """Why a node may not answer SDO, where its heartbeat says: NMT STOPPED (CiA 301: SDO is off there)."""
    nmt = node.nmt
    if getattr(nmt, "timestamp", None) is None or nmt.state != "STOPPED":  # no heartbeat seen, or not stopped
        return ""
    return ("; its heartbeat shows NMT STOPPED, where a node answers no SDO (an NMT stop from another master or "
            "its own: start it with NMT start, or reset it)")
