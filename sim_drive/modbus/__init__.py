"""The simulated CiA-402 drive as a Modbus TCP server (register map: :mod:`drives.modbus.register_map`).

The drive behind the registers is :class:`sim_drive.device.SimulatedDrive`, the same plant, state
machine and operator models as the CANopen slave.  :mod:`~sim_drive.modbus.bank` maps registers
onto its objects and keeps the virtual time (no network), :mod:`~sim_drive.modbus.faults` arms
injected faults, :mod:`~sim_drive.modbus.server` serves the bank with pymodbus.  The command line
is ``haptic-bus sim --modbus tcp://HOST:PORT`` (:mod:`sim_drive.cli`).
"""

from sim_drive.modbus.bank import RegisterBank
from sim_drive.modbus.faults import FaultInjector
from sim_drive.modbus.server import LINK_LOST_ERROR_CODE, ModbusSimServer, parse_modbus_url

__all__ = ["LINK_LOST_ERROR_CODE", "FaultInjector", "ModbusSimServer", "RegisterBank", "parse_modbus_url"]
