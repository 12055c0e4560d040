"""A ring of fixed-size records with a write counter that readers poll: the one way data leaves the cycle.

The control thread's part is :meth:`Ring.put`: one precompiled ``struct.pack_into`` into a
preallocated slot and one store of the counter (no allocation, no lock, no system call).  The
ring lives in private memory (a ``bytearray``: readers in the same process) or in
``multiprocessing.shared_memory`` (:meth:`Ring.shared`; a writer process attaches with
:meth:`Ring.attach` from its :class:`RingSpec`), so the formatting and the file writing happen in
another process, which takes no share of the control process' interpreter lock.

Layout: 8 bytes of counter (int64: records written so far), then ``capacity`` records.  The one
writer packs record ``n`` into slot ``n % capacity`` and then stores ``n + 1``; x86 keeps stores in
order and loads in order (and CPython reorders neither), so a reader that reads the counter
first finds every record below it complete.  Record ``total - capacity`` shares its slot with the
record being written next, so a reader takes at most ``capacity - 1`` records, and after copying
re-reads the counter and drops what the writer may have overwritten meanwhile.  A reader that
fell that far behind loses the oldest records: :meth:`Ring.read_from` says from which index it
could still read, and the caller counts the difference as lost.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from multiprocessing import shared_memory
from typing import Any

_COUNTER = 8  # bytes: the int64 write counter ahead of the records


@dataclass(frozen=True)
class RingSpec:
    """What another process needs to attach to a shared ring: the segment's ``name``, the
    record's ``struct`` format and the ``capacity`` in records (picklable)."""

    name: str
    format: str
    capacity: int


class Segment(shared_memory.SharedMemory):
    """A shared-memory segment that lets go of a ring's views of it before it closes: a mapping
    with views left cannot close, and a garbage cycle may finalize the segment before its ring."""

    views: tuple[memoryview, ...] = ()

    def close(self) -> None:
        """Release the ring's views, then close as ``SharedMemory`` does."""
        for view in self.views:
            view.release()
        super().close()


def segment(record: struct.Struct, capacity: int) -> Segment:
    """A new shared-memory segment (zeroed) for a ring of ``capacity`` records of ``record``."""
    return Segment(create=True, size=_COUNTER + capacity * record.size)


class Ring:
    """``capacity`` records of ``record``'s layout; one writer (:meth:`put`), readers (:meth:`read_from`).

    ``memory``: the shared segment the ring lives in (None: private memory).  Readers never hold
    a view of the ring after a call returns (:meth:`read_from` copies), so closing the segment
    (:meth:`close`, or its finalizer) always succeeds.
    """

    def __init__(self, record: struct.Struct, capacity: int, memory: Segment | None = None) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 2:
            raise ValueError(f"capacity = {capacity!r} is invalid; allowed: an integer >= 2")
        size = _COUNTER + capacity * record.size
        if memory is not None and memory.size < size:
            raise ValueError(f"shared memory {memory.name!r} holds {memory.size} bytes; the ring needs {size}")
        self.record = record
        self.capacity = capacity
        self.width = record.size
        self._memory = memory
        buffer = memory.buf if memory is not None else None
        self._view = memoryview(buffer if buffer is not None else bytearray(size))[:size]
        self._counter = self._view[:_COUNTER].cast("q")
        self._data = self._view[_COUNTER:]
        if memory is not None:
            memory.views = (self._counter, self._data, self._view)
        self._pack = record.pack_into
        self._slot = 0
        self._total = 0

    @classmethod
    def shared(cls, record: struct.Struct, capacity: int) -> Ring:
        """A new ring in a new shared-memory segment; :meth:`unlink` removes its name."""
        return cls(record, capacity, segment(record, capacity))

    @classmethod
    def attach(cls, spec: RingSpec) -> Ring:
        """The ring another process made (``spec``), to read."""
        return cls(struct.Struct(spec.format), spec.capacity, Segment(name=spec.name))

    @property
    def spec(self) -> RingSpec:
        """How another process attaches to this ring (ValueError for a ring in private memory)."""
        if self._memory is None:
            raise ValueError("a ring in private memory cannot be attached from another process")
        return RingSpec(self._memory.name, self.record.format, self.capacity)

    @property
    def total(self) -> int:
        """Records written so far (the counter, as readers see it)."""
        return int(self._counter[0])

    def put(self, *values: Any) -> None:
        """Write one record (``values`` in the record's order): one ``pack_into``, one counter store."""
        slot = self._slot
        self._pack(self._data, slot * self.width, *values)
        self._slot = slot + 1 if slot + 1 < self.capacity else 0
        self._total = total = self._total + 1
        self._counter[0] = total  # last: a reader sees the record complete

    def read_from(self, first: int, limit: int | None = None) -> tuple[int, bytes]:
        """The records from index ``first`` on (at most ``limit`` of them), as ``(index of the first
        one returned, their bytes)`` (a copy, oldest first); the index exceeds ``first`` when older
        ones were overwritten."""
        total = int(self._counter[0])
        capacity, width = self.capacity, self.width
        start = max(first, total - capacity + 1)
        if start >= total:
            return max(first, total), b""
        end = total if limit is None else min(total, start + limit)
        lo, hi = start % capacity, end % capacity
        data = self._data
        chunk = bytes(data[lo * width:hi * width]) if lo < hi else bytes(data[lo * width:]) + bytes(data[:hi * width])
        torn = int(self._counter[0]) - capacity + 1 - start  # overwritten while copied
        if torn > 0:
            return start + torn, chunk[torn * width:]
        return start, chunk

    def last(self) -> tuple[Any, ...] | None:
        """The newest record's values, or None before the first."""
        total = int(self._counter[0])
        if not total:
            return None
        return self.record.unpack_from(self._data, ((total - 1) % self.capacity) * self.width)

    def close(self) -> None:
        """Let go of the memory (idempotent); the ring cannot be used after it."""
        if self._memory is not None:
            self._memory.close()
        for view in (self._counter, self._data, self._view):
            view.release()

    def unlink(self) -> None:
        """Remove the shared segment's name (those attached keep their mapping); nothing for private memory."""
        if self._memory is not None:
            self._memory.unlink()
