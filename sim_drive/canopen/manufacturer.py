"""The manufacturer area 0x2000.. of the simulated drive's object dictionary (SDO access).

Layout (all REAL64 values are IEEE 754 doubles in SI units; see also ``sim_drive.eds``):

- 0x2000 plant: sub 1 ``mass`` kg, sub 2 ``friction`` N s/m, sub 3 plant sub-steps per SYNC (UNSIGNED16)
- 0x2001 scaling: sub 1 velocity per count m/s, sub 2 position per count m, sub 3 force per
  torque N/(N m)
- 0x2002 timing: sub 1 loop timing (0 cia402, 1 ideal, 2 reception), sub 2 SYNC count, sub 3
  virtual time s, sub 4 late RPDO count, sub 5 RPDO length error count (2-5 read-only), sub 6
  reception delay (samples in [0, 1): when ``reception`` timing applies a target after the SYNC)
- 0x2003 energy: sub 1 operator energy J, sub 2 wall energy J (read-only)
- 0x2010 operator: sub 1 model code (``sim_drive.operator.OPERATOR_CODES``), sub 2..7
  parameters p1..p6.  Write the parameters first, then the code: writing the code builds the
  model from p1..p6 and swaps it in (a rejected model leaves the running one in place).

A rejected value aborts the SDO transfer with 0x06090030 (value range exceeded).
"""

from __future__ import annotations

from canopen import SdoAbortedError

from haptic_bus.errors import HapticBusError
from sim_drive.canopen.pdo_engine import SlaveCounters
from sim_drive.device import SimulatedDrive
from sim_drive.operator import MAX_OD_PARAMETERS, operator_code, operator_from_code
from sim_drive.parameters import Timing

ABORT_RANGE = 0x06090030
PLANT, SCALING, TIMING, ENERGY, OPERATOR = 0x2000, 0x2001, 0x2002, 0x2003, 0x2010
_PARAMETER_FIELDS = {
    (PLANT, 1): "mass",
    (PLANT, 2): "friction",
    (PLANT, 3): "substeps",
    (SCALING, 1): "velocity_per_count",
    (SCALING, 2): "position_per_count",
    (SCALING, 3): "force_per_torque",
    (TIMING, 6): "reception_delay",
}
_TIMING_CODES = {Timing.CIA402: 0, Timing.IDEAL: 1, Timing.RECEPTION: 2}


class ManufacturerObjects:
    """SDO reads and writes of 0x2000.. against ``drive`` and the slave's ``counters``."""

    def __init__(self, drive: SimulatedDrive, counters: SlaveCounters) -> None:
        self._drive = drive
        self._counters = counters
        self._pending = self._padded(drive.operator.parameters())

    @staticmethod
    def _padded(parameters: tuple[float, ...]) -> list[float]:
        return list(parameters[:MAX_OD_PARAMETERS]) + [0.0] * (MAX_OD_PARAMETERS - len(parameters))

    @staticmethod
    def owns(index: int) -> bool:
        """True for the indices of the manufacturer area this class serves."""
        return index in (PLANT, SCALING, TIMING, ENERGY, OPERATOR)

    def read(self, index: int, subindex: int) -> int | float | None:
        """The value of ``index``:``subindex``, or None for a sub-index 0 (left to the EDS)."""
        drive = self._drive
        name = _PARAMETER_FIELDS.get((index, subindex))
        if name is not None:
            return getattr(drive.parameters, name)
        values = {
            (TIMING, 1): lambda: _TIMING_CODES[drive.timing],
            (TIMING, 2): lambda: drive.sync_count & 0xFFFFFFFF,
            (TIMING, 3): lambda: drive.time,
            (TIMING, 4): lambda: self._counters.late_rpdos,
            (TIMING, 5): lambda: self._counters.rpdo_length_errors,
            (ENERGY, 1): lambda: drive.operator_energy,
            (ENERGY, 2): lambda: drive.wall_energy,
            (OPERATOR, 1): lambda: operator_code(drive.operator),
        }
        if (index, subindex) in values:
            return values[(index, subindex)]()
        if index == OPERATOR and subindex >= 2:
            return self._pending[subindex - 2]
        return None

    def write(self, index: int, subindex: int, value: int | float) -> None:
        """Apply one SDO write; raise SdoAbortedError(0x06090030) on a rejected value."""
        drive = self._drive
        try:
            name = _PARAMETER_FIELDS.get((index, subindex))
            if name is not None:
                drive.reconfigure(**{name: value})
            elif (index, subindex) == (TIMING, 1):
                drive.timing = next(t for t, code in _TIMING_CODES.items() if code == value)
            elif (index, subindex) == (OPERATOR, 1):
                drive.set_operator(operator_from_code(int(value), self._pending))
                self._pending = self._padded(drive.operator.parameters())
            elif index == OPERATOR and subindex >= 2:
                self._pending[subindex - 2] = float(value)
        except (HapticBusError, StopIteration) as exc:
            raise SdoAbortedError(ABORT_RANGE) from exc
