"""The cyclic pymodbus requests of one Modbus drive, built once at construction.

The output registers are updated in place and the labels formatted once, so a cycle builds no
request and formats no string; with ``cycle="fc23"`` the inputs an output write brought back wait
here for the next cycle's read (:mod:`drives.modbus.drive`).
"""

from __future__ import annotations

from collections.abc import Sequence

from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadWriteMultipleRegistersRequest,
    WriteMultipleRegistersRequest,
)

from drives.cia402 import SAFE_CONTROLWORD
from drives.modbus.register_map import INPUT_BLOCK, OUTPUT_BLOCK, OUTPUT_BLOCK_COUNT, describe_range


class CyclicRequests:
    """The cyclic pymodbus requests of one drive, built once (the output registers are updated
    in place), and their labels (no string formatting per cycle); ``cached``: with ``cycle="fc23"``,
    the inputs the last output write read (None: none held), ``cached_at`` the
    ``time.perf_counter_ns()`` its answer arrived."""

    def __init__(self, unit_id: int, input_count: int) -> None:
        self.outputs = [SAFE_CONTROLWORD, 0]
        self.cached: Sequence[int] | None = None
        self.cached_at = 0
        self.read = ReadHoldingRegistersRequest(address=INPUT_BLOCK, count=input_count, dev_id=unit_id)
        self.write = WriteMultipleRegistersRequest(address=OUTPUT_BLOCK, registers=self.outputs, dev_id=unit_id)
        self.write.count = OUTPUT_BLOCK_COUNT
        self.read_write = ReadWriteMultipleRegistersRequest(
            read_address=INPUT_BLOCK, read_count=input_count, write_address=OUTPUT_BLOCK,
            write_registers=self.outputs, dev_id=unit_id,
        )
        self.read_what = describe_range(INPUT_BLOCK, input_count)
        self.write_what = describe_range(OUTPUT_BLOCK, OUTPUT_BLOCK_COUNT)
        self.read_label = f"reading {self.read_what}"
        self.write_label = f"writing {self.write_what}"
        self.read_write_label = f"writing {self.write_what} and reading {self.read_what} (FC23)"
