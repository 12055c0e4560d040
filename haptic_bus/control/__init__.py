"""The run-time controller: scenes, the passivity gate, the cycle, its observer, record and clocks.

No bus library here: the controller on the bus (its CANopen node, the upload client) is
:mod:`haptic_bus.node`; drives reach it through :class:`drives.base.Drive`.
"""
